"""A ``salo.methods`` plug-in's own process (``python -m tools.plugin_child NAME STAGE_INPUT RESULT_DIR``).

Started by ``tools.isolation.run_plugin_isolated`` in the stage's work folder: it
loads the plug-in by its entry point's name, runs it on the staged folder (the
sensor's data only) and writes the poses into RESULT_DIR
(``tools.isolation.RESULT_NPZ`` and ``RESULT_JSON``). A failure it can explain is
its last line on stderr and exit status ``EXPLAINED_FAILURE``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from tools.isolation import EXPLAINED_FAILURE, RESULT_JSON, RESULT_NPZ


def main(name: str, root: str, result: str) -> int:
    from tools.methods import MethodError, load_plugin, plugin_entry_points
    from tools.staging import StagedInput

    try:
        entry = plugin_entry_points().get(name)
        if entry is None:
            raise MethodError(f"plug-in {name}: no entry point of that name in this process's environment")
        method = load_plugin(entry)
        frames = len(list((Path(root) / "velodyne").glob("*.bin")))
        output = method.run_staged(StagedInput(Path(root), Path(result) / "poses.txt", (), frames))
    except MethodError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXPLAINED_FAILURE
    arrays = {"poses": np.asarray(output.poses, dtype=np.float64)}
    if output.degenerate is not None:
        arrays["degenerate"] = np.asarray(output.degenerate, dtype=bool)
    np.savez(Path(result) / RESULT_NPZ, **arrays)
    info = {"seconds": output.seconds, "settings": output.settings, "note": output.note}
    (Path(result) / RESULT_JSON).write_text(json.dumps(info, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
