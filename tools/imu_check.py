"""The simulated IMU against the truth: dead reckoning from the true initial state, and the noise's Allan deviation.

    python -m tools.imu_check                       # both figures into /work/runs/imu (see --out)
    python -m tools.imu_check --what integration    # only the dead reckoning
    python -m tools.imu_check --what allan          # only the Allan deviation

**Dead reckoning** (``dead_reckon``): the noise-free samples (``ImuTruth``'s
angular velocity and specific force) integrated from the true pose and velocity of
the first sample, in the first scan's frame with its gravity. The scheme, per sample
interval dt: the attitude by the two-sample coning algorithm (rotation vector
``dt (w_k + w_k+1) / 2 + dt^2 / 12 w_k x w_k+1``, exact to third order for a rate
that is linear over the interval), the world acceleration ``a_k = R_k f_k + g`` at the
samples, and velocity and position integrated exactly for an acceleration linear
between samples (the trapezoid rule for velocity). It is a second-order scheme: the
position error of a motion with continuous acceleration shrinks as dt^2.

``integration_error_bound`` bounds its position error from the scheme's own error
terms and the truth's smoothness (no cancellation assumed, so it is loose; see its doc).

**Allan deviation** (``allan_deviation``): the overlapping estimator over cluster
times tau = m dt, of the noise alone (measured minus noise-free values, bias included).
For white noise of density N it is ``N / sqrt(tau)``, for a bias random walk of
K ``K sqrt(tau / 3)`` (IEEE Std 952's slopes -1/2 and +1/2); together
``sqrt(N^2 / tau + K^2 tau / 3)``.

Prints the figures and writes ``integration.png`` and ``allan.png``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from simlidar.se3 import hat


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """(n, 3) rotation vectors, rad -> (n, 3, 3) rotations (Rodrigues; series below 1e-8 rad)."""
    angle = np.linalg.norm(phi, axis=1)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle**2 / 6, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24, (1 - np.cos(safe)) / safe**2)
    K = hat(phi)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def dead_reckon(time_s: np.ndarray, angular_velocity: np.ndarray, specific_force: np.ndarray, R0: np.ndarray,
                p0: np.ndarray, v0: np.ndarray, gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Strapdown integration of (n,) times, (n, 3) rad/s and (n, 3) m/s^2 from the state at the first sample.

    R0: (3, 3) the IMU's attitude, p0, v0: (3,) its position (m) and velocity (m/s), gravity: (3,) m/s^2,
    all in one frame. Returns (n, 3, 3) attitudes, (n, 3) positions, (n, 3) velocities (see the module doc).
    """
    dt = np.diff(time_s)[:, None]
    w0, w1 = angular_velocity[:-1], angular_velocity[1:]
    phi = dt * (w0 + w1) / 2 + dt**2 / 12 * np.cross(w0, w1)
    steps = so3_exp(phi)
    R = np.empty((len(time_s), 3, 3))
    R[0] = R0
    for k in range(len(steps)):
        R[k + 1] = R[k] @ steps[k]
    a = np.einsum("nij,nj->ni", R, specific_force) + gravity
    dv = dt * (a[:-1] + a[1:]) / 2
    v = np.vstack([v0, v0 + np.cumsum(dv, axis=0)])
    dp = dt * v[:-1] + dt**2 * (2 * a[:-1] + a[1:]) / 6
    p = np.vstack([p0, p0 + np.cumsum(dp, axis=0)])
    return R, p, v


def reckon_truth(truth, until_s: float | None = None):
    """``dead_reckon`` of an ``ImuTruth``'s noise-free samples (up to ``until_s`` after the first) from its
    first state; returns (times (n,), position error (n,) m, attitude error (n,) rad)."""
    from scipy.spatial.transform import Rotation

    n = len(truth) if until_s is None else int(np.searchsorted(truth.time_s, truth.time_s[0] + until_s + 1e-9))
    Rt = Rotation.from_quat(truth.orientation[:n]).as_matrix()
    R, p, _ = dead_reckon(truth.true_time_s[:n], truth.angular_velocity[:n], truth.specific_force[:n], Rt[0],
                          truth.position[0], truth.velocity[0], truth.gravity)
    angle = Rotation.from_matrix(np.swapaxes(Rt, 1, 2) @ R).magnitude()
    return truth.true_time_s[:n] - truth.true_time_s[0], np.linalg.norm(p - truth.position[:n], axis=1), angle


def window_errors(truth, window_s: float = 0.1) -> np.ndarray:
    """``dead_reckon`` over consecutive windows of ``window_s`` (a sweep: what a preintegration between scans
    spans), each from the true state at its start: (m,) the position error at each window's end, m."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(truth.orientation).as_matrix()
    step = int(round(window_s / np.median(np.diff(truth.time_s))))
    out = []
    for k in range(0, len(truth) - step, step):
        w = slice(k, k + step + 1)
        _, p, _ = dead_reckon(truth.true_time_s[w], truth.angular_velocity[w], truth.specific_force[w], R[k],
                              truth.position[k], truth.velocity[k], truth.gravity)
        out.append(np.linalg.norm(p[-1] - truth.position[k + step]))
    return np.array(out)


def integration_error_bound(trajectory, model, t_start: float, seconds: float, substeps: int = 16):
    """A worst-case bound of ``reckon_truth``'s position error, from the scheme and the truth's smoothness.

    On each sample interval I (length dt), with the truth evaluated ``substeps`` times finer
    (``kinematics_at``; TV: total variation over I, jumps included, from those samples):

    - attitude: the rotation vector of the step differs from the true one by at most the
      trapezoid rule's error on the rate, ``dt^2 / 8 TV(w')`` (Peano kernel), plus the coning
      correction's, ``dt^3 / 8 |w|max TV(w')`` (the rotation-vector series' next term,
      fourth order, is left out: it is |w| dt ~ 1e-3 of these); the errors of the steps add up
      (rotations are isometries), giving a bound dtheta_k at each sample;
    - position: the scheme integrates exactly the acceleration linear between its samples
      ``R_k f_k + g``; these are off by at most ``|f| dtheta_k``, and the true acceleration
      departs from its linear interpolation by at most ``min(dt TV(a), dt^2 / 8 TV(a'))``
      integrated over I; an error of acceleration over I moves the position at T by at most
      (T - t_k) times its integral.

    So B(T) = sum_k (T - t_k) [dt |f|max,I max(dtheta_k, dtheta_k+1) + min(dt TV_I(a), dt^2/8 TV_I(a'))].
    It assumes no cancellation between intervals (the oscillating suspension's errors largely
    cancel in fact), so it is far above the error; a model error that biases the specific force by
    b adds b T^2 / 2, which it does not cover once b is larger than ~2 B(T) / T^2.

    Returns (n,) times since the first sample, s, and (n,) the bound, m.
    """
    dt = model.sample_period_s
    n = int(math.floor(seconds * model.update_rate + 1e-9)) + 1
    m = int(substeps)
    h = dt / m
    times = t_start - model.time_offset_s + np.arange((n - 1) * m + 1) * h
    k = trajectory.kinematics_at(times)
    R, w, alpha = k.pose[:, :3, :3], k.angular_velocity, k.angular_acceleration
    r = np.asarray(model.lever_arm_m)
    accel = k.acceleration + np.einsum("nij,nj->ni", R, np.cross(alpha, r) + np.cross(w, np.cross(w, r)))
    force = np.einsum("nji,nj->ni", R, accel - np.array([0.0, 0.0, -model.gravity_m_s2]))  # its norm is the IMU's

    def per_interval(values: np.ndarray, how) -> np.ndarray:  # (n - 1) reductions over each interval's substeps
        return how(values.reshape(n - 1, m), axis=1)

    def variation(x: np.ndarray) -> np.ndarray:
        return per_interval(np.linalg.norm(np.diff(x, axis=0), axis=1), np.sum)

    def variation_of_rate(x: np.ndarray) -> np.ndarray:
        rate = np.diff(x, axis=0) / h
        return per_interval(np.append(np.linalg.norm(np.diff(rate, axis=0), axis=1), 0.0), np.sum)

    tv_alpha = variation(alpha)
    w_max = per_interval(np.linalg.norm(w, axis=1)[:-1], np.max)
    theta = np.concatenate([[0.0], np.cumsum(dt**2 / 8 * tv_alpha + dt**3 / 8 * w_max * tv_alpha)])
    f_max = per_interval(np.linalg.norm(force, axis=1)[:-1], np.max) + variation(force)
    local = dt * f_max * np.maximum(theta[:-1], theta[1:]) + np.minimum(dt * variation(accel),
                                                                         dt**2 / 8 * variation_of_rate(accel))
    t = np.arange(n) * dt
    # B(t_j) = sum_{k < j} (t_j - t_k) local_k
    s0 = np.concatenate([[0.0], np.cumsum(local)])
    s1 = np.concatenate([[0.0], np.cumsum(local * t[:-1])])
    return t, t * s0 - s1


def allan_deviation(x: np.ndarray, rate_hz: float, m: np.ndarray) -> np.ndarray:
    """Overlapping Allan deviation of (n,) or (n, k) samples at cluster sizes ``m`` (samples), per column.

    tau = m / rate_hz. sigma^2(tau) = 1 / (2 (n - 2m + 1)) sum_j (ybar_{j+m} - ybar_j)^2 over the means
    ybar_j of m consecutive samples starting at j.
    """
    x = np.asarray(x, dtype=float)
    x2 = x.reshape(len(x), -1)
    c = np.vstack([np.zeros((1, x2.shape[1])), np.cumsum(x2, axis=0)])
    out = []
    for mi in np.asarray(m, dtype=int):
        mean = (c[mi:] - c[:-mi]) / mi  # (n - m + 1, k) means of m consecutive samples
        d = mean[mi:] - mean[:-mi]
        out.append(np.sqrt(0.5 * np.mean(d**2, axis=0)))
    result = np.array(out)
    return result if x.ndim > 1 else result[:, 0]


def allan_model(tau: np.ndarray, density: float, walk: float) -> np.ndarray:
    """The Allan deviation of white noise of density N plus a random walk of K: sqrt(N^2 / tau + K^2 tau / 3)."""
    tau = np.asarray(tau, dtype=float)
    return np.sqrt(density**2 / tau + walk**2 * tau / 3)


def cluster_sizes(n: int, per_decade: int = 8, min_clusters: int = 9) -> np.ndarray:
    """Cluster sizes m, log-spaced from 1, leaving at least ``min_clusters`` clusters of n samples."""
    top = max(1, n // min_clusters)
    return np.unique(np.round(np.logspace(0, math.log10(top), int(per_decade * math.log10(max(top, 10))) + 1)).astype(
        int))


# ---------------------------------------------------------------- figures
MOUNTING = dict(lever_arm_m=(0.3, -0.2, -0.4), rotation_rpy_deg=(180.0, 0.0, 90.0), time_offset_s=0.004)


def integration_figure(out: Path, seconds: float = 60.0, start_s: float = 2.0) -> list[str]:
    """Dead reckoning of the noise-free IMU (mounted with ``MOUNTING``) from ``start_s`` along the bare tunnel
    (with the bound of ``integration_error_bound``) and the city (its raw speed profile, and smoothed):
    position error against time at 200 and 400 Hz. Returns the lines printed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from simlidar.imu import ImuModel, simulate_imu
    from tools.worlds import build_scene_world

    lines = []
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4), sharey=True)
    runs = ((axes[0], "bare-tunnel", {}, "-"), (axes[1], "city", {}, "-"),
            (axes[1], "city", {"accel_smoothing_s": 1.0}, "-."))
    for ax, scene, overrides, style in runs:
        traj = build_scene_world(scene, 0, overrides).trajectory
        label = "smoothed 1 s" if overrides else ("smoothed 1 s (its default)" if scene == "bare-tunnel" else "raw")
        for rate, width in ((200.0, 1.6), (400.0, 0.8)):
            model = ImuModel(enabled=True, update_rate=rate, **MOUNTING)
            _, truth = simulate_imu(traj, model, start_s, seconds, seed=0)
            t, e_p, e_r = reckon_truth(truth)
            at = [float(np.interp(s, t, e_p)) for s in (10.0, 60.0)]
            line = (f"{scene} ({label}) {rate:g} Hz: position error {at[0]:.1e} m after 10 s, {at[1]:.1e} m after "
                    f"60 s; attitude error {np.interp(60.0, t, e_r):.1e} rad after 60 s")
            ax.semilogy(t[1:], e_p[1:], style, lw=width, label=f"{label}, {rate:g} Hz")
            if rate == 200.0:
                w = window_errors(truth)
                line += (f"; over each 0.1 s ({len(w)}): median {np.median(w):.1e} m, 99th percentile "
                         f"{np.percentile(w, 99):.1e} m, max {w.max():.1e} m")
            if scene == "bare-tunnel" and rate == 200.0:
                tb, bound = integration_error_bound(traj, model, start_s, seconds)
                ax.semilogy(tb[1:], bound[1:], "k--", lw=0.8, label="worst-case bound, 200 Hz")
                line += f" (bound {np.interp(10.0, tb, bound):.1e} m, {np.interp(60.0, tb, bound):.1e} m)"
            lines.append(line)
    for ax, title in zip(axes, ("bare-tunnel (seed 0)", "city (seed 0)"), strict=True):
        for s in (10.0, 60.0):
            ax.axvline(s, color="0.7", lw=0.8)
        ax.set_title(title)
        ax.set_xlabel(f"time since the true initial state (t = {start_s:g} s on the path), s")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("position error of the dead reckoning, m")
    fig.suptitle("Noise-free IMU integrated from the true initial state (lever arm (0.3, -0.2, -0.4) m, axes "
                 "rotated, clock 4 ms ahead)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "integration.png", dpi=100)
    return lines


def allan_figure(out: Path, hours: float = 3.0, seed: int = 0) -> list[str]:
    """The Allan deviation of ``hours`` of the default model's noise, per axis, against its model lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from simlidar.imu import ImuModel, noise

    model = ImuModel(enabled=True)
    n = int(hours * 3600 * model.update_rate)
    white_g, bias_g, white_a, bias_a = noise(model, n, seed)
    m = cluster_sizes(n)
    tau = m / model.update_rate
    lines = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (name, x, density, walk, unit) in zip(axes, (
            ("gyroscope", white_g + bias_g, model.gyroscope_noise_density, model.gyroscope_random_walk, "rad/s"),
            ("accelerometer", white_a + bias_a, model.accelerometer_noise_density, model.accelerometer_random_walk,
             "m/s^2")), strict=True):
        adev = allan_deviation(x, model.update_rate, m)
        for i, axis in enumerate("xyz"):
            ax.loglog(tau, adev[:, i], ".", ms=3, label=f"{axis}")
        ax.loglog(tau, allan_model(tau, density, walk), "k-", lw=1, label="sqrt(N^2/tau + K^2 tau/3)")
        ax.loglog(tau, density / np.sqrt(tau), "k:", lw=0.8, label="N / sqrt(tau)")
        ax.loglog(tau, walk * np.sqrt(tau / 3), "k--", lw=0.8, label="K sqrt(tau/3)")
        ax.set_title(f"{name}: N = {density:g}, K = {walk:g}")
        ax.set_xlabel("tau, s")
        ax.set_ylabel(f"Allan deviation, {unit}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        ratio = adev / allan_model(tau, density, walk)[:, None]
        at1 = int(np.argmin(np.abs(tau - 1.0)))
        lines.append(f"{name}: ADEV / model at tau = {tau[at1]:.2f} s: {', '.join(f'{r:.3f}' for r in ratio[at1])}; "
                     f"over tau {tau[0]:.3g} .. {tau[-1]:.0f} s: {ratio.min():.3f} .. {ratio.max():.3f}")
    fig.suptitle(f"Allan deviation of {hours:g} h of simulated IMU noise ({model.update_rate:g} Hz, seed {seed})")
    fig.tight_layout()
    fig.savefig(out / "allan.png", dpi=110)
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--what", choices=("both", "integration", "allan"), default="both")
    ap.add_argument("--out", type=Path, default=Path("/work/runs/imu"), help="folder for the PNGs")
    ap.add_argument("--hours", type=float, default=3.0, help="length of the noise for the Allan deviation")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.what in ("both", "integration"):
        for line in integration_figure(args.out):
            print(line)
    if args.what in ("both", "allan"):
        for line in allan_figure(args.out, args.hours):
            print(line)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
