"""Digests of the odometry's poses: prove that a change to the code left every pose bit-identical.

    python -m tools.pose_digest --out before.json                    # at the old commit
    python -m tools.pose_digest --out after.json --compare before.json

Runs every variant of ours (``odometry.config.VARIANTS``, and a few non-default keys) closed loop,
and the default open loop, over the first frames of one tuning-seed sequence of every family of
the generalisation suite in both kinds (simulated: per-point times and rings; as real: x, y, z
only), and over the real excerpts of ``../shared/data/real``. Each run's poses (and the open-loop
estimates) are digested with sha256 of their float64 bytes: equal digests are equal poses to the
last bit.
Exit status 1 when ``--compare`` finds a difference.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

# Runs beside the variants: keys whose code paths the variants do not take.
EXTRA_RUNS = {
    "salo-map/refinements=0": ("salo-map", {"deskew": {"refinements": 0}}),
    "salo-map/refinements=2": ("salo-map", {"deskew": {"refinements": 2}}),
    "salo-map/remap": ("salo-map", {"degeneracy": {"weak_direction_update": "remap"}}),
    "salo/isotropic,paper": ("salo", {"ncf": {"noise_model": "isotropic", "noise_free_gaps": False},
                                       "gcr": {"formula": "paper"}}),
    "salo-map/ncf-both": ("salo-map", {"ncf": {"applies_to": "both"}}),
    "bl/plain-knn,no-deskew": ("bl", {"filter": {"adjacent_ring_reach_m": None}, "deskew": {"enabled": False}}),
    "salo-map/dynamic": ("salo-map", {"dynamic": {"enabled": True}}),
}
DEFAULT_FRAMES = 40


def digest(array: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array, dtype=np.float64).tobytes()).hexdigest()[:16]


def configs() -> dict:
    from odometry.config import VARIANTS

    out = {name: cfg for name, cfg in VARIANTS.items()}
    for label, (base, changes) in EXTRA_RUNS.items():
        out[label] = VARIANTS[base].replace(**changes)
    return out


def suite_sequences(frames: int, families: tuple[str, ...] | None):
    """(name, in-memory sequence) of one tuning seed per family, both kinds, as the suite simulates them."""
    from tools.family_suite import TUNING_SEEDS, simulate, suite

    for seq in suite((TUNING_SEEDS[0],), frames=frames, families=families):
        yield seq.name, simulate(seq)


def real_sequences():
    """(name, sequence) of the real excerpts that are present (``tools.bench_real``'s)."""
    from simlidar.dataset import open_sequence
    from tools.bench_real import EXCERPTS, REAL_DATA

    for name, (folder, sensor, _) in EXCERPTS.items():
        if (REAL_DATA / folder).exists():
            yield name, open_sequence(REAL_DATA / folder, sensor=sensor)


def open_loop_estimates(seq, config, sensor) -> np.ndarray:
    """(F, 4, 4) the open-loop run's estimated motions, the first frame's the identity."""
    try:
        from odometry.open_loop import run_open_loop
    except ImportError:  # (before the open-loop harness wrapped the odometry: the run's diagnostics held them)
        from odometry.pipeline import run_sequence

        run = run_sequence(seq, config, sensor=sensor, true_poses=np.asarray(seq.poses))
        return np.stack([np.eye(4) if d.estimated_motion is None else d.estimated_motion for d in run.diagnostics])
    estimates = run_open_loop(seq, config, np.asarray(seq.poses), sensor=sensor).estimated_motions
    estimates[0] = np.eye(4)
    return estimates


def run_all(frames: int, families: tuple[str, ...] | None) -> dict:
    from odometry.config import variant
    from odometry.pipeline import run_sequence

    out: dict[str, str] = {}
    cfgs = configs()
    t0 = time.perf_counter()
    for name, seq in [*suite_sequences(frames, families), *real_sequences()]:
        sensor = seq.sensor
        for label, cfg in cfgs.items():
            if cfg.gcr.enabled and sensor is None:
                continue
            run = run_sequence(seq, cfg, sensor=sensor)
            out[f"{name} {label}"] = digest(run.poses)
        if seq.poses is not None and len(seq.poses) == len(seq):
            out[f"{name} salo-map/open-loop"] = digest(open_loop_estimates(seq, variant("salo-map"), sensor))
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.pose_digest", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="write the digests here (JSON)")
    ap.add_argument("--compare", help="a digest file to compare with: exit 1 on any difference")
    ap.add_argument("--frames", type=int, default=DEFAULT_FRAMES)
    ap.add_argument("--families", help="comma-separated families (default: all)")
    args = ap.parse_args(argv)
    families = tuple(args.families.split(",")) if args.families else None
    digests = run_all(args.frames, families)
    Path(args.out).write_text(json.dumps(digests, indent=1, sort_keys=True) + "\n")
    print(f"{len(digests)} runs digested -> {args.out}")
    if args.compare:
        before = json.loads(Path(args.compare).read_text())
        differ = sorted(k for k in before.keys() & digests.keys() if before[k] != digests[k])
        missing = sorted(before.keys() ^ digests.keys())
        for k in differ:
            print(f"DIFFERENT: {k}")
        for k in missing:
            print(f"only in one: {k}")
        same = len(before.keys() & digests.keys()) - len(differ)
        print(f"{same} identical, {len(differ)} different, {len(missing)} in one file only")
        return 1 if differ or missing else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
