"""The bare tunnel's degeneracy truth along its path: the smallest translational eigenvalue per return.

    python -m tools.view_bare_tunnel                     # /work/runs/imu/bare_tunnel_degeneracy.png
    python -m tools.view_bare_tunnel --sensor vlp16 --every 0.5 --out FILE.png

One sweep every ``--every`` seconds along the ``bare-tunnel`` scene (seed 0), its
``simlidar.degeneracy`` figures from the returns' true normals (what a sequence's
``degeneracy.csv`` holds), against the distance travelled: the bare stretch and the
stop shaded, the flag's threshold (``tools.degenerate.TRUTH_THRESHOLD``) drawn, the
speed on a second axis. Prints the weak stretches.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def profile(sensor_name: str = "salo32", every_s: float = 1.0, seed: int = 0, scene: str = "bare-tunnel"):
    """Per sweep: (times (n,) s, distance along the path (n,) m, t_eig0 (n,), speed (n,) m/s, the scene)."""
    import scenes
    from simlidar.degeneracy import degeneracy
    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator
    from tools.worlds import world_of_scene

    built = scenes.build_scene(scene, seed=seed)
    sensor = load_sensor(sensor_name)
    sim = SweepSimulator(world_of_scene(built), sensor, seed=seed)
    traj = built.trajectory
    times = np.arange(0.0, traj.duration_s - sensor.sweep_period_s, every_s)
    t_eig0 = np.array([degeneracy(s.true_xyz, s.normal).translation_eigenvalues[0]
                       for s in (sim.sweep(traj, float(t), k) for k, t in enumerate(times))])
    return times, traj.distance_at(times), t_eig0, traj.speed_at(times), built


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tools.degenerate import TRUTH_THRESHOLD

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensor", default="salo32")
    ap.add_argument("--every", type=float, default=1.0, help="seconds between the sweeps drawn")
    ap.add_argument("--out", type=Path, default=Path("/work/runs/imu/bare_tunnel_degeneracy.png"))
    args = ap.parse_args()
    times, dist, t_eig0, speed, built = profile(args.sensor, args.every)
    meta = built.metadata
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.axvspan(*meta["portal_s"], color="0.92", label="tunnel")
    ax.axvspan(*meta["bare_s"], color="0.8", label="bare walls")
    ax.semilogy(dist, np.maximum(t_eig0, 1e-7), "o-", ms=3, label="smallest translational eigenvalue per return")
    ax.axhline(TRUTH_THRESHOLD, color="r", lw=1, label=f"weak below {TRUTH_THRESHOLD:g}")
    ax.set_xlabel("distance along the path, m")
    ax.set_ylabel("t_eig0 (true normals; 0 drawn at 1e-7)")
    ax2 = ax.twinx()
    ax2.plot(dist, speed, "k:", lw=1, label="speed")
    ax2.set_ylabel("speed, m/s")
    ax.axvline(meta["stop_s"], color="k", lw=0.8)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(f"bare-tunnel (seed 0), {args.sensor}, one sweep every {args.every:g} s; stop at "
                 f"{meta['stop_s']:.0f} m")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    weak = t_eig0 < TRUTH_THRESHOLD
    edges = np.flatnonzero(np.diff(np.concatenate([[0], weak.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        print(f"weak from {dist[a]:.0f} m to {dist[b - 1]:.0f} m (t {times[a]:.1f} .. {times[b - 1]:.1f} s), "
              f"t_eig0 max {t_eig0[a:b].max():.1e}")
    (b0, b1), (p0, p1) = meta["bare_s"], meta["portal_s"]
    print(f"outside the weak stretches t_eig0 >= {t_eig0[~weak].min():.3f}; bare walls {b0:.0f} to {b1:.0f} m, "
          f"portals at {p0:.0f} and {p1:.0f} m; inside the bare walls t_eig0 <= "
          f"{t_eig0[(dist > b0) & (dist < b1)].max():.1e}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
