"""Open-loop registration error: each frame registered against a target built from true poses.

    python -m tools.open_loop --family open --seed 107 --sensor salo32 --methods bl,default
    python -m tools.open_loop --family tunnel --seed 101 --kind simulated --plot along.png

A closed-loop run mixes two things: the error each registration makes, and the drift
those errors feed back (a map or a motion prior built from wrong poses). Here the
odometry runs as always, but after each frame its state (pose, motion prior, de-skew,
map or target scan) advances with the true motion (``odometry.open_loop.run_open_loop``),
so every frame meets a target the truth built. What remains is the
registration's own error, printed per method over the same frames:

- per-frame translation error |t(true^-1 estimate)|, cm: median and 90th percentile;
- along-track error, (t_est - t_true) . unit(t_true), cm per frame: its mean and its sum
  over the distance travelled (%). A scan-to-scan odometry adds these up into drift; against
  a map they need not add up (the map's older points hold the pose where they constrain it),
  so compare with the closed-loop t_err before reading the sum as drift;
- vertical error (z of the sensor frame), cm per frame: mean;
- rotation error per frame, degrees: median;
- frames extrapolated (not registered: their errors are left out, their count shown);
- weakest information: the median over frames of the smallest translational eigenvalue of
  the registration's information per match (``FrameDiagnostics.translation_eigenvalues``),
  beside the truth's: the same figure of every return with its true normal, per return
  (``simlidar.degeneracy``). A method far above the truth constrains the weak direction
  with normals the scene does not have (noise on one-ring normals: evidence for standing
  still); far below, it has thrown the scene's evidence away.

The sequence is a generalisation-suite sequence (``salo experiment generalize``), drawn
for any seed; diagnose on seeds outside the evaluation split. Prints figures; ``--plot``
also writes the along-track error per frame of each method (PNG).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from simlidar import se3

MIN_MOTION_M = 0.01  # frames moving less than this have no along-track direction


@dataclasses.dataclass
class OpenLoopErrors:
    """Per-frame errors of one method's open-loop run (frames 1..F-1).

    translation_m, along_m, vertical_m: (F-1,) m; rotation_deg: (F-1,); travelled_m: (F-1,) true motion, m.
    weakest_information: (F-1,) smallest translational eigenvalue of each registration's information
    per match (dimensionless, in [0, 1]); nan where the frame was extrapolated.
    extrapolated: (F-1,) bool, frames not registered (too few points, singular, implausible): their
    errors are nan, since their estimate is the guess, which open loop makes the previous true motion.
    along_m is also nan where the frame moved less than ``MIN_MOTION_M``.
    """

    translation_m: np.ndarray
    along_m: np.ndarray
    vertical_m: np.ndarray
    rotation_deg: np.ndarray
    travelled_m: np.ndarray
    extrapolated: np.ndarray
    weakest_information: np.ndarray

    @property
    def along_bias_pct(self) -> float:
        """Sum of the along-track errors over the distance travelled, %."""
        ok = np.isfinite(self.along_m)
        return float(100.0 * self.along_m[ok].sum() / max(self.travelled_m[ok].sum(), 1e-12))


def open_loop_errors(true_poses: np.ndarray, estimated_motions: np.ndarray, diagnostics: list) -> OpenLoopErrors:
    """Errors of each frame's estimate against the true motion.

    true_poses: (F, 4, 4) of the frames run, in order (``true_poses[run.frame_indices]`` for a slice);
    estimated_motions: (F, 4, 4) each frame's estimate of its motion (``OpenLoopRun.estimated_motions``;
    the first is not used); diagnostics: the run's F frame diagnostics.
    """
    if len(diagnostics) != len(true_poses):
        raise ValueError(f"{len(diagnostics)} frame diagnostics for {len(true_poses)} true poses")
    true = se3.inverse(true_poses[:-1]) @ true_poses[1:]
    if len(estimated_motions) != len(true_poses):
        raise ValueError(f"{len(estimated_motions)} estimated motions for {len(true_poses)} true poses")
    est = np.array(estimated_motions[1:], dtype=float)
    extrapolated = np.array([d.extrapolated for d in diagnostics[1:]], dtype=bool)
    est[extrapolated] = np.nan  # every error of those frames is nan from here on
    err = se3.inverse(true) @ est
    dt = est[:, :3, 3] - true[:, :3, 3]
    travelled = np.linalg.norm(true[:, :3, 3], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.where(travelled >= MIN_MOTION_M,
                         np.einsum("ij,ij->i", dt, true[:, :3, 3]) / travelled, np.nan)
    weakest = np.array([d.translation_eigenvalues[0] for d in diagnostics[1:]], dtype=float)
    weakest[extrapolated] = np.nan
    return OpenLoopErrors(np.linalg.norm(err[:, :3, 3], axis=1), along, dt[:, 2],
                          np.degrees(se3.rotation_angle(err)), travelled, extrapolated, weakest)


def run_open_loop(sequence, true_poses: np.ndarray, method: str, changes: dict | None = None) -> OpenLoopErrors:
    """Run our ``method`` (a variant name or ``default``) open loop over an in-memory sequence."""
    from odometry.open_loop import run_open_loop as odometry_open_loop
    from tools.methods import our_config
    from tools.staging import DEFAULT_FIELDS, sensor_view

    config = our_config(method, changes)
    view = sensor_view(sequence, DEFAULT_FIELDS)  # what the odometry sees: no poses, no truth
    result = odometry_open_loop(view, config, true_poses)
    return open_loop_errors(true_poses, result.estimated_motions, result.run.diagnostics)


def plot_along(errors: dict[str, OpenLoopErrors], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for name, e in errors.items():
        ax.plot(np.arange(1, len(e.along_m) + 1), 100 * e.along_m, lw=1,
                label=f"{name} (sum {e.along_bias_pct:+.2f} % of the distance)")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("frame")
    ax.set_ylabel("along-track error, cm per frame")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    from odometry.config import ConfigError, changes_from_assignments
    from tools.family_suite import EVALUATION_SEEDS, KINDS, SENSORS, simulate, suite
    from tools.methods import MethodError, our_config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--family", required=True, help="a scene family of the generalisation suite")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--sensor", choices=SENSORS, help="default: the suite's sensor for this seed")
    ap.add_argument("--kind", choices=KINDS, default="real")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--methods", default="bl,default", help="comma-separated: default and our variants")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override an odometry parameter of every method (repeatable)")
    ap.add_argument("--plot", type=Path, help="write the along-track error per frame here (PNG)")
    args = ap.parse_args(argv)
    try:
        changes = changes_from_assignments(args.set)
        methods = args.methods.split(",")
        for method in methods:
            our_config(method)  # an unknown name fails here, before the simulation
        spec = next(s for s in suite((args.seed,), frames=args.frames, families=(args.family,)) if s.kind == args.kind)
        if args.sensor:
            spec = dataclasses.replace(spec, sensor=args.sensor)
        if args.seed in EVALUATION_SEEDS:
            print(f"note: seed {args.seed} is an evaluation seed: report on it, do not choose parameters with it")
        sequence = simulate(spec)
    except (ConfigError, MethodError, ValueError) as exc:
        print(f"open_loop: {exc}", file=sys.stderr)
        return 2
    print(f"{spec.name}: {args.frames} frames, open loop (each frame registered against a target from true poses)")
    truth = np.median([d.translation_eigenvalues[0] for d in sequence.degeneracy])
    print(f"weakest information of the true normals, per return (median over frames): {truth:.2e}")
    print(f"{'method':14s} {'t err cm':>9s} {'p90':>6s} {'along cm':>9s} {'along %':>8s} {'vert cm':>8s} "
          f"{'rot deg':>8s} {'extrapolated':>12s} {'weakest info':>12s}")
    errors = {}
    for method in methods:
        e = errors[method] = run_open_loop(sequence, sequence.poses, method, changes)
        print(f"{method:14s} {100 * np.nanmedian(e.translation_m):9.2f} "
              f"{100 * np.nanpercentile(e.translation_m, 90):6.2f} {100 * np.nanmean(e.along_m):+9.2f} "
              f"{e.along_bias_pct:+8.2f} {100 * np.nanmean(e.vertical_m):+8.2f} {np.nanmedian(e.rotation_deg):8.3f} "
              f"{int(e.extrapolated.sum()):12d} {np.nanmedian(e.weakest_information):12.2e}")
    if args.plot:
        plot_along(errors, f"{spec.name}: open-loop along-track error", args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
