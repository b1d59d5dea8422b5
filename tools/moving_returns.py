"""The moving-object stage against the truth: which moving returns it kept, which static ones it dropped.

    python -m tools.moving_returns out/seqs/red_light-moving
    python -m tools.moving_returns SEQ1 SEQ2 --set dynamic.free_margin_m=0.3 --frames 200 --out rejection.json
    python -m tools.moving_returns out/seqs/red_light-moving --oracle     # the truth's static returns only

The odometry (the default variant, with ``dynamic.enabled`` and any ``--set``) runs over each
simulated sequence as always (its scans, times and rings only); the truth's per-return ``moving``
flags then judge the stage's verdicts (``odometry.dynamic``). The stage drops voxel centroids; a
return counts as dropped when the centroid of its voxel was (the registration and the map see
returns only through their centroids). Counted are the returns the odometry keeps in range
(``clean``), over every frame, the first two included (no earlier scan to compare with: nothing is
dropped there). Per sequence: the fraction of moving returns kept, and of static returns dropped,
each per object class and per band of speed of the moving ones; with the sequence's poses, the run's
KITTI t_err, end error and the motion it invented while the sensor truly stood still
(``tools.family_suite.trajectory_figures``).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from odometry.config import OdometryConfig, variant
from odometry.kernels.voxel_hash import group_keys
from odometry.pipeline import Odometry
from odometry.voxels import voxel_keys
from simlidar.formats.truth import ACTOR_CLASSES

# The bands of the moving returns' speeds, m/s: creeping, walking and cycling, town traffic, faster.
SPEED_BANDS_M_S = (0.0, 1.0, 3.0, 8.0, float("inf"))


def speed_band(speed_m_s: float | np.ndarray) -> np.ndarray:
    """The band (index into ``SPEED_BANDS_M_S``'s intervals) of each speed, m/s."""
    return np.searchsorted(SPEED_BANDS_M_S[1:-1], speed_m_s, side="right")


def band_name(band: int) -> str:
    lo, hi = SPEED_BANDS_M_S[band], SPEED_BANDS_M_S[band + 1]
    return f"{lo:g}-{hi:g} m/s" if np.isfinite(hi) else f">= {lo:g} m/s"


class MovingTruthMissing(ValueError):
    """A sequence without the truth's per-return moving flags (a static world, or a real one)."""


@dataclass
class RejectionCounts:
    """Returns judged over a sequence. moving, static: returns in range; *_dropped: those the stage dropped;
    by_class: per object class of the moving returns, [returns, dropped]; by_speed: the same per band of
    their speed (``SPEED_BANDS_M_S``)."""

    moving: int = 0
    moving_dropped: int = 0
    static: int = 0
    static_dropped: int = 0
    by_class: dict = field(default_factory=dict)
    by_speed: dict = field(default_factory=dict)

    @property
    def moving_kept_fraction(self) -> float:
        return (self.moving - self.moving_dropped) / self.moving if self.moving else float("nan")

    @property
    def static_dropped_fraction(self) -> float:
        return self.static_dropped / self.static if self.static else float("nan")

    def add(self, moving: np.ndarray, dropped: np.ndarray, classes: np.ndarray | None,
            speeds_m_s: np.ndarray | None = None) -> None:
        """Count one frame: (N,) bool truth flags and verdicts of its returns in range, (N,) their class codes
        and speeds, m/s (either may be None)."""
        self.moving += int(moving.sum())
        self.moving_dropped += int((moving & dropped).sum())
        self.static += int((~moving).sum())
        self.static_dropped += int((~moving & dropped).sum())
        if classes is not None:
            for code in np.unique(classes[moving]):
                on = moving & (classes == code)
                name = ACTOR_CLASSES[int(code)] if int(code) < len(ACTOR_CLASSES) else str(int(code))
                seen = self.by_class.setdefault(name, [0, 0])
                seen[0] += int(on.sum())
                seen[1] += int((on & dropped).sum())
        if speeds_m_s is not None:
            bands = speed_band(speeds_m_s)
            for band in np.unique(bands[moving]):
                on = moving & (bands == band)
                seen = self.by_speed.setdefault(int(band), [0, 0])
                seen[0] += int(on.sum())
                seen[1] += int((on & dropped).sum())


def returns_dropped(clean_points: np.ndarray, moving_centroids: np.ndarray | None, voxel_size_m: float) -> np.ndarray:
    """(N,) bool: each clean return (N, 3, as measured) is in a voxel whose centroid the stage dropped.

    moving_centroids: (V,) the stage's verdict per centroid of the scan's voxel grid, in the grid's key order
    (``PreparedScan.moving``), or None (not judged: nothing dropped)."""
    if moving_centroids is None or len(clean_points) == 0:
        return np.zeros(len(clean_points), dtype=bool)
    voxels, slot = group_keys(voxel_keys(clean_points, voxel_size_m))
    if len(voxels) != len(moving_centroids):
        raise ValueError(f"{len(moving_centroids)} verdicts for a grid of {len(voxels)} voxels")
    return moving_centroids[slot]


def rejection_figures(sequence, config: OdometryConfig, frames: int | None = None, oracle: bool = False) -> dict:
    """Run ``config`` (its moving-object stage on) over a simulated sequence; the stage's verdicts against the
    truth (``RejectionCounts``) and, where the sequence has poses, the run's t_err, end error and standstill motion.

    oracle: instead, the stage off and the odometry given only the returns the truth says are static: what a
    perfect moving-object stage would leave (its verdicts are the truth's: every moving return dropped)."""
    from tools.family_suite import trajectory_figures

    if sequence.sensor is None:
        raise MovingTruthMissing(f"{sequence.path}: no sensor model (sensor.yaml): the stage needs one")
    config = config.replace(dynamic={"enabled": not oracle})
    odo = Odometry(config, sequence.sensor)
    counts = RejectionCounts()
    n = len(sequence) if frames is None else min(frames, len(sequence))
    for k in range(n):
        frame = sequence[k]
        moving = frame.field("moving")
        if moving is None:
            raise MovingTruthMissing(f"{sequence.path}: frame {k} has no per-return 'moving' truth "
                                     "(simulate a world with traffic: --set traffic.enabled=true, or a stress scene)")
        moving = moving.astype(bool)
        given = np.flatnonzero(~moving) if oracle else np.arange(len(moving))
        times, rings = frame.time_s, frame.ring
        prepared = odo.prepare(frame.points[given], None if times is None else times[given],
                               None if rings is None else rings[given], first=not odo.poses)
        stamp = float(sequence.times[k]) if sequence.times is not None else None
        odo.register_prepared(prepared, stamp_s=stamp)
        classes, velocity = frame.field("object_class"), frame.field("velocity")
        if oracle:
            rows, dropped = np.arange(len(moving)), moving
        else:
            rows = prepared.clean.kept_rows
            # (the voxel grid of the clean points as measured: the one the centroids came from)
            dropped = returns_dropped(prepared.clean.points, prepared.moving, config.filter.voxel_size_m)
        counts.add(moving[rows], dropped, None if classes is None else classes[rows],
                   None if velocity is None else np.linalg.norm(velocity[rows], axis=1))
    out = {"sequence": str(sequence.path), "frames": n, "moving_returns": counts.moving,
           "moving_kept_fraction": counts.moving_kept_fraction, "static_returns": counts.static,
           "static_dropped_fraction": counts.static_dropped_fraction,
           "moving_kept_fraction_by_class": {c: (r - d) / r for c, (r, d) in sorted(counts.by_class.items()) if r},
           "moving_by_speed": [{"speed": band_name(b), "returns": r, "kept_fraction": (r - d) / r}
                               for b, (r, d) in sorted(counts.by_speed.items()) if r]}
    if sequence.poses is not None:
        figures = trajectory_figures(np.asarray(sequence.poses)[:n], np.stack(odo.poses))
        out.update({k: figures.get(k) for k in ("t_err_pct", "end_error_m", "standstill_motion_m")})
    return out


def main(argv: list[str] | None = None) -> int:
    from odometry.config import changes_from_assignments, config_from_dict
    from simlidar.dataset import open_sequence
    from tools.records import write_json

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequences", nargs="+", help="simulated sequence folders with moving objects")
    ap.add_argument("--variant", default="salo-map", help="the odometry variant (default: salo-map, the default)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an odometry key (repeatable)")
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames of each sequence")
    ap.add_argument("--oracle", action="store_true",
                    help="the stage off, and the odometry given only the returns the truth says are static (the "
                         "figures a perfect moving-object stage would reach)")
    ap.add_argument("--out", type=Path, default=None, help="also write the figures as JSON here")
    args = ap.parse_args(argv)
    try:
        config = config_from_dict(changes_from_assignments(args.set), base=variant(args.variant), origin="--set")
        results = [rejection_figures(open_sequence(path), config, args.frames, args.oracle) for path in args.sequences]
    except ValueError as exc:  # (a sequence that cannot be read, a bad key, no truth: one line)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for r in results:
        line = (f"{r['sequence']}: {r['frames']} frames; moving returns kept {100 * r['moving_kept_fraction']:.1f} % "
                f"of {r['moving_returns']}, static returns dropped {100 * r['static_dropped_fraction']:.2f} % "
                f"of {r['static_returns']}")
        if r.get("end_error_m") is not None:
            still = r["standstill_motion_m"]
            line += (f"; t_err {r['t_err_pct']:.3f} %, end error {r['end_error_m']:.3f} m"
                     + ("" if still is None else f", standstill {still:.4f} m"))
        print(line)
        if r["moving_kept_fraction_by_class"]:
            print("  moving kept by class: " + ", ".join(f"{c} {100 * f:.1f} %"
                                                         for c, f in r["moving_kept_fraction_by_class"].items()))
        if r["moving_by_speed"]:
            print("  moving kept by speed: " + ", ".join(f"{b['speed']} {100 * b['kept_fraction']:.1f} % of "
                                                         f"{b['returns']}" for b in r["moving_by_speed"]))
    if args.out is not None:
        write_json(args.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
