"""The first registration of a sequence: standing still or the coarse estimate, whichever the scene says.

The first registration has no motion to extrapolate. It starts from standing
still and, since the sensor may already move by metres a frame, first runs a
coarse pass (a wide bound, no trimming) whose estimate the ICP then refines.
Where the scene pins every direction that pass walks to the motion. Where it
pins one only through a few objects (rocks on flat open ground), the pass's
wide, untrimmed matches can walk a standing start off by most of a metre
along that direction; the ICP, with little to pull it back, stays there, and
the motion prior carries that speed on through the sequence.

With ``match.cold_start_from_rest`` (an option, off: over the suite's seeds it
fixed such a start and lost as many highway starts, README) the ICP also
refines standing still, and where the two results disagree,
the points that see the disagreement decide (``choose_start``): those whose
target plane at either estimate faces the direction d between them
(``|n . d| > FACING_COS``). Their mean truncated point-to-plane cost is
compared (each point's squared distance to the plane of its nearest target
point, at most ``tau^2``, ``tau^2`` without one; ``tau`` three times the smaller
RMS residual of the two). All points would not do: at standing still a
sensor's scan lines fall where the target's fell, so on curved ground each
point sits on its own earlier line and the residuals of the whole scan favour
standing still even at 17 m/s; points on surfaces parallel to d (ground,
rails) cannot tell the two apart anyway. Without such points, or on a tie,
the coarse estimate is kept, as it always was.

Only for scans without per-point times. With them, both scans of the first
registration are de-skewed as if standing still, and only the de-skew
refinements that follow (``odometry.pipeline``) re-de-skew them with the
estimate; before that, scans distorted by a metre of motion favour standing
still (a highway start at 17 m/s: coarse 0.65 m, refined to 1.73 m by the
re-de-skew; the facing points preferred standing still), so there the
coarse estimate is kept.
"""

from __future__ import annotations

import numpy as np

from .icp import RegistrationResult, Target, match

# The truncation of the cost, in RMS residuals of the better-fitting registration.
TRUNCATION_RMS = 3.0
# A point sees the disagreement when its target plane's normal is within 60 deg of it.
FACING_COS = 0.5


def plane_costs(source_points: np.ndarray, T: np.ndarray, target: Target, direction: np.ndarray,
                bound_m: float, tau_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per point of (M, 3) ``source_points`` moved by ``T`` (4, 4): its truncated point-to-plane cost, m^2,
    and |n . direction| of its target plane (0 without one), both (M,).

    A point costs ``min(r^2, tau^2)``, r its distance to the plane of its nearest target
    point within ``bound_m``; ``tau^2`` with no neighbour there or no plane (a nan normal).
    """
    moved = source_points @ T[:3, :3].T + T[:3, 3]
    m = match(moved, target, bound_m)  # (the ICP's own nearest-neighbour search and its cache)
    cost = np.full(len(moved), tau_m * tau_m)
    facing = np.zeros(len(moved))
    if len(m):
        normals = target.normals_at(m.target_index)
        r = np.einsum("ij,ij->i", normals,
                      moved.take(m.source_index, axis=0) - target.points.take(m.target_index, axis=0))
        cost[m.source_index] = np.where(np.isfinite(r), np.minimum(r * r, tau_m * tau_m), tau_m * tau_m)
        facing[m.source_index] = np.nan_to_num(np.abs(normals @ direction))
    return cost, facing


def choose_start(source_points: np.ndarray, target: Target, at_rest: RegistrationResult,
                 coarse: RegistrationResult, bound_m: float) -> RegistrationResult:
    """The refined standing start or the refined coarse estimate of (M, 3) ``source_points`` on ``target``.

    ``at_rest`` wins only if the points facing the direction between the two fit it better
    (module doc); a singular result loses. ``bound_m``: the cost's nearest-neighbour bound, m.
    """
    if at_rest.singular or coarse.singular:
        return coarse if at_rest.singular else at_rest
    d = coarse.T_target_source[:3, 3] - at_rest.T_target_source[:3, 3]
    apart = float(np.linalg.norm(d))
    if not apart > 0:
        return coarse
    d = d / apart
    tau = TRUNCATION_RMS * max(min(at_rest.rms_m, coarse.rms_m), 1e-3)
    cost_rest, facing_rest = plane_costs(source_points, at_rest.T_target_source, target, d, bound_m, tau)
    cost_coarse, facing_coarse = plane_costs(source_points, coarse.T_target_source, target, d, bound_m, tau)
    seeing = (facing_rest > FACING_COS) | (facing_coarse > FACING_COS)
    if not seeing.any():
        return coarse
    return at_rest if cost_rest[seeing].mean() < cost_coarse[seeing].mean() else coarse
