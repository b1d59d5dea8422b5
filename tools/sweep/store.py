"""The results store of a sweep: one folder per run, one JSON per result, a table rebuilt from them.

Layout under the sweep's output folder::

    OUT/
      spec.yaml                 the resolved spec of the latest sweep into this folder
      results.csv               one row per run of that spec, rebuilt from runs/*/result.json
      summary.csv, summary.md   per (scene, sensor, noise, variant): runs, failures, means over seeds
      plots/<scene>.png         error against noise level, one line per variant
      runs/<key>/               a run's artifacts: params.json (written first), poses.txt,
                                diagnostics.csv, config.yaml (or command.log), metrics.json,
                                result.json (written last, atomically: the run is complete)
      sequences/<sim_key>/      a cached simulated sequence (simlidar's atomic writer)
      sequences/<sim_key>.json  how it was made: parameters, seconds
      .lock                     held (flock) while a sweep writes here

Why it never corrupts: a run's ``result.json`` is written with a rename, after
every artifact, so a folder without it is a run that was killed half-way and
is redone; the table is derived data, rewritten atomically from the JSON files;
sequences are renamed into place only when complete. Two sweeps into one
folder at once are refused by the lock (released by the kernel if a sweep dies).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from simlidar.formats.atomic import atomic_write_text

RESULT_FILE = "result.json"
PARAMS_FILE = "params.json"

# Columns of results.csv, in order. Parameters, then status, metrics, diagnostics, timings, versions.
PARAM_COLUMNS = ("key", "sim_key", "label", "scene", "seed", "sensor", "noise_std_m", "variant", "frames",
                 "speed_m_s", "start_s", "motion_distortion", "scene_params", "odometry")
METRIC_COLUMNS = ("path_length_m", "t_err_pct", "r_err_deg_per_100m", "segments", "t100_mean_m", "t100_std_m",
                  "t100_count", "ate_rmse_m", "ate_mean_m", "ate_max_m", "ate_aligned_rmse_m",
                  "ate_aligned_mean_m", "ate_aligned_max_m", "rpe_pairs", "rpe_t_mean_m", "rpe_t_median_m",
                  "rpe_t_rmse_m", "rpe_r_mean_deg", "rpe_r_median_deg", "rpe_r_rmse_deg")
DIAGNOSTIC_COLUMNS = ("extrapolated_frames", "degenerate_frames")
TIMING_COLUMNS = ("simulate_s", "sim_cached", "odometry_s", "frames_per_s", "evaluate_s", "run_s")
VERSION_COLUMNS = ("package_version", "numpy_version", "scipy_version", "python_version")
TABLE_COLUMNS = (PARAM_COLUMNS + ("status",) + METRIC_COLUMNS + DIAGNOSTIC_COLUMNS + TIMING_COLUMNS
                 + VERSION_COLUMNS + ("host", "finished_utc", "error"))
# Columns that differ between two executions of the same run (where, when, how fast).
VOLATILE_COLUMNS = frozenset(TIMING_COLUMNS + ("host", "finished_utc"))


class StoreBusy(RuntimeError):
    """Another sweep holds this output folder's lock."""


def flatten(result: dict) -> dict:
    """A result JSON (nested: params, metrics, timings, versions) -> one table row (TABLE_COLUMNS)."""
    row = {
        "key": result.get("key"),
        "sim_key": result.get("sim_key"),
        **result.get("params", {}),
        "status": result.get("status"),
        **{k: result.get("metrics", {}).get(k) for k in METRIC_COLUMNS},
        **result.get("diagnostics", {}),
        **result.get("timings", {}),
        **result.get("versions", {}),
        "host": result.get("host"),
        "finished_utc": result.get("finished_utc"),
        "error": result.get("error"),
    }
    return {c: row.get(c) for c in TABLE_COLUMNS}


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    return str(value)


def format_table(rows: Iterable[dict]) -> str:
    """CSV text of flattened rows (None and NaN as empty cells, floats at full precision)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE_COLUMNS)
    for row in rows:
        w.writerow([_cell(row.get(c)) for c in TABLE_COLUMNS])
    return buf.getvalue()


# Columns read back as numbers; every other column stays text (a hex run key such as
# "1234e56789012345" or a version "2.0" must not turn into a number).
NUMERIC_COLUMNS = frozenset(("seed", "noise_std_m", "frames", "speed_m_s", "start_s")
                            + METRIC_COLUMNS + DIAGNOSTIC_COLUMNS + TIMING_COLUMNS)


def read_table(path: str | Path) -> list[dict]:
    """Read a results.csv back: numeric columns as int/float, true/false as bool, empty cells as None."""

    def parse(column: str, text: str):
        if text == "":
            return None
        if text in ("true", "false"):
            return text == "true"
        if column in NUMERIC_COLUMNS:
            for cast in (int, float):
                try:
                    return cast(text)
                except ValueError:
                    pass
        return text

    with open(path, newline="") as fh:
        return [{k: parse(k, v) for k, v in row.items()} for row in csv.DictReader(fh)]


class Store:
    """A sweep's output folder (see the module docstring for the layout)."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.runs_dir = self.root / "runs"
        self.sequences_dir = self.root / "sequences"
        self.table_path = self.root / "results.csv"

    # -- runs
    def run_dir(self, key: str) -> Path:
        return self.runs_dir / key

    def result_path(self, key: str) -> Path:
        return self.run_dir(key) / RESULT_FILE

    def read_result(self, key: str) -> dict | None:
        """The run's result, or None when it has none (never run, or killed before the end)."""
        try:
            data = json.loads(self.result_path(key).read_text())
        except (OSError, json.JSONDecodeError):
            return None
        return data if isinstance(data, dict) and data.get("key") == key else None

    def state(self, key: str) -> str:
        """"ok" or "failed" (a result exists), "partial" (a folder without result: redo), or "new"."""
        result = self.read_result(key)
        if result is not None:
            return "ok" if result.get("status") == "ok" else "failed"
        return "partial" if self.run_dir(key).exists() else "new"

    def clear_run(self, key: str) -> None:
        """Remove a run's folder (a half-written one, or one about to be redone)."""
        shutil.rmtree(self.run_dir(key), ignore_errors=True)

    def write_result(self, result: dict) -> None:
        """Commit a run: its result JSON, atomically (written last, after the artifacts)."""
        atomic_write_text(self.result_path(result["key"]),
                          json.dumps(result, indent=1, sort_keys=True, allow_nan=False) + "\n")

    # -- sequences
    def sequence_dir(self, sim_key: str) -> Path:
        return self.sequences_dir / sim_key

    def sequence_info_path(self, sim_key: str) -> Path:
        return self.sequences_dir / f"{sim_key}.json"

    def sequence_ready(self, sim_key: str) -> bool:
        """A complete cached sequence: the writer renames it into place with its manifest last."""
        return (self.sequence_dir(sim_key) / "manifest.json").is_file()

    def sequence_info(self, sim_key: str) -> dict:
        try:
            return json.loads(self.sequence_info_path(sim_key).read_text())
        except (OSError, json.JSONDecodeError):
            return {}

    def remove_sequence(self, sim_key: str) -> None:
        shutil.rmtree(self.sequence_dir(sim_key), ignore_errors=True)

    def clean_partials(self) -> int:
        """Remove sequence folders a killed simulation left half-written (hidden ``.KEY.partial-PID``)."""
        if not self.sequences_dir.is_dir():
            return 0
        stale = [p for p in self.sequences_dir.iterdir()
                 if p.name.startswith(".") and (".partial-" in p.name or ".old-" in p.name)]
        for p in stale:
            shutil.rmtree(p, ignore_errors=True)
        return len(stale)

    # -- table
    def results(self, keys: Iterable[str]) -> Iterator[dict]:
        """The results of ``keys`` that have one, in order."""
        for key in keys:
            result = self.read_result(key)
            if result is not None:
                yield result

    def write_table(self, keys: Iterable[str]) -> list[dict]:
        """Rebuild results.csv from the result JSONs of ``keys`` (atomically); returns the rows."""
        rows = [flatten(r) for r in self.results(keys)]
        atomic_write_text(self.table_path, format_table(rows))
        return rows

    # -- exclusive use
    @contextmanager
    def lock(self):
        """Hold the folder's lock for a sweep; StoreBusy if another live sweep holds it."""
        import fcntl

        self.root.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.root / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise StoreBusy(f"{self.root}: another sweep is writing into this folder") from None
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            yield self
        finally:
            os.close(fd)  # closing releases the flock


__all__ = ["Store", "StoreBusy", "TABLE_COLUMNS", "VOLATILE_COLUMNS", "flatten", "format_table", "read_table"]
