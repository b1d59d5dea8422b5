"""Every method on the real excerpts in ``../shared/data/real``: mean per-pair error against their truth.

    python -m tools.bench_real                       # our variants and the installed peers
    python -m tools.bench_real --methods bl,salo-map
    python -m tools.bench_real --set filter.adjacent_ring_reach_m=2   # a change to every variant of ours

The excerpts (KITTI 05 and 01, HDL-64E, 10 frames each; an HDL-32E scan pair) are
too short for 100 m segments; as their README says, they are scored by the
per-pair relative pose error: translation (cm) and rotation (deg) of each
consecutive pair's estimated motion against the true one, averaged. KITTI is read
with the HDL-64E model and its 0.205 deg vertical-angle correction for our
methods; the peers get the points as read. Every method runs through the one
interface (``tools.methods.run_method``) on the excerpt as read. Prints figures;
asserts nothing.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from odometry.config import DEFAULT_VARIANT, VARIANTS, ConfigError, changes_from_assignments, config_from_dict, variant
from simlidar import se3
from simlidar.dataset import open_sequence
from tools.methods import OursMethod, PeerMethod, run_method
from tools.peers import PEERS

REAL_DATA = Path(os.environ.get("SALO_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real"))
EXCERPTS = {  # name: (folder below the real-data root, sensor preset, KITTI correction)
    "kitti-05": ("kitti/sequences/05", "hdl64e", True),
    "kitti-01": ("kitti/sequences/01", "hdl64e", True),
    "hdl32-pair": ("hdl32-pair", "hdl32e", False),
}


def pair_errors(gt: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    """Mean translation (cm) and rotation (deg) error of consecutive relative motions, (N, 4, 4) each."""
    err = se3.inverse(se3.inverse(gt[:-1]) @ gt[1:]) @ (se3.inverse(est[:-1]) @ est[1:])
    return float(np.mean(np.linalg.norm(err[:, :3, 3], axis=1)) * 100), float(np.degrees(np.mean(
        se3.rotation_angle(err))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--methods", default=",".join([*VARIANTS, *PEERS]),
                    help=f"comma-separated variants and peers (default all; the default variant is {DEFAULT_VARIANT})")
    ap.add_argument("--root", type=Path, default=REAL_DATA, help=f"real-data folder (default {REAL_DATA})")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="an odometry parameter changed for our variants (dotted, e.g. ncf.max_normal_std_deg=3)")
    args = ap.parse_args()
    try:
        changes = changes_from_assignments(args.set)
    except ConfigError as exc:
        ap.error(str(exc))
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    print(f"{'excerpt':11s} {'method':20s} {'t, cm':>6s} {'r, deg':>7s}")
    for name, (folder, sensor, kitti) in EXCERPTS.items():
        seq = open_sequence(args.root / folder, sensor=sensor)
        for m in methods:
            if m in PEERS:
                method = PeerMethod(m)
            else:
                method = OursMethod(m, config_from_dict(changes, base=variant(m), origin="--set").replace(
                    clean={"kitti_vertical_correction_deg": 0.205 if kitti else 0.0}))
            reason = method.unavailable()
            if reason:
                print(f"{name:11s} {m:20s} {reason}")
                continue
            # (read as given: the excerpt's sensor is chosen here, not by a file beside the scans)
            poses = run_method(method, seq, stage=False).poses
            t, r = pair_errors(seq.poses, poses)
            print(f"{name:11s} {m + (' (default)' if m == DEFAULT_VARIANT else ''):20s} {t:6.2f} {r:7.3f}")


if __name__ == "__main__":
    main()
