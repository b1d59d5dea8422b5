"""One rotation of a spinning lidar: rays per (ring, column), firing times, motion, noise.

Frames and motion distortion. The scan's frame is the sensor frame at the
sweep's *reference time*, its start (time 0 of ``time_s``, the time written to
``times.txt``, the pose written to ``poses.txt``). Each ray leaves from the
sensor pose at its own firing time (on by default), and the point is reported
the way a real sensor reports it: measured range along the beam in the sensor
frame *at the firing instant*, with no compensation. When the sensor moves, the
scan is therefore distorted with respect to its reference frame by the motion
since the sweep start; that is what de-skewing corrects. The ground truth is
undistorted: ``true_xyz`` and ``normal`` give where each return really is, and
its surface normal, in the reference frame. With motion distortion off, all
rays leave from the reference pose and the two frames coincide.

Noise model per return: measured range = true range + ring bias (fixed per
laser, optional) + N(0, sigma^2); the point is placed along the beam at the
measured range. sigma is ``range_noise_std_m``, or with
``incidence_noise_max_factor`` F > 1, ``range_noise_std_m * min(1 / |cos a|, F)``
(``a`` the angle of incidence: the footprint stretches along a tilted surface).
Returns whose measured range falls outside [min_range_m, max_range_m] are
dropped, as are random dropouts (optional). Misses produce no return.

Beam divergence (``beam_divergence_deg`` > 0): each beam is a cone of
``beam_subrays`` sub-rays; where the beam's axis hits something, the range
before noise is an echo of the sub-rays' hits (``_echo_range``): at a depth
edge, sub-rays on the near and the far surface mix into a range between them
when they are within ``echo_separation_m``, else ``return_mode`` picks the
first, last or strongest echo. The truth (true range, point, normal, object)
stays the axis ray's hit, so the mixed-pixel error is measured minus true
range. A beam whose axis misses returns nothing (no blooming past silhouettes).

Intensity model (documented, not calibrated): ``reflectance(object) * |cos a|^k *
min(1, (r_ref / r)^2)``, with ``a`` the angle of incidence, ``k`` the sensor's
``intensity_incidence_exponent`` (1: Lambertian), ``r_ref`` its
``intensity_range_ref_m`` and the reflectance per object (``World.reflectance``,
by default from its label); values in [0, 1].

Receiver and weather (``simlidar.weather``, off by default): with the sensor's
``receiver`` on, each beam's echoes have a received power and only those above
the receiver's threshold are detected; the weather (fog, rain, snow) attenuates
them and adds echoes of its own, and the return mode picks the one the beam
reports. Each beam's weather draws come from a generator of the block's own
(seeded with (seed, 2, frame, block)), apart from the range noise's. A surface's
intensity is then the model's above times the overlap and the air's two-way
transmission; a weather echo's is its power times ``min(r, r_ref)^2``. The truth
of a weather return (``Scan.weather`` > 0) keeps the surface its beam reached,
if any (true range, point, normal, object); without one, NaN and object -1.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass

import numpy as np

from . import se3
from .actors import ActorSet, merge_hits
from .formats.tracks import TRACK_DTYPE
from .formats.truth import MOVING_SPEED_M_S, SIDECAR_DTYPE, sidecar_dtype
from .inside import InsideProbe, SensorInsideGeometry, probe
from .kernels.sweep import block_rays, fill_actor_rows, fill_rows, measure_block
from .raycast import CompactHits, Raycaster
from .sensor import LidarModel
from .trajectory import Trajectory
from .weather import SURFACE, WeatherModel
from .world import World

__all__ = ["SIDECAR_DTYPE", "Scan", "SensorInsideGeometry", "SweepSimulator"]

# Column blocks a sweep is cut into (fixed, so results do not depend on the core count).
N_BLOCKS = 8

@dataclass
class Scan:
    """The returns of one sweep, ordered by firing (column, then ring).

    xyz: (N, 3) float64 measured points as the sensor reports them (sensor frame at each
        point's firing time; distorted when the sensor moves), metres.
    intensity: (N,) float32 in [0, 1].
    ring: (N,) int, 0 = lowest beam.  azimuth_index: (N,) int column index.
    time_s: (N,) float64 firing time since the sweep start, seconds.
    range_m: (N,) measured range; true_range_m: (N,) noise-free range, metres.
    true_xyz: (N, 3) noise-free hit point in the reference frame (undistorted), metres.
    normal: (N, 3) unit surface normal of the hit triangle in the reference frame,
        facing the sensor.
    object_id: (N,) int32 id of the hit object.
    motion: (C + 1, 4, 4) the sensor's pose at the start of each firing column (and at the sweep's
        end) in the reference frame, ``T_ref^-1 T_fire``; None without motion distortion (identity).
    weather: (N,) uint8 what each return is (``simlidar.weather.KINDS``: 0 a surface, 1 fog, 2 rain,
        3 snow), or None when the sensor has no weather. A weather return's true range, point, normal
        and object are those of the surface its beam reached (NaN and -1 when it reached none).
    object_class, moving, velocity, tracks: with moving objects in the world (``simlidar.actors``),
        else None: (N,) uint8 the class of the object hit (``simlidar.formats.truth.ACTOR_CLASSES``: 0
        the static world); (N,) bool it moved at the return's instant; (N, 3) the velocity of the
        point hit in the world, along the reference frame's axes, m/s (0 on the static world);
        ``tracks``: (n,) ``simlidar.formats.tracks.TRACK_DTYPE``, every moving object within range
        at the sweep's start, its box in the reference frame.
    """

    xyz: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray
    azimuth_index: np.ndarray
    time_s: np.ndarray
    range_m: np.ndarray
    true_range_m: np.ndarray
    true_xyz: np.ndarray
    normal: np.ndarray
    object_id: np.ndarray
    motion: np.ndarray | None = None
    weather: np.ndarray | None = None
    object_class: np.ndarray | None = None
    moving: np.ndarray | None = None
    velocity: np.ndarray | None = None
    tracks: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.xyz)

    @property
    def surface_returns(self) -> slice | np.ndarray:
        """The returns that measured a surface (an index: all of them without weather)."""
        return slice(None) if self.weather is None else np.flatnonzero(self.weather == SURFACE)

    def sidecar(self) -> np.ndarray:
        """The per-point fields KITTI's .bin lacks, as a structured array (SIDECAR_DTYPE, format version 1; with
        the ``weather`` field when the scan has one, and the moving objects' fields when the world has them:
        ``sidecar_dtype(weather, actors)``)."""
        rec = np.zeros(len(self), dtype=sidecar_dtype(self.weather is not None, self.object_class is not None))
        rec["ring"] = self.ring
        rec["azimuth_index"] = self.azimuth_index
        rec["time_s"] = self.time_s
        rec["range_m"] = self.range_m
        rec["true_range_m"] = self.true_range_m
        rec["true_xyz"] = self.true_xyz
        rec["normal"] = self.normal
        rec["object_id"] = self.object_id
        if self.weather is not None:
            rec["weather"] = self.weather
        if self.object_class is not None:
            rec["object_class"], rec["moving"], rec["velocity"] = self.object_class, self.moving, self.velocity
        return rec


@dataclass
class CastBlock:
    """The returns of one block of rays (``SweepSimulator._cast_block``), before they are written into the scan.

    first_ray: index of the block's first ray in the sweep's firing order.
    hits: the kept returns' ``CompactHits`` (``ray``: (M,) index within the block,
        ``distance``: (M,) true range, m; face, normal, incidence).
    ring: (M,) ring of each return. measured: (M,) range with bias and noise, m.
    dir_local: (B, 3) unit beam directions of the block's rays in the sensor frame.
    origin_bvh, direction_bvh: (B, 3) ray origins (m) and unit directions in the BVH's frame
        (the world shifted by ``-Raycaster.offset``), at each ray's firing pose.
    kind, power, gain: with the receiver on, (M,) what each return is (``simlidar.weather.KINDS``), its
        received power, and a surface's overlap x two-way transmission; ``hits`` then has a row per
        return, face -1 and distance NaN where the beam reached no surface.
    """

    first_ray: int
    hits: CompactHits
    ring: np.ndarray
    measured: np.ndarray
    dir_local: np.ndarray
    origin_bvh: np.ndarray
    direction_bvh: np.ndarray
    kind: np.ndarray | None = None
    power: np.ndarray | None = None
    gain: np.ndarray | None = None


# A scan's per-return arrays: {field: (dtype, columns)}; with moving objects, their truth's too.
SCAN_FIELDS = {"xyz": (np.float64, 3), "intensity": (np.float32, 1), "ring": (np.int64, 1),
               "azimuth_index": (np.int64, 1), "time_s": (np.float64, 1), "range_m": (np.float64, 1),
               "true_range_m": (np.float64, 1), "true_xyz": (np.float64, 3), "normal": (np.float64, 3),
               "object_id": (np.int32, 1)}
ACTOR_FIELDS = {"object_class": (np.uint8, 1), "moving": (np.bool_, 1), "velocity": (np.float64, 3)}


class ScanMemory:
    """The per-return arrays of a simulator's scans, reused once a scan is let go.

    Writing fresh memory costs a page fault per 4 kB page, and a sweep's arrays are some 17 MB
    (on the development machine, a virtual machine that hands free memory back to its host,
    the faults were a fifth of a sweep's CPU time whenever the allocator did not happen to reuse
    the last scan's memory). Each scan's arrays are views of a set allocated for a whole sweep's
    rays; a set none of whose arrays is referenced any more (the writer has written its frame,
    the caller dropped it) is handed to the next sweep. A set still referenced is never reused.
    """

    def __init__(self, fields: dict, capacity: int, keep: int = 4):
        self.fields, self.capacity, self.keep = fields, int(capacity), keep
        self._sets: list[dict[str, np.ndarray]] = []

    def arrays(self, n: int) -> dict[str, np.ndarray]:
        """Uninitialised arrays of ``n`` rows, one per field."""
        for arrays in self._sets:
            # each referenced only by this dict and getrefcount's argument: no scan holds a view of them
            if len(arrays["xyz"]) >= n and all(sys.getrefcount(arrays[k]) <= 2 for k in arrays):
                return {k: a[:n] for k, a in arrays.items()}
        size = max(n, self.capacity)
        arrays = {k: np.empty((size, cols) if cols > 1 else size, dt) for k, (dt, cols) in self.fields.items()}
        if len(self._sets) < self.keep:
            self._sets.append(arrays)
        return {k: a[:n] for k, a in arrays.items()}


# An empty draw: the kernels' placeholder where no draws are made (no dropouts, exponent 1).
_NO_DRAWS = np.empty(0)
_NO_INDEX = np.empty(0, np.int64)
_NO_ROWS = np.empty((0, 3))


def _bare(hits: CompactHits) -> np.ndarray:
    """(m,) the rows of a block whose beam reached no surface (a weather echo): no face, no moving object."""
    bare = hits.face < 0
    return bare if hits.actor is None else bare & (hits.actor < 0)


class SweepSimulator:
    """Simulates sweeps of ``sensor`` in ``world``.

    Args:
        world: the mesh with object ids and labels.
        sensor: the lidar model.
        seed: seeds the per-laser bias (drawn once here) and every frame's noise.
        motion_distortion: each firing from its own pose (True) or all from the
            reference pose (False).
        threads: Embree worker threads (default: all cores).
    """

    def __init__(
        self,
        world: World,
        sensor: LidarModel,
        seed: int = 0,
        motion_distortion: bool = True,
        threads: int | None = None,
        raycaster: Raycaster | None = None,
    ):
        self.world = world
        self.sensor = sensor
        self.seed = int(seed)
        self.motion_distortion = motion_distortion
        self.raycaster = raycaster or Raycaster(world.vertices, world.faces, threads=threads)
        self._reflectance = world.object_reflectance
        self.actors = ActorSet(world.actors, len(world.object_labels), sensor.max_range_m) if world.actors else None
        if self.actors is not None:  # the actors' object ids follow the static world's
            self._reflectance = np.concatenate([self._reflectance, self.actors.reflectance])
        cols, rings = sensor.columns_per_sweep, sensor.rings
        # Ray tables in firing order: column-major, rings ascending within a column.
        self.ray_column = np.repeat(np.arange(cols), rings)
        self.ray_ring = np.tile(np.arange(rings), cols)
        self.ray_time_s = sensor.firing_time_s(self.ray_ring, self.ray_column)
        # Rays sharing a firing time share a pose: interpolate once per distinct time.
        self._times_unique, self._ray_time_idx = np.unique(self.ray_time_s, return_inverse=True)
        self._dir_local = self._directions(
            sensor.elevation_rad[self.ray_ring],
            sensor.column_azimuth_rad(self.ray_column) + sensor.ring_azimuth_offset_rad[self.ray_ring],
        )
        bias_rng = np.random.default_rng([self.seed, 0xB1A5])
        self.ring_bias_m = bias_rng.normal(0.0, 1.0, rings) * sensor.ring_bias_std_m
        self._weather = WeatherModel(sensor) if sensor.receiver.enabled else None
        fields = dict(SCAN_FIELDS)
        if sensor.weather.on:
            fields["weather"] = (np.uint8, 1)
        if self.actors is not None:
            fields.update(ACTOR_FIELDS)
        self._memory = ScanMemory(fields, sensor.rays_per_sweep)

    @staticmethod
    def _directions(elevation: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
        ce = np.cos(elevation)
        return np.stack([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)], axis=1)

    def check_clear(self, pose: np.ndarray, where: str = "", strict: bool | None = None) -> InsideProbe:
        """Probe whether the sensor at ``pose`` (4, 4) is inside a solid (``simlidar.inside``).

        If most probe rays hit back faces, raise ``SensorInsideGeometry`` when
        ``strict`` (default: when the world's normals are reliable, as a
        procedural scene's are); otherwise return the evidence for the caller to
        report. ``where`` prefixes the message (e.g. "frame 3: ").
        """
        found = probe(self.raycaster, pose)
        if strict is None:
            strict = self.world.normals_reliable
        if strict and found.enclosed:
            raise SensorInsideGeometry(f"{where}{found.where()} is inside geometry: {found.evidence()}")
        return found

    def sweep(self, trajectory: Trajectory, t0: float, frame_index: int = 0) -> Scan:
        """Simulate the sweep that starts at time ``t0`` (s) along ``trajectory``.

        The sweep is cut into a fixed number of column blocks processed on the
        raycaster's threads; block ``k`` of frame ``frame_index`` draws its noise
        from its own generator seeded with (seed, frame_index, k), so results are
        reproducible in any order and on any number of cores.
        """
        s = self.sensor
        motion = None
        if self.motion_distortion:
            if s.laser_interval_s == 0:  # the firing times are the column starts: one more pose, the sweep's end
                T_fire = trajectory.pose_at(np.append(t0 + self._times_unique, t0 + s.sweep_period_s))
                T_cols, T_fire = T_fire, T_fire[:-1]
                T_ref = T_fire[0]  # column 0 fires at the sweep's start
            else:
                T_ref = trajectory.pose_at(np.array([t0]))[0]
                T_fire = trajectory.pose_at(t0 + self._times_unique)
                T_cols = trajectory.pose_at(t0 + np.arange(s.columns_per_sweep + 1) * s.column_period_s)
            motion = se3.inverse(T_ref) @ T_cols
        else:
            T_ref = trajectory.pose_at(np.array([t0]))[0]
            T_fire = None
        acts = None
        if self.actors is not None:
            acts = self.actors.for_sweep(self, t0, T_ref, T_cols if self.motion_distortion else None)
        cols = np.linspace(0, s.columns_per_sweep, N_BLOCKS + 1).astype(int)
        blocks = [(k, cols[k] * s.rings, cols[k + 1] * s.rings) for k in range(N_BLOCKS)]
        if acts is not None:
            acts.split(cols * s.rings)
        # Each block is cast, then written into the scan's rows as soon as the blocks before it have counted
        # theirs: its rays and hits are still in the cache (a second pass over the whole sweep found them gone).
        # A ray gives at most one return, so block k's rows start at or before its first ray, a: they fit.
        room = self._memory.arrays(self._memory.capacity)
        rows = Scan(**room, motion=motion)
        offsets = np.zeros(N_BLOCKS + 1, np.int64)
        counted = [threading.Event() for _ in range(N_BLOCKS)]

        def cast_and_fill(blk) -> None:
            k = blk[0]
            c = None
            try:
                c = self._cast_block(*blk, T_ref, T_fire, frame_index, t0, acts)
            finally:  # (the next block waits for this one's count, even when it failed)
                if k > 0:
                    counted[k - 1].wait()
                offsets[k + 1] = offsets[k] + (len(c.measured) if c is not None else 0)
                counted[k].set()
            self._fill_block(c, rows, int(offsets[k]), T_ref)

        self.raycaster.map(cast_and_fill, blocks)
        n = int(offsets[-1])
        out = Scan(**{k: a[:n] for k, a in room.items()}, motion=motion)
        if self.actors is not None:
            out.tracks = acts.tracks(out.object_id) if acts is not None else np.zeros(0, TRACK_DTYPE)
        return out

    def _cast_block(self, k, a, b, T_ref, T_fire, frame_index, t0: float = 0.0, acts=None) -> CastBlock:
        """Cast rays a:b of the sweep (block ``k``) and draw their noise; returns the block's returns.

        acts: the moving objects near the sensor in this sweep (``simlidar.actors.SweepActors``), or None."""
        s, rc = self.sensor, self.raycaster
        rng = np.random.default_rng([self.seed, 1, int(frame_index), k])
        dir_local = self._dir_local[a:b]
        if s.angular_jitter_deg > 0:
            jit = np.radians(s.angular_jitter_deg)
            ring, col = self.ray_ring[a:b], self.ray_column[a:b]
            dir_local = self._directions(
                s.elevation_rad[ring] + rng.normal(0, jit, b - a),
                s.column_azimuth_rad(col) + s.ring_azimuth_offset_rad[ring] + rng.normal(0, jit, b - a),
            )
        # Rays are cast in the BVH's frame, the world shifted by -rc.offset (the mesh centred for Embree's float32).
        if T_fire is None:
            R, t, pose_of_ray = T_ref[None, :3, :3], T_ref[None, :3, 3], np.zeros(b - a, np.int64)
        elif s.laser_interval_s == 0:  # one pose per column
            c0, c1 = a // s.rings, b // s.rings
            R, t, pose_of_ray = T_fire[c0:c1, :3, :3], T_fire[c0:c1, :3, 3], _NO_INDEX
        else:
            R, t, pose_of_ray = T_fire[:, :3, :3], T_fire[:, :3, 3], self._ray_time_idx[a:b]
        o_bvh, d_bvh, o32, d32 = block_rays(dir_local, R, t, pose_of_ray, s.rings, rc.offset)
        hits = rc.cast_compact(o_bvh, d_bvh, s.max_range_m + 1.0, o32, d32)
        if acts is not None:  # the nearest of the static hit and the moving objects' at each ray's instant
            rows, which = acts.block_rows(a)
            found = acts.cast(rows, which, o_bvh, rc.offset, d_bvh, t0 + self.ray_time_s[a + rows], s.max_range_m + 1.0,
                              nearer=hits)
            hits = merge_hits(hits, found)
        if self._weather is not None:
            return self._cast_weather(k, a, b, hits, rng, frame_index, dir_local, o_bvh, d_bvh, t0, acts)

        m = len(hits.ray)
        z = rng.standard_normal(m)  # the noise's draws, then the dropouts': the order the seeds were drawn in
        u = rng.random(m) if s.dropout_probability > 0 else _NO_DRAWS
        echo = hits.distance if s.beam_divergence_deg == 0 else self._echo_range(hits, o_bvh, d_bvh, a, t0, acts)
        # sigma0 / cos(incidence) clipped, measured = echo + bias + noise, the range window, the dropouts
        ring, measured, keep = measure_block(hits.ray, echo, hits.cos_incidence, self.ray_ring[a:b], self.ring_bias_m,
                                             z, s.range_noise_std_m, s.incidence_noise_max_factor, s.min_range_m,
                                             s.max_range_m, u, s.dropout_probability)
        if len(keep) < m:
            hits, ring, measured = hits.select(keep), ring[keep], measured[keep]
        return CastBlock(a, hits, ring, measured, dir_local, o_bvh, d_bvh)

    def _hit_objects(self, hits: CompactHits) -> np.ndarray:
        """(m,) the object id of each hit (an actor's after the static world's)."""
        obj = np.take(self.world.face_object_id, hits.face)
        if hits.actor is not None:
            on = hits.actor >= 0
            obj[on] = self.actors.first_object_id + hits.actor[on]
        return obj

    def _cast_weather(self, k, a, b, hits: CompactHits, rng, frame_index, dir_local, o_bvh, d_bvh, t0=0.0,
                      acts=None) -> CastBlock:
        """``_cast_block``'s end with the receiver on: each beam's echo through ``WeatherModel.select``, then
        the range noise (the surface's incidence-grown sigma on a surface's echo, sigma itself on a weather
        echo), the range window and the dropouts."""
        s = self.sensor
        echo = hits.distance if s.beam_divergence_deg == 0 else self._echo_range(hits, o_bvh, d_bvh, a, t0, acts)
        cosk = np.abs(hits.cos_incidence)
        if s.intensity_incidence_exponent != 1:
            cosk = cosk**s.intensity_incidence_exponent
        refl = np.take(self._reflectance, self._hit_objects(hits))
        power = refl * cosk / np.maximum(hits.distance, 1e-6) ** 2
        weather_rng = np.random.default_rng([self.seed, 2, int(frame_index), k])
        got = self._weather.select(weather_rng, b - a, hits.ray, hits.distance, echo, power)
        surface = got.hit >= 0
        face, distance, cos_incidence = np.full(len(got.ray), -1), np.full(len(got.ray), np.nan), \
            np.full(len(got.ray), np.nan)
        hit = got.hit[surface]
        face[surface], distance[surface], cos_incidence[surface] = hits.face[hit], hits.distance[hit], \
            hits.cos_incidence[hit]
        rows = CompactHits(got.ray, face, distance, cos_incidence, hits.face_normals)
        if hits.actor is not None:  # a beam's surface may be a moving object
            rows.actor = np.full(len(got.ray), -1, np.int64)
            rows.actor[surface] = hits.actor[hit]
            slot = hits.actor_slots()[hit]
            slot = slot[slot >= 0]  # (the rows keep the hits' order)
            rows.actor_normal, rows.actor_velocity = hits.actor_normal[slot], hits.actor_velocity[slot]
        ring = self.ray_ring[a + got.ray]
        sigma = np.full(len(ring), s.range_noise_std_m)
        on_surface = got.kind == SURFACE
        if s.incidence_noise_max_factor > 1:
            cos = np.abs(rows.cos_incidence[on_surface])
            sigma[on_surface] *= np.minimum(1.0 / np.maximum(cos, 1e-12), s.incidence_noise_max_factor)
        measured = got.range_m + self.ring_bias_m[ring] + rng.standard_normal(len(ring)) * sigma
        keep = (measured >= s.min_range_m) & (measured <= s.max_range_m)
        if s.dropout_probability > 0:
            keep &= rng.random(len(ring)) >= s.dropout_probability
        return CastBlock(a, rows.select(keep), ring[keep], measured[keep], dir_local, o_bvh, d_bvh,
                         got.kind[keep], got.power[keep], got.gain[keep])

    def _echo_range(self, hits: CompactHits, o_bvh: np.ndarray, d_bvh: np.ndarray, a: int = 0, t0: float = 0.0,
                    acts=None) -> np.ndarray:
        """(m,) range a divergent beam reports for each axis hit: an echo of its sub-rays (see the module doc).

        The beam's ``beam_subrays`` sub-rays (``LidarModel.beam_pattern_rad``, oriented across and up the
        beam with the world's z as up) leave from the beam's origin. Their hits, sorted by range, form
        echoes wherever consecutive ranges are within ``echo_separation_m``; an echo's power is the sum of
        its sub-rays' ``reflectance x |cos incidence|^k / range^2`` and its range their power-weighted mean.
        ``return_mode`` picks the nearest (first), the farthest (last) or the most powerful (strongest)
        echo. A beam none of whose sub-rays hits keeps its axis range.
        """
        s, rc = self.sensor, self.raycaster
        m, S = len(hits.ray), s.beam_subrays
        if m == 0:
            return hits.distance
        axis = np.take(d_bvh, hits.ray, axis=0)
        origin = np.take(o_bvh, hits.ray, axis=0)
        across = np.cross(axis, [0.0, 0.0, 1.0])
        vertical = np.linalg.norm(across, axis=1) < 1e-6
        if vertical.any():
            across[vertical] = np.cross(axis[vertical], [1.0, 0.0, 0.0])
        across /= np.linalg.norm(across, axis=1, keepdims=True)
        up = np.cross(across, axis)
        off = s.beam_pattern_rad()
        r = np.hypot(off[:, 0], off[:, 1])
        c, k_across, k_up = np.cos(r), np.sin(r) * off[:, 0] / np.maximum(r, 1e-300), np.sin(r) * off[:, 1] / \
            np.maximum(r, 1e-300)
        dirs = (axis[:, None, :] * c[None, :, None] + across[:, None, :] * k_across[None, :, None]
                + up[:, None, :] * k_up[None, :, None]).reshape(-1, 3)
        sub_origin = np.repeat(origin, S, axis=0)
        sub = rc.cast_compact(sub_origin, dirs, s.max_range_m + 1.0)
        if acts is not None:  # the sub-rays meet the moving objects too, at their beam's instant
            parent = np.repeat(a + hits.ray, S)
            rows, which = acts.rows_of_rays(parent)
            found = acts.cast(rows, which, sub_origin, rc.offset, dirs, t0 + self.ray_time_s[parent[rows]],
                              s.max_range_m + 1.0)
            sub = merge_hits(sub, found)
        dist = np.full(m * S, np.inf)
        power = np.zeros(m * S)
        dist[sub.ray] = sub.distance
        cosk = np.abs(sub.cos_incidence) ** s.intensity_incidence_exponent
        power[sub.ray] = self._reflectance[self._hit_objects(sub)] * cosk / np.maximum(sub.distance, 1e-6) ** 2
        dist, power = dist.reshape(m, S), power.reshape(m, S)
        order = np.argsort(dist, axis=1, kind="stable")
        dist = np.take_along_axis(dist, order, axis=1)
        power = np.take_along_axis(power, order, axis=1)
        with np.errstate(invalid="ignore"):
            gap = np.diff(dist, axis=1) > s.echo_separation_m  # inf - finite starts the misses' own echo
        label = np.concatenate([np.zeros((m, 1), np.int64), np.cumsum(gap, axis=1)], axis=1)
        flat = (np.arange(m)[:, None] * S + label).ravel()
        e_power = np.bincount(flat, power.ravel(), minlength=m * S).reshape(m, S)
        e_moment = np.bincount(flat, (power * np.where(np.isfinite(dist), dist, 0.0)).ravel(),
                               minlength=m * S).reshape(m, S)
        has = e_power > 0
        if s.return_mode == "strongest":
            pick = np.argmax(e_power, axis=1)
        elif s.return_mode == "first":
            pick = np.argmax(has, axis=1)
        else:  # last
            pick = S - 1 - np.argmax(has[:, ::-1], axis=1)
        rows = np.arange(m)
        with np.errstate(invalid="ignore", divide="ignore"):
            rng_e = e_moment[rows, pick] / e_power[rows, pick]
        return np.where(has[rows, pick], rng_e, hits.distance)

    def _fill_block(self, c: CastBlock, out: Scan, off: int, T_ref: np.ndarray) -> None:
        """Write one block's returns into rows off:off+m of the preallocated scan (``kernels.sweep.fill_rows``:
        the measured and true points, normals, intensities, rings, azimuths, times, ranges, objects)."""
        s, rc = self.sensor, self.raycaster
        hits = c.hits
        sl = slice(off, off + len(hits.ray))
        cosk_pow = _NO_DRAWS
        if s.intensity_incidence_exponent != 1:
            cosk_pow = np.abs(hits.cos_incidence) ** s.intensity_incidence_exponent
        R_ref = np.ascontiguousarray(T_ref[:3, :3])
        moving = hits.actor is not None
        fill_rows(off, c.first_ray, hits.ray, hits.face, hits.distance, hits.cos_incidence, c.measured, c.ring,
                  c.dir_local, c.origin_bvh, c.direction_bvh, np.ascontiguousarray(T_ref[:3, 3] - rc.offset),
                  R_ref, hits.face_normals, self.world.face_object_id, self._reflectance, cosk_pow,
                  s.intensity_range_ref_m, self.ray_column, self.ray_time_s,
                  hits.actor if moving else _NO_INDEX, hits.actor_normal if moving else _NO_ROWS,
                  self.actors.first_object_id if self.actors is not None else 0,
                  out.xyz, out.intensity, out.ring, out.azimuth_index, out.time_s, out.range_m, out.true_range_m,
                  out.true_xyz, out.normal, out.object_id)
        if self.actors is not None:  # the moving objects' truth: class, motion, velocity in the reference frame
            velocity = hits.actor_velocity @ R_ref if moving else _NO_ROWS
            fill_actor_rows(off, len(hits.ray), hits.actor if moving else _NO_INDEX, self.actors.class_code, velocity,
                            np.linalg.norm(velocity, axis=1) > MOVING_SPEED_M_S, out.object_class, out.moving,
                            out.velocity)
        if c.kind is not None:
            self._fill_weather(c, out, sl)
            out.object_id[sl][_bare(hits)] = -1

    def _fill_weather(self, c: CastBlock, out: Scan, sl: slice) -> None:
        """The receiver's part of a block's rows: intensities (a surface's times its gain, a weather echo's from
        its power), the weather flags, and the truth of beams that reached no surface (NaN)."""
        s = self.sensor
        weather = c.kind != SURFACE
        intensity = out.intensity[sl]
        intensity *= np.where(weather, 1.0, c.gain)
        if weather.any():
            r = np.maximum(c.measured[weather], 1e-6)
            intensity[weather] = np.minimum(1.0, c.power[weather] * np.minimum(r, s.intensity_range_ref_m) ** 2)
            out.normal[sl][_bare(c.hits)] = np.nan
        if out.weather is not None:
            out.weather[sl] = c.kind
