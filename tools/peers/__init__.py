"""Peer odometry methods run on our frames through their Python APIs: what the peers share.

The peers are methods like ours (``tools.methods.PeerMethod`` runs them through the one
interface, ``tools.methods.run_method``). The peers (optional extra ``peer``:
``pip install -e '.[peer]'``), one module each:

- ``kiss-icp`` (``kiss_icp``): KISS-ICP (Vizzo et al., RA-L 2023), point-to-point
  ICP against a voxel-hash local map, adaptive threshold, constant-velocity de-skew.
- ``genz-icp`` (``genz_icp``): GenZ-ICP (Lee et al., RA-L 2025), a KISS-ICP fork
  that weights point-to-plane against point-to-point residuals by local planarity.
- ``small-gicp`` (``small_gicp``): a scan-to-map pipeline over small_gicp (Koide,
  JOSS 2024): GICP of each downsampled scan against a Gaussian voxel map that forgets
  voxels not seen for 100 frames, from a constant-velocity guess; no de-skew.

They run on the same frames as our odometry (the finite measured points and, when
the scans are distorted, their per-point firing times), with the same range limits
(ours, capped at ``PEER_MAX_RANGE_M``, KISS-ICP's and GenZ-ICP's default), so all
see the same points. Each runner returns a ``tools.runners.MethodRun`` (with the peer's
own poses and their instants); ``peer_unavailable_reason`` says why a peer cannot run
(not installed, too old), and the table and the odometry bench print that instead of a row.

Which instant a peer's pose belongs to. Our ground truth and our odometry give the
sensor pose at each sweep's *start*. A peer's pose of frame k belongs to the
instant ``k + phi_k`` (in sweep periods), ``phi_k`` the frame's pose instant:

- 0 when the frame carries no per-point times (``scan_times`` is None): the scan
  is motion-compensated or instantaneous (real KITTI's ``.bin`` files, a simulation
  without motion distortion), no peer de-skews it, and its pose is that of the
  scan's own frame, the sweep start. No shift applies.
- With per-point times (raw, distorted scans):

  - 1 for KISS-ICP (1.x) once it de-skews: it maps the times to [0, 1] and moves
    each point by ``exp((s - 1) log(delta))``, to the sweep's last firing (to one
    azimuth step, the start of the next sweep);
  - 0.5 for GenZ-ICP with de-skew on: it moves each point by
    ``exp((s - 0.5) log(delta))`` (KISS-ICP 0.x's rule), the middle of the sweep;
  - ``UNDESKEWED_INSTANT`` (0.5) for a distorted scan that is not de-skewed
    (small_gicp; KISS-ICP's first two frames and GenZ-ICP's first three, while
    their motion estimate is still missing): a rigid registration of a distorted
    scan places it at about the middle of its firing times.

``tests/test_peers.py`` measures each peer's residual time offset against the
sweep starts, with and without times, on a simulated drive whose sensor oscillates
in yaw (a time offset then shows in every frame's relative pose): 0.00 frame
without times (-0.46 and -0.92 with a half- and a one-frame shift, the latter the
old treatment of time-less frames); with times -0.02 for GenZ-ICP and small_gicp,
and -0.18 for KISS-ICP, whose de-skew uses the previous frame's motion: under the
oscillation's angular acceleration its pose falls a little before the sweep's end
(+1.14 without the shift).

``sweep_start_poses`` turns poses at these instants into sweep-start poses, the one
place where the convention is applied: the start of sweep k lies between frame
k-1's pose (at ``k - 1 + phi_{k-1}``) and frame k's (at ``k + phi_k``), and is
screw-interpolated there; sweep 0's start is extrapolated back along the first
interval; all are then expressed relative to sweep 0's start (``poses[0]`` is the
identity, as everywhere else). With phi = 1 this is the one-frame shift
``start[k] = end[k - 1]``; with phi = 0 it changes nothing.
"""

from __future__ import annotations

import importlib
import logging
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from simlidar import se3
from simlidar.sequence import deskew_times, method_frame
from tools.runners import MethodRun

log = logging.getLogger(__name__)

# The far range limit of every peer, m: KISS-ICP's and GenZ-ICP's default max_range.
PEER_MAX_RANGE_M = 100.0
# Pose instant (sweep periods after the sweep start) of a scan without per-point times.
TIMELESS_INSTANT = 0.0
# Pose instant of a distorted scan registered as it is (not de-skewed).
UNDESKEWED_INSTANT = 0.5
INSTALL_HINT = "pip install -e '.[peer]'"


@dataclass(frozen=True)
class PeerSpec:
    """One peer: its method key, table label, pip distribution, the module that must
    import, the oldest version the runner is written for (the ``peer`` extra's floor,
    the version the pose-instant conventions were checked on), and its runner."""

    name: str
    label: str
    distribution: str
    module: str
    min_version: str
    runner: str  # "module:function"


PEERS: dict[str, PeerSpec] = {p.name: p for p in (
    PeerSpec("kiss-icp", "KISS-ICP", "kiss-icp", "kiss_icp.kiss_icp", "1.3",
             "tools.peers.kiss_icp:run_kiss_icp"),
    PeerSpec("genz-icp", "GenZ-ICP", "genz-icp", "genz_icp.genz_icp", "0.3.2",
             "tools.peers.genz_icp:run_genz_icp"),
    PeerSpec("small-gicp", "small_gicp s2m", "small_gicp", "small_gicp", "1.0.1",
             "tools.peers.small_gicp:run_small_gicp"),
)}


class PeerUnavailable(ImportError):
    """A peer cannot run here (not installed, or older than the runner is written for)."""


def _spec(name: str) -> PeerSpec:
    try:
        return PEERS[name]
    except KeyError:
        raise ValueError(f"unknown peer {name!r} (known: {', '.join(PEERS)})") from None


def _version_tuple(text: str) -> tuple[int, ...]:
    """Leading numeric release parts of a version string: "1.3.0rc1" -> (1, 3, 0)."""
    parts = []
    for piece in text.split("."):
        m = re.match(r"\d+", piece)
        if m is None:
            break
        parts.append(int(m.group()))
        if m.end() < len(piece):
            break
    return tuple(parts)


def peer_version(name: str) -> str | None:
    """The installed version of a peer's distribution, or None."""
    try:
        return version(_spec(name).distribution)
    except PackageNotFoundError:
        return None


def peer_unavailable_reason(name: str) -> str | None:
    """Why peer ``name`` cannot run here (a sentence for a table row), or None when it can."""
    spec = _spec(name)
    try:
        importlib.import_module(spec.module)
    except ImportError:
        return f"not installed ({INSTALL_HINT})"
    found = peer_version(name)
    if found is not None and _version_tuple(found) < _version_tuple(spec.min_version):
        return (f"{spec.distribution} {found} is older than {spec.min_version}, the version its pose "
                f"convention was checked on ({INSTALL_HINT})")
    return None


def peer_available(name: str) -> bool:
    """True when peer ``name`` imports and is recent enough."""
    return peer_unavailable_reason(name) is None


def require_peer(name: str) -> None:
    """Raise ``PeerUnavailable`` (an ImportError) naming the reason when peer ``name`` cannot run."""
    reason = peer_unavailable_reason(name)
    if reason is not None:
        raise PeerUnavailable(f"{_spec(name).label}: {reason}")


def range_limits(min_range_m: float, max_range_m: float) -> tuple[float, float]:
    """The range limits every peer gets, m: ours, the far one capped at ``PEER_MAX_RANGE_M``."""
    return float(min_range_m), min(float(max_range_m), PEER_MAX_RANGE_M)


# ---------------------------------------------------------------- the pose-instant convention
def scan_times(sequence, frame) -> np.ndarray | None:
    """A frame's per-point times for de-skewing (``simlidar.sequence.deskew_times``)."""
    return deskew_times(sequence, frame)


def pose_instant(times: np.ndarray | None, deskewed_to: float | None) -> float:
    """Pose instant of a frame, sweep periods after its start (see the module notes).

    times: the frame's per-point times as given to the peer (None: none).
    deskewed_to: the instant the peer de-skewed this frame to, or None when it did not.
    """
    if times is None:
        return TIMELESS_INSTANT
    return UNDESKEWED_INSTANT if deskewed_to is None else float(deskewed_to)


def sweep_start_poses(poses: np.ndarray, instants) -> np.ndarray:
    """Poses (N, 4, 4) at instants ``k + instants[k]`` -> sweep-start poses (N, 4, 4), the first the identity.

    poses: a peer's poses, frame k's at ``k + instants[k]`` sweep periods.
    instants: (N,) or a scalar, each in [0, 1].
    See the module notes for the interpolation.
    """
    poses = np.asarray(poses, dtype=np.float64)
    n = len(poses)
    if n == 0:
        raise ValueError("no poses")
    phi = np.broadcast_to(np.asarray(instants, dtype=np.float64), (n,))
    if not np.all((phi >= 0.0) & (phi <= 1.0)):
        raise ValueError("pose instants must lie in [0, 1] sweep periods")
    if n == 1:
        return np.eye(4)[None]
    at = np.arange(n) + phi  # each pose's instant, sweep periods
    span = np.diff(at)  # >= 0
    tiny = 1e-12
    frac = np.where(span > tiny, (np.arange(1, n) - at[:-1]) / np.maximum(span, tiny), 1.0)
    starts = np.empty_like(poses)
    starts[1:] = se3.interpolate(poses[:-1], poses[1:], frac)
    starts[0] = se3.interpolate(poses[0], poses[1], -phi[0] / span[0]) if span[0] > tiny else poses[0]
    return se3.inverse(starts[0]) @ starts


# ---------------------------------------------------------------- the run
# register(points (M, 3) float64 m, times (M,) float64 s or None) -> (pose (4, 4), pose instant)
Register = Callable[[np.ndarray, "np.ndarray | None"], "tuple[np.ndarray, float]"]


def valid_pose(T: np.ndarray) -> bool:
    """True for a finite (4, 4) rigid transform (rotation orthonormal to 1e-6)."""
    T = np.asarray(T)
    return bool(np.all(np.isfinite(T)) and np.abs(T[:3, :3] @ T[:3, :3].T - np.eye(3)).max() < 1e-6)


def run_frames(name: str, sequence, register: Register, config: dict, frames: slice | None = None,
               on_frame: Callable[[int], None] | None = None) -> MethodRun:
    """The loop every peer shares: feed each frame to ``register``, convert to sweep-start poses.

    Each frame's finite points (and their times, see ``scan_times``) go to
    ``register``, which returns the peer's pose after that frame and the frame's
    pose instant (``pose_instant``). A pose that is not a finite rigid transform
    ends the run (the peer diverged): that frame and the rest get NaN poses and
    ``config["diverged_at_frame"]`` says where. ``config`` is completed with the
    peer's version and the input kind (the run's ``settings``). ``frames``: which frames
    (default all); ``on_frame(k)`` after each (progress). Returns the run: sweep-start
    poses, the wall time of the loop (reading frames included, as for our odometry), the
    peer's own poses and their instants (NaN from a divergence on).
    """
    idx = np.arange(len(sequence))[frames if frames is not None else slice(None)]
    n = len(idx)
    if n == 0:
        raise ValueError(f"{name}: no frames to run")
    method_poses = np.full((n, 4, 4), np.nan)
    instants = np.full(n, np.nan)
    timed, diverged_at = 0, None
    t0 = time.perf_counter()
    for i, k in enumerate(idx):
        frame = method_frame(sequence, int(k))
        pts = np.asarray(frame.points, dtype=np.float64)
        keep = np.all(np.isfinite(pts), axis=1)
        times = scan_times(sequence, frame)
        if times is not None:
            keep &= np.isfinite(times)
            times = np.ascontiguousarray(times[keep])
            timed += 1
        pose, instant = register(np.ascontiguousarray(pts[keep]), times)
        if on_frame is not None:
            on_frame(int(k))
        if not valid_pose(pose):
            diverged_at = int(k)
            log.warning("%s diverged at frame %d (not a finite rigid transform); the rest of the run is NaN",
                        name, diverged_at)
            break
        method_poses[i], instants[i] = pose, instant
    seconds = time.perf_counter() - t0
    done = int(np.sum(np.isfinite(instants)))
    poses = np.full((n, 4, 4), np.nan)
    poses[:done] = sweep_start_poses(method_poses[:done], instants[:done]) if done else np.nan
    config = {**config, "version": peer_version(name), "frames": n, "frames_with_times": timed,
              "diverged_at_frame": diverged_at}
    log.info("%s: %d frames (%d with per-point times) in %.1f s", name, n, timed, seconds)
    return MethodRun(name, poses, seconds, note=f"{name} {config['version']}", settings=config,
                     method_poses=method_poses, instants=instants)


def run_peer(name: str, sequence, **kwargs) -> MethodRun:
    """Run peer ``name`` over ``sequence`` (kwargs: its runner's: ``min_range_m``, ``max_range_m``,
    ``frames``, ``on_frame``, ...). Raises ``PeerUnavailable`` when it cannot run here."""
    module, func = _spec(name).runner.split(":")
    return getattr(importlib.import_module(module), func)(sequence, **kwargs)
