"""Geometric correspondence rejector (GCR): Sec. III-B of Kovalenko et al., "Sensor Aware Lidar Odometry" (2019).

A match (p_k, p'_k) is kept when ``|p_k - p'_k| < max_l d_kl``: the matching
distance must be shorter than the farthest *neighbour beam distance*, the
distance from p_k to where one of the four neighbour beams of p_k's beam (the
rings above and below, one azimuth step either side) would hit the surface
through p_k with normal n_k. A match farther away than any neighbour beam
could reach on that surface was probably made with another surface.

The paper's construction, and what this module makes of it:

- ``u = p x p_ground``, ``v = p x u`` with ``p_ground = (p_x, p_y, 0)``:
  ``p x p_ground = z (-y, x, 0)`` is horizontal and perpendicular to the beam,
  i.e. along increasing azimuth, but its length is ``|z| rho`` and its sign
  follows z (zero for a point at sensor height); ``v`` is then along increasing
  elevation with length ``r |z| rho``. Since ``p_kl`` is then scaled by
  ``|p_k|`` and the angles, the intended u, v are *unit* vectors: the small-angle
  offset of a neighbour beam at range r is ``r phi`` along u and ``r theta``
  along v. We normalise them, ``u = (-y, x, 0) / rho`` and ``v = p_hat x u``.
  (The signs do not matter: all four sign combinations are taken.)
- Adjacent columns on a ring at elevation e are ``phi cos(e)`` apart in angle
  (the azimuth circle at elevation e has radius cos e). We include the cos e
  (<0.7 % for the SALO 32-beam table, 9 % of the azimuth part on the HDL-64E's
  lowest rings).
- ``p_kl = r (+-phi cos(e) u +- theta_{j+-1, j} v)``: offsets towards the
  rings below (pitch ``ring_pitch_below_rad[j]``) and above
  (``ring_pitch_above_rad[j]``), each with the previous and next azimuth step;
  the lowest and highest rings have no neighbour on one side (nan).
- The neighbour beam is taken parallel to p_k's beam (the paper's "segment of
  the sphere approximated by a plane"); its hit on the plane through p_k with
  normal n is ``p_k + p_kl + t p_hat`` with ``t = -(p_kl . n) / (p_hat . n)``, so::

      d_kl = sqrt(|p_kl|^2 + (p_kl . n)^2 / (p_hat . n)^2)        ("beam", default)

  which is what the paper's text describes ("projection of p_kl onto the
  reflecting surface along the laser beam flight direction"). The paper's
  printed formula ``|p_kl|^2 / sqrt(|p_kl|^2 - (p_kl . n)^2)`` = ``|p_kl| / sin``
  (angle between p_kl and n) agrees with it only when n lies in the plane of
  p_hat and p_kl; otherwise it is smaller (it is a lower bound). It is
  available as ``formula="paper"``. The parallel-beam approximation itself
  errs by about ``|offset angle| tan(incidence)``: < 1 % for the SALO sensor
  up to 60 deg incidence.
- Grazing incidence: as ``p_hat . n -> 0`` the neighbour beam runs along the
  surface and meets it arbitrarily far away, ``d_kl -> inf``; the threshold is
  then infinite and the match is kept (the rejector cannot bound it). This is
  explicit here (``p_hat . n == 0`` gives ``inf``, never a division warning).
  The printed formula does not see grazing: it stays finite there and is
  infinite only when ``p_kl`` is parallel to n (handled the same way).

All of this is in the frame of the sensor that measured p_k (the source scan's
own frame, sensor at the origin); the matching distance is frame-independent.

KITTI: its HDL-64E scans carry a vertical-angle calibration error. Deschaud's
IMLS-SLAM (ICRA 2018) found the beams about 0.22 deg higher than the points
say; CT-ICP and KISS-ICP correct it on reading by rotating every point up by
0.205 deg about the horizontal axis ``p x z`` (PIN-SLAM and MULLS use 0.195).
``correct_kitti_vertical_angle`` does that rotation; ``ring_of_points`` takes
the same correction when assigning rings from elevation.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from .kernels.gcr import neighbour_beam_distance_table, row_max_with_floor

KITTI_VERTICAL_ANGLE_CORRECTION_DEG = 0.205

# Column order of ``neighbour_beam_distances``: (vertical side, azimuth side),
# -1 = ring below / azimuth - phi, +1 = ring above / azimuth + phi.
NEIGHBOUR_OFFSETS = ((-1, -1), (-1, +1), (+1, -1), (+1, +1))


def elevation_rad(points: np.ndarray) -> np.ndarray:
    """(N,) elevation of (N, 3) points seen from the origin, rad."""
    p = np.asarray(points, dtype=np.float64)
    return np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]))


def correct_kitti_vertical_angle(
    points: np.ndarray, angle_deg: float = KITTI_VERTICAL_ANGLE_CORRECTION_DEG
) -> np.ndarray:
    """Raise every point's elevation by ``angle_deg``, keeping its range and azimuth.

    The rotation of each point p by the angle about the horizontal axis
    ``(p x z) / |p x z|``. With ``rho = |(x, y)|`` it reads
    ``p' = p cos(a) + sin(a) (-x z / rho, -y z / rho, rho)``. Points on the z
    axis (rho = 0) are returned unchanged.

    Args:
        points: (N, 3) KITTI velodyne points, m (extra columns, e.g. intensity,
            are not accepted: pass ``scan[:, :3]``).
        angle_deg: the correction, degrees (0.205 as CT-ICP / KISS-ICP; IMLS-SLAM
            reported 0.22).

    Returns:
        (N, 3) float64 corrected points.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {p.shape}")
    a = math.radians(angle_deg)
    rho = np.hypot(p[:, 0], p[:, 1])
    ok = rho > 0
    out = p.copy()
    s, c = math.sin(a), math.cos(a)
    z_over_rho = np.divide(p[:, 2], rho, out=np.zeros_like(rho), where=ok)
    out[:, 0] = np.where(ok, p[:, 0] * (c - s * z_over_rho), p[:, 0])
    out[:, 1] = np.where(ok, p[:, 1] * (c - s * z_over_rho), p[:, 1])
    out[:, 2] = np.where(ok, p[:, 2] * c + s * rho, p[:, 2])
    return out


def ring_of_points(points: np.ndarray, sensor, vertical_correction_deg: float = 0.0) -> np.ndarray:
    """Ring of each point from its elevation, for scans without a ring field.

    The nearest ring of ``sensor``'s elevation table (``LidarModel.ring_of_elevation``).

    Args:
        points: (N, 3) points in the sensor frame, m.
        sensor: ``simlidar.sensor.LidarModel``.
        vertical_correction_deg: added to every elevation first, degrees: use
            ``KITTI_VERTICAL_ANGLE_CORRECTION_DEG`` for raw KITTI scans (not for
            scans already passed through ``correct_kitti_vertical_angle``).

    Returns:
        (N,) int32 ring indices (0 = lowest).
    """
    el = elevation_rad(points) + math.radians(vertical_correction_deg)
    return sensor.ring_of_elevation(el)


def neighbour_beam_distances(
    points: np.ndarray,
    normals: np.ndarray,
    rings: np.ndarray,
    sensor,
    formula: Literal["beam", "paper"] = "beam",
) -> np.ndarray:
    """The paper's neighbour beam distances d_kl for each point.

    Args:
        points: (M, 3) points in the frame of the sensor that measured them, m.
        normals: (M, 3) unit surface normals at the points, same frame.
        rings: (M,) int ring of each point (0 = lowest).
        sensor: ``simlidar.sensor.LidarModel`` (phi = ``azimuth_step_rad``,
            ring pitches from its elevation table).
        formula: "beam" (projection along the beam, the paper's stated intent) or
            "paper" (the formula as printed), see the module notes.

    Returns:
        (M, 4) distances, m, columns in ``NEIGHBOUR_OFFSETS`` order: (ring below,
        azimuth - phi), (below, + phi), (above, - phi), (above, + phi); nan where
        the ring has no neighbour on that side; inf at grazing incidence.
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    rings = np.asarray(rings)
    if p.shape != n.shape or p.ndim != 2 or p.shape[1] != 3 or rings.shape != (len(p),):
        raise ValueError(f"need (M, 3) points and normals and (M,) rings, got {p.shape}, {n.shape}, {rings.shape}")
    if formula not in ("beam", "paper"):
        raise ValueError(f"formula must be 'beam' or 'paper', got {formula!r}")
    if len(rings) and (rings.min() < 0 or rings.max() >= sensor.rings):
        raise ValueError(f"rings must be in [0, {sensor.rings}), got {rings.min()} .. {rings.max()}")
    # (one compiled pass: the formulas are in the kernel's docstring and the module notes)
    return neighbour_beam_distance_table(
        np.ascontiguousarray(p), np.ascontiguousarray(n),
        np.ascontiguousarray(sensor.ring_pitch_below_rad[rings], dtype=np.float64),
        np.ascontiguousarray(sensor.ring_pitch_above_rad[rings], dtype=np.float64),
        float(sensor.azimuth_step_rad), _OFFSETS, formula == "paper")


_OFFSETS = np.array(NEIGHBOUR_OFFSETS, dtype=np.int64)


def gcr_threshold_m(
    points: np.ndarray,
    normals: np.ndarray,
    rings: np.ndarray,
    sensor,
    formula: Literal["beam", "paper"] = "beam",
    noise_floor_m: float = 0.0,
) -> np.ndarray:
    """(M,) rejection threshold ``max_l d_kl`` per source point, m.

    Depends only on the source scan (its points and normals in their own sensor
    frame), not on the ICP iterate: compute it once per scan.

    Args:
        points, normals, rings, sensor, formula: as ``neighbour_beam_distances``.
        noise_floor_m: lower bound on the threshold, m. 0 (default) is the paper.
            Close to the sensor d_kl shrinks with range (about 2.4 cm at 5 m for
            the SALO sensor) below the spread that range noise gives true
            matches; a floor of a few range-noise sigmas keeps those.

    Returns:
        (M,) thresholds: inf at grazing incidence, nan where no neighbour beam
        exists (a single-ring sensor) or the input is not finite.
    """
    return row_max_with_floor(neighbour_beam_distances(points, normals, rings, sensor, formula), float(noise_floor_m))


def gcr_keep(
    source_points_in_sensor_frame: np.ndarray,
    source_normals: np.ndarray,
    source_rings: np.ndarray,
    match_distances: np.ndarray,
    sensor,
    formula: Literal["beam", "paper"] = "beam",
    noise_floor_m: float = 0.0,
    thresholds_m: np.ndarray | None = None,
) -> np.ndarray:
    """The rejector: keep a match when ``|p_k - p'_k| < max_l d_kl``.

    Args:
        source_points_in_sensor_frame: (M, 3) matched source points p_k in the
            frame of the sensor that measured them (not the ICP-transformed ones), m.
        source_normals: (M, 3) their unit normals, same frame.
        source_rings: (M,) their rings.
        match_distances: (M,) ``|p_k - p'_k|`` of each correspondence, m.
        sensor: ``simlidar.sensor.LidarModel``.
        formula, noise_floor_m: as ``gcr_threshold_m``.
        thresholds_m: (M,) precomputed ``gcr_threshold_m`` for these points (then
            points, normals, rings and sensor are not used).

    Returns:
        (M,) bool keep mask. Grazing incidence (infinite threshold) keeps; a point
        whose threshold cannot be evaluated (nan) is kept too: the rejector
        abstains rather than drop a match it knows nothing against.
    """
    if thresholds_m is None:
        thresholds_m = gcr_threshold_m(
            source_points_in_sensor_frame, source_normals, source_rings, sensor, formula, noise_floor_m
        )
    dist = np.asarray(match_distances, dtype=np.float64)
    thr = np.asarray(thresholds_m, dtype=np.float64)
    if dist.shape != thr.shape:
        raise ValueError(f"match_distances {dist.shape} and thresholds {thr.shape} differ")
    with np.errstate(invalid="ignore"):
        return (dist < thr) | np.isnan(thr)
