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

from dataclasses import dataclass

import numpy as np

from . import se3
from .formats.truth import SIDECAR_DTYPE, sidecar_dtype
from .inside import InsideProbe, SensorInsideGeometry, probe
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

    def __len__(self) -> int:
        return len(self.xyz)

    @property
    def surface_returns(self) -> slice | np.ndarray:
        """The returns that measured a surface (an index: all of them without weather)."""
        return slice(None) if self.weather is None else np.flatnonzero(self.weather == SURFACE)

    def sidecar(self) -> np.ndarray:
        """The per-point fields KITTI's .bin lacks, as a structured array (SIDECAR_DTYPE, format version 1; with
        the ``weather`` field when the scan has one, ``sidecar_dtype(weather=True)``)."""
        rec = np.zeros(len(self), dtype=sidecar_dtype(self.weather is not None))
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


def _rows_times(x: np.ndarray, M: np.ndarray, out: np.ndarray) -> None:
    """out = x @ M for (m, 3) rows x and a (3, 3) M, into the C-contiguous (m, 3) ``out``.

    As a batch of 32-row products (numpy's own small-matrix loop: 3 times faster here than einsum,
    and than BLAS, whose threads wait for cores on a busy machine), the remainder by einsum.
    """
    m = len(x) - len(x) % 32
    if m:
        np.matmul(x[:m].reshape(-1, 32, 3), M, out=out[:m].reshape(-1, 32, 3))
    if m < len(x):
        np.einsum("ni,ij->nj", x[m:], M, out=out[m:])


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
        cols = np.linspace(0, s.columns_per_sweep, N_BLOCKS + 1).astype(int)
        blocks = [(k, cols[k] * s.rings, cols[k + 1] * s.rings) for k in range(N_BLOCKS)]
        cast = self.raycaster.map(lambda blk: self._cast_block(*blk, T_ref, T_fire, frame_index), blocks)
        # Fill preallocated outputs block by block (no concatenation pass).
        sizes = [len(c.measured) for c in cast]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        n = int(offsets[-1])
        out = Scan(
            xyz=np.empty((n, 3)), intensity=np.empty(n, np.float32), ring=np.empty(n, np.int64),
            azimuth_index=np.empty(n, np.int64), time_s=np.empty(n), range_m=np.empty(n),
            true_range_m=np.empty(n), true_xyz=np.empty((n, 3)), normal=np.empty((n, 3)),
            object_id=np.empty(n, np.int32), motion=motion,
            weather=np.empty(n, np.uint8) if s.weather.on else None,
        )
        jobs = list(zip(cast, offsets[:-1], strict=True))
        self.raycaster.map(lambda job: self._fill_block(job[0], out, job[1], T_ref), jobs)
        return out

    def _cast_block(self, k, a, b, T_ref, T_fire, frame_index) -> CastBlock:
        """Cast rays a:b of the sweep (block ``k``) and draw their noise; returns the block's returns."""
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
        R_ref, t_ref = T_ref[:3, :3], T_ref[:3, 3] - rc.offset
        if T_fire is None:
            d_bvh = np.einsum("nj,ij->ni", dir_local, R_ref)
            o_bvh = np.broadcast_to(t_ref, (b - a, 3))
        elif s.laser_interval_s == 0:
            # One pose per column: rotate each column's beams with one batched matmul.
            c0, c1 = a // s.rings, b // s.rings
            R = T_fire[c0:c1, :3, :3]
            d_bvh = np.matmul(dir_local.reshape(c1 - c0, s.rings, 3), R.transpose(0, 2, 1)).reshape(-1, 3)
            o_bvh = np.repeat(T_fire[c0:c1, :3, 3] - rc.offset, s.rings, axis=0)
        else:
            ti = self._ray_time_idx[a:b]
            d_bvh = np.einsum("nij,nj->ni", T_fire[ti, :3, :3], dir_local)
            o_bvh = T_fire[ti, :3, 3] - rc.offset
        hits = rc.cast_compact(o_bvh, d_bvh, s.max_range_m + 1.0)
        if self._weather is not None:
            return self._cast_weather(k, a, b, hits, rng, frame_index, dir_local, o_bvh, d_bvh)

        ring = self.ray_ring[a + hits.ray]
        sigma = s.range_noise_std_m
        if s.incidence_noise_max_factor > 1:  # sigma0 / cos(incidence), clipped
            cos = np.abs(hits.cos_incidence)
            sigma = sigma * np.minimum(1.0 / np.maximum(cos, 1e-12), s.incidence_noise_max_factor)
        noise = rng.standard_normal(len(ring)) * sigma
        echo = hits.distance if s.beam_divergence_deg == 0 else self._echo_range(hits, o_bvh, d_bvh)
        measured = echo + self.ring_bias_m[ring] + noise
        keep = (measured >= s.min_range_m) & (measured <= s.max_range_m)
        if s.dropout_probability > 0:
            keep &= rng.random(len(ring)) >= s.dropout_probability
        if not keep.all():
            hits, ring, measured = hits.select(keep), ring[keep], measured[keep]
        return CastBlock(a, hits, ring, measured, dir_local, o_bvh, d_bvh)

    def _cast_weather(self, k, a, b, hits: CompactHits, rng, frame_index, dir_local, o_bvh, d_bvh) -> CastBlock:
        """``_cast_block``'s end with the receiver on: each beam's echo through ``WeatherModel.select``, then
        the range noise (the surface's incidence-grown sigma on a surface's echo, sigma itself on a weather
        echo), the range window and the dropouts."""
        s = self.sensor
        echo = hits.distance if s.beam_divergence_deg == 0 else self._echo_range(hits, o_bvh, d_bvh)
        cosk = np.abs(hits.cos_incidence)
        if s.intensity_incidence_exponent != 1:
            cosk = cosk**s.intensity_incidence_exponent
        refl = np.take(self._reflectance, np.take(self.world.face_object_id, hits.face))
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

    def _echo_range(self, hits: CompactHits, o_bvh: np.ndarray, d_bvh: np.ndarray) -> np.ndarray:
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
        sub = rc.cast_compact(np.repeat(origin, S, axis=0), dirs, s.max_range_m + 1.0)
        dist = np.full(m * S, np.inf)
        power = np.zeros(m * S)
        dist[sub.ray] = sub.distance
        cosk = np.abs(sub.cos_incidence) ** s.intensity_incidence_exponent
        power[sub.ray] = self._reflectance[self.world.face_object_id[sub.face]] * cosk / np.maximum(
            sub.distance, 1e-6) ** 2
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
        """Write one block's returns into rows off:off+m of the preallocated scan.

        Gathers go through ``np.take`` and the (m, 3) x (3, 3) products through ``_rows_times``:
        numpy's fancy indexing of rows, and BLAS (``matmul``, ``dot``) on such thin arrays, were 3 and 5
        times slower here.
        """
        s, rc = self.sensor, self.raycaster
        hits, measured, ray = c.hits, c.measured, c.hits.ray
        sl = slice(off, off + len(ray))
        R_ref, t_ref = T_ref[:3, :3], T_ref[:3, 3] - rc.offset
        g = c.first_ray + ray
        np.multiply(measured[:, None], np.take(c.dir_local, ray, axis=0), out=out.xyz[sl])  # as the sensor reports
        hit_bvh = np.take(c.direction_bvh, ray, axis=0)
        hit_bvh *= hits.distance[:, None]
        hit_bvh += np.take(c.origin_bvh, ray, axis=0)
        hit_bvh -= t_ref
        _rows_times(hit_bvh, R_ref, out.true_xyz[sl])  # BVH frame -> reference frame
        _rows_times(np.take(hits.face_normals, hits.face, axis=0), R_ref, out.normal[sl])
        out.normal[sl] *= -np.sign(hits.cos_incidence)[:, None]  # face the sensor
        obj = np.take(self.world.face_object_id, hits.face)
        falloff = np.minimum(1.0, (s.intensity_range_ref_m / np.maximum(measured, 1e-6)) ** 2)
        cosk = np.abs(hits.cos_incidence)
        if s.intensity_incidence_exponent != 1:
            cosk **= s.intensity_incidence_exponent
        out.intensity[sl] = np.take(self._reflectance, obj) * cosk * falloff
        if c.kind is not None:
            self._fill_weather(c, out, sl, obj)
        out.ring[sl] = c.ring
        np.take(self.ray_column, g, out=out.azimuth_index[sl])
        np.take(self.ray_time_s, g, out=out.time_s[sl])
        out.range_m[sl] = measured
        out.true_range_m[sl] = hits.distance
        out.object_id[sl] = obj
        if c.kind is not None:
            out.object_id[sl][hits.face < 0] = -1

    def _fill_weather(self, c: CastBlock, out: Scan, sl: slice, obj: np.ndarray) -> None:
        """The receiver's part of a block's rows: intensities (a surface's times its gain, a weather echo's from
        its power), the weather flags, and the truth of beams that reached no surface (NaN)."""
        s = self.sensor
        weather = c.kind != SURFACE
        intensity = out.intensity[sl]
        intensity *= np.where(weather, 1.0, c.gain)
        if weather.any():
            r = np.maximum(c.measured[weather], 1e-6)
            intensity[weather] = np.minimum(1.0, c.power[weather] * np.minimum(r, s.intensity_range_ref_m) ** 2)
            bare = c.hits.face < 0
            out.normal[sl][bare] = np.nan
        if out.weather is not None:
            out.weather[sl] = c.kind
