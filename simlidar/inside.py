"""Is the sensor inside a solid? Probe rays in all directions and count back-face hits.

A mesh's winding says which side of each triangle is "outside". From a sensor
in open space the first surface along almost every direction is seen from its
outside (front); from inside a solid (a building, under the ground) most are
seen from their back. That is conclusive only when the winding can be trusted:
the procedural scenes are wound outward everywhere, but a user's mesh may be a
room, garage or tunnel modelled as a closed box with outward normals (from the
inside every wall is a back face), or a scan with flipped or inconsistent
normals. The simulator ranges back-face hits like any other (distance along
the ray, normal turned towards the sensor), so for such meshes an enclosed
probe is evidence to report, not a reason to stop.

``probe`` measures one pose; ``check_poses`` applies the policy to a path:
refuse (``SensorInsideGeometry``) when strict, else log one warning with the
evidence and carry on.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

# Probe rays per pose, on a golden-angle spiral (near-uniform over the sphere).
N_PROBE_RAYS = 200
# An origin is "enclosed" when more than this fraction of the probes that hit see a back face.
ENCLOSED_FRACTION = 0.5


class SensorInsideGeometry(ValueError):
    """The sensor origin lies inside a solid of the world."""


@dataclass(frozen=True)
class InsideProbe:
    """What the probe rays saw from one sensor position.

    position: (3,) float64 sensor origin, world frame, m.
    n_rays: probe rays cast; n_hit: of them, rays that hit a surface;
    n_back: of those, rays whose first hit is a triangle's back face.
    """

    position: np.ndarray
    n_rays: int
    n_hit: int
    n_back: int

    @property
    def enclosed(self) -> bool:
        """Most surfaces around are seen from behind: inside a solid, or a mesh wound inward-out."""
        return self.n_hit > 0 and self.n_back > ENCLOSED_FRACTION * self.n_hit

    def where(self) -> str:
        p = self.position
        return f"sensor at ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) m"

    def evidence(self) -> str:
        return f"{self.n_back} of {self.n_hit} probe rays hit the back face of a surface"


def probe_directions(n: int = N_PROBE_RAYS) -> np.ndarray:
    """(n, 3) unit vectors spread near-uniformly over the sphere (golden-angle spiral)."""
    golden = np.pi * (3.0 - np.sqrt(5.0))
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(golden * k), r * np.sin(golden * k), z], axis=1)


def probe(raycaster, pose: np.ndarray) -> InsideProbe:
    """Cast the probe rays from ``pose`` (4, 4) ``T_world_lidar`` with ``raycaster`` (``simlidar.raycast``)."""
    dirs = probe_directions()
    hits = raycaster.cast(pose[:3, 3], dirs, 1e6)
    return InsideProbe(np.array(pose[:3, 3], dtype=float), len(dirs), int(hits.hit.sum()),
                       int(hits.back_face[hits.hit].sum()))


def check_poses(raycaster, poses: np.ndarray, strict: bool, source: str = "") -> dict:
    """Probe every pose of a path; refuse or warn about the enclosed ones.

    poses: (N, 4, 4) ``T_world_lidar`` of the frames (frame k = poses[k]).
    strict: raise ``SensorInsideGeometry`` at the first enclosed pose (the
        world's winding is trusted); else log one warning naming how many
        frames are enclosed and the first one's evidence, and go on.
    source: the world's name for the messages (a mesh path).
    Returns the manifest's record: ``mode`` ("strict" or "warn"),
    ``enclosed_frames`` (count), ``first_enclosed_frame`` (index or None) and,
    for that frame, ``probe_rays_hit`` / ``probe_rays_back_face``.
    """
    enclosed: list[tuple[int, InsideProbe]] = []
    for k, pose in enumerate(poses):
        found = probe(raycaster, pose)
        if not found.enclosed:
            continue
        if strict:
            raise SensorInsideGeometry(f"frame {k}: {found.where()} is inside geometry: {found.evidence()}")
        enclosed.append((k, found))
    record: dict = {"mode": "strict" if strict else "warn", "enclosed_frames": len(enclosed),
                    "first_enclosed_frame": None}
    if enclosed:
        k, first = enclosed[0]
        record.update(first_enclosed_frame=k, probe_rays_hit=first.n_hit, probe_rays_back_face=first.n_back)
        log.warning(
            "%sthe sensor sees mostly back faces at %d of %d frames (frame %d: %s, %s); simulating anyway. "
            "An enclosed space (room, garage, tunnel) modelled with outward normals, or a mesh with "
            "inconsistent normals, looks like this, and back-face returns are ranged like any other; "
            "if the sensor is really inside a solid, fix the poses (--strict-inside-check refuses them).",
            f"{source}: " if source else "", len(enclosed), len(poses), k, first.where(), first.evidence(),
        )
    return record
