"""The compact per-return truth of a simulated sequence (sequence format versions 2 and 3).

One file per frame, ``sidecar/NNNNNN.truth``, beside the frame's KITTI ``.bin``
(whose points it describes, in the same order). Little-endian throughout::

    header   32 bytes: magic b"SALOTRU2", u4 returns N, u4 knots K, u1 object-id bytes W (1, 2 or 4),
             u1 compression (0: none, 1: zlib, the rest of the file one zlib stream), u1 blocks B
             (version 3; 0 in version 2: a bit per optional block after the object ids), 13 bytes zero
    knots    K x 6 float32: the sensor's motion during the sweep, knot c at the start of firing
             column c (c = 0..K-1, K = columns + 1; K = 0 without motion distortion): rotation
             vector (rad) and translation (m) of T_start_fire, the sensor pose at that instant in
             the sweep-start frame
    ray      N x u4: firing index, column * rings + ring (ring 0 the lowest beam)
    range    N x f4: true range, m: the noise-free distance from where the beam left to the surface
             along the beam
    normal   N x 2 int16: the true surface normal in the sweep-start frame, facing the sensor,
             octahedral encoding scaled by 32767
    object   N x uW: the object hit; W is the fewest bytes that hold the world's object count
    weather  (block bit 0, ``BLOCK_WEATHER``) N x u1: what each return is, ``simlidar.weather.KINDS``
             (0 a surface, 1 fog, 2 rain, 3 snow)
    actors   (block bit 1, ``BLOCK_ACTORS``) N x u1 ``what``: 0 the static world, else the moving object's
             class in bits 0-6 (``ACTOR_CLASSES``: 1 car, 2 van, 3 lorry, 4 bus, 5 cyclist, 6 pedestrian)
             and bit 7 set when the surface hit was moving at the return's instant (faster than
             ``MOVING_SPEED_M_S``); then M x 3 i2, one row per return whose ``what`` is not 0, in
             order: the velocity of the point hit (in the world, along the scan frame's axes), cm/s

Optional blocks (format version 3). A block is a set of per-return fields of
its own, present when its bit of the header's byte B is set, stored after the
object ids in the order of the bits; a reader refuses a file with a bit it does
not know. A file without blocks is a version-2 file byte for byte, and the
sequence's manifest says ``format_version`` 3 only when some frame has a block
(so readers of version 2 refuse it with a clear message). The weather block
(bit 0): for a weather return, the record's truth (range, normal, object) is
the surface its beam reached, if any; a beam that reached none stores range
NaN (normal and object written as 0), decoded as true_xyz and normal NaN and
object_id -1. The decoded record then has the field ``weather``
(``sidecar_dtype(weather=True)``). The actors block (bit 1, ``simlidar.actors``: cars,
lorries, cyclists, pedestrians moving through the world): the decoded record has the
fields ``object_class`` (u1, 0 for the static world), ``moving`` (bool) and ``velocity``
(3 float32, m/s; zero on the static world), ``sidecar_dtype(actors=True)``. The
velocity is rounded to 1 cm/s (``VELOCITY_STEP_M_S``).

that is 14 bytes a return (16 for worlds of more than 65,536 objects) plus 24
bytes a column for the motion (salo32 in a city: 0.8 bytes a return), against
50 in format version 1 (``simlidar.sweep.SIDECAR_DTYPE``, one ``.npy`` per frame).
Compressed (``compress=True``, ``salo simulate --compress-truth``), a salo32 city
sweep's truth takes 5.4 bytes a return, at 45 ms more a frame to write and 8 ms
to read (zlib level 1).

``decode`` rebuilds the version-1 record (``SIDECAR_DTYPE``: every field the
readers have always given) from this file, the frame's ``.bin`` points and the
sequence's own sensor model:

- ring, azimuth_index: from the firing index (exact);
- time_s: the sensor's firing table at (ring, column) (exact: the simulator's own formula);
- range_m: the length of the ``.bin`` point (the measured range, float32 rounding: <= 1.2e-7 x range;
  a return measured at exactly 0 m, possible only with ``min_range_m`` 0, has no direction and
  its true_xyz is then the firing position);
- true_xyz: ``t(t_k) + true_range * R(t_k) b``, the beam ``b`` being the unit vector of the ``.bin``
  point (measured points lie on their beam, so jitter and divergence are carried), ``R, t`` the
  sensor's pose at the firing time in the sweep-start frame, from the knots (exact at the knots,
  which are the firing times when a column fires at once; linear within a column otherwise,
  a 55 microsecond step for salo32, second order in it: below 1e-9 m). Error bound, from the
  float32 rounding of the range, the ``.bin`` point and the knots:
  ``|true_xyz - truth| <= 4e-7 x true_range + 1e-6 m`` (80 micrometres at 200 m; version 1
  stored float32 coordinates: <= 6e-8 x |coordinate|);
- normal: octahedral decoding, angular error below 0.004 deg (0.0037 measured over 2 million
  directions; bound 0.01 deg);
- object_id: exact.

The round trip is tested against the simulator's float64 truth
(``tests/test_truth_format.py``).
"""

from __future__ import annotations

import zlib

import numpy as np

from ..kernels.files import fill_body
from ..sequence import DatasetError

MAGIC = b"SALOTRU2"
HEADER_BYTES = 32
KNOT_FLOATS = 6
OCT_SCALE = 32767.0
# Bounds the format guarantees (docs/sequence-format.md; checked by the round-trip test).
TRUE_XYZ_REL_BOUND = 4e-7  # x true range
TRUE_XYZ_ABS_BOUND_M = 1e-6
NORMAL_BOUND_DEG = 0.01

# The version-1 per-point record every reader gives (kept so callers see the same fields).
SIDECAR_DTYPE = np.dtype(
    [
        ("ring", "<u2"),
        ("azimuth_index", "<u4"),
        ("time_s", "<f8"),
        ("range_m", "<f4"),
        ("true_range_m", "<f4"),
        ("true_xyz", "<f4", (3,)),
        ("normal", "<f4", (3,)),
        ("object_id", "<i4"),
    ]
)
# Optional blocks: the header's byte 18, a bit each.
BLOCKS_BYTE = 18
BLOCK_WEATHER = 1
BLOCK_ACTORS = 2
KNOWN_BLOCKS = BLOCK_WEATHER | BLOCK_ACTORS
WEATHER_DTYPE = np.dtype(SIDECAR_DTYPE.descr + [("weather", "u1")])
# What a method may read of a return (``decode(..., truth=False)``): when and by which beam it was measured.
FIRING_DTYPE = np.dtype(SIDECAR_DTYPE.descr[:4])
ACTOR_FIELDS = [("object_class", "u1"), ("moving", "?"), ("velocity", "<f4", (3,))]
# The classes of moving objects, by their code in the actors block (0: the static world).
ACTOR_CLASSES = ("world", "car", "van", "lorry", "bus", "cyclist", "pedestrian")
MOVING_BIT = 0x80
MOVING_SPEED_M_S = 0.01  # a surface faster than this moves (1 cm/s: the velocity's own step)
VELOCITY_STEP_M_S = 0.01


def sidecar_dtype(weather: bool = False, actors: bool = False) -> np.dtype:
    """The decoded per-point record: ``SIDECAR_DTYPE``, with the ``weather`` field (u1) when the truth has one,
    and the actors' fields (``ACTOR_FIELDS``: object_class, moving, velocity) when it has those."""
    if not actors:
        return WEATHER_DTYPE if weather else SIDECAR_DTYPE
    return np.dtype((WEATHER_DTYPE if weather else SIDECAR_DTYPE).descr + ACTOR_FIELDS)


def object_id_bytes(n_objects: int) -> int:
    """The fewest bytes (1, 2 or 4) of an unsigned id that numbers ``n_objects`` objects."""
    if n_objects <= 1 << 8:
        return 1
    if n_objects <= 1 << 16:
        return 2
    return 4


# ---------------------------------------------------------------- normals
def octahedral_encode(normal: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors -> (N, 2) int16 octahedral codes (scale 32767, rounded to nearest).

    Computed in float32 on the columns (float32 rounding, 6e-8, is far below a code step, 3e-5).
    """
    cols = np.asarray(normal, dtype=np.float32).T  # (3, N) views of the columns
    x, y, z = cols[0], cols[1], cols[2]
    l1 = np.abs(x) + np.abs(y) + np.abs(z)
    np.maximum(l1, np.float32(1e-30), out=l1)
    px, py = x / l1, y / l1
    lower = z < 0  # the lower half folds over the diagonals, branch-free
    one = np.float32(1.0)
    fx = (one - np.abs(py)) * np.where(px >= 0, one, -one)
    fy = (one - np.abs(px)) * np.where(py >= 0, one, -one)
    p = np.empty((len(x), 2), dtype=np.float32)
    np.copyto(p[:, 0], np.where(lower, fx, px))
    np.copyto(p[:, 1], np.where(lower, fy, py))
    p *= np.float32(OCT_SCALE)
    np.clip(p, -OCT_SCALE, OCT_SCALE, out=p)
    return np.rint(p).astype("<i2")


def octahedral_decode(code: np.ndarray) -> np.ndarray:
    """(N, 2) int16 octahedral codes -> (N, 3) float64 unit vectors."""
    p = np.asarray(code, dtype=np.float64) / OCT_SCALE
    z = 1.0 - np.abs(p[:, 0]) - np.abs(p[:, 1])
    lower = z < 0
    if lower.any():
        q = p[lower]
        sign = np.where(q >= 0, 1.0, -1.0)
        p[lower] = (1.0 - np.abs(q[:, ::-1])) * sign
    n = np.column_stack([p, z])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# ---------------------------------------------------------------- rotations
def rotvec_of(R: np.ndarray) -> np.ndarray:
    """(K, 3, 3) rotations (angles below pi) -> (K, 3) rotation vectors, rad."""
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    s2 = np.linalg.norm(v, axis=1)  # 2 sin(theta)
    theta = np.arctan2(s2, np.trace(R, axis1=1, axis2=2) - 1.0)
    scale = np.where(s2 > 1e-12, theta / np.where(s2 > 1e-12, s2, 1.0), 0.5)
    return v * scale[:, None]


def rotate(rotvec: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (N, 3) vectors by (N, 3) rotation vectors (Rodrigues), float64."""
    theta = np.linalg.norm(rotvec, axis=1)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    k = rotvec / th[:, None]
    k[small] = 0.0
    c, s = np.cos(theta), np.sin(theta)
    kxv = np.cross(k, v)
    kv = np.einsum("ij,ij->i", k, v)
    out = v * c[:, None] + kxv * s[:, None] + k * (kv * (1 - c))[:, None]
    if small.any():  # first order: v + w x v
        out[small] = v[small] + np.cross(rotvec[small], v[small])
    return out


def motion_knots(T_start_fire: np.ndarray) -> np.ndarray:
    """(K, 4, 4) poses at the column starts in the sweep-start frame -> (K, 6) float32 knots."""
    T = np.asarray(T_start_fire, dtype=np.float64)
    return np.concatenate([rotvec_of(T[:, :3, :3]), T[:, :3, 3]], axis=1).astype("<f4")


# ---------------------------------------------------------------- encode / decode
def encode(ray: np.ndarray, true_range_m: np.ndarray, normal: np.ndarray, object_id: np.ndarray,
           knots: np.ndarray | None, id_bytes: int, compress: bool = False, weather: np.ndarray | None = None,
           actors: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, scratch: dict | None = None):
    """One frame's truth file as bytes (see the module doc).

    ray: (N,) firing index. true_range_m: (N,) m. normal: (N, 3) unit, sweep-start frame, or
    (N, 2) int16 octahedral codes already. object_id: (N,) >= 0. knots: (K, 6) float32 or None.
    id_bytes: 1, 2 or 4. compress: zlib (level 1) the part after the header. weather: (N,) uint8
    kinds (the weather block), or None; its returns without a surface (true range NaN) may carry
    any normal and object id (NaN, -1): 0 is written. actors: (object_class (N,) uint8, moving (N,)
    bool, velocity (N, 3) m/s) (the actors block), or None. scratch: a dict the caller keeps between
    frames; the file is then built in a buffer it holds (no new memory to touch each frame) and
    returned as a memoryview of it, valid until the next call with the same scratch.
    """
    n = len(ray)
    knots = np.zeros((0, KNOT_FLOATS), "<f4") if knots is None else np.ascontiguousarray(knots, "<f4")
    ids = np.asarray(object_id)
    true_range_m = np.asarray(true_range_m)
    live = ids[~np.isnan(true_range_m)] if weather is not None else ids  # a bare weather return's id is written 0
    if len(live) and (live.min() < 0 or live.max() >= 1 << (8 * id_bytes)):
        raise ValueError(f"object ids {live.min()}..{live.max()} do not fit in {id_bytes} bytes")
    if weather is not None and len(weather) != n:
        raise ValueError(f"{len(weather)} weather kinds for {n} returns")
    what = velocity_cm = None
    if actors is not None:
        object_class, moving, velocity = actors
        if not len(object_class) == len(moving) == len(velocity) == n:
            raise ValueError(f"actors' truth of {len(object_class)}, {len(moving)}, {len(velocity)} rows for {n} "
                             "returns")
        what = np.asarray(object_class, np.uint8) | np.where(moving, MOVING_BIT, 0).astype(np.uint8)
        velocity_cm = np.rint(np.asarray(velocity, np.float64)[what != 0] / VELOCITY_STEP_M_S)
        velocity_cm = np.clip(velocity_cm, -32767, 32767).astype("<i2")
    sizes = [knots.nbytes, 4 * n, 4 * n, 4 * n, id_bytes * n, 0 if weather is None else n,
             0 if what is None else n + velocity_cm.nbytes]
    total = HEADER_BYTES + sum(sizes)
    if scratch is None:
        buf = np.empty(total, np.uint8)
    else:
        buf = scratch.get("truth")
        if buf is None or len(buf) < total:
            buf = scratch["truth"] = np.empty(max(total, int(1.25 * total)), np.uint8)
        buf = buf[:total]
    buf[:HEADER_BYTES] = 0
    buf[:8] = np.frombuffer(MAGIC, np.uint8)
    buf[8:16] = np.frombuffer(np.array([n, len(knots)], "<u4").tobytes(), np.uint8)
    buf[16] = id_bytes
    buf[17] = 1 if compress else 0
    buf[BLOCKS_BYTE] = (0 if weather is None else BLOCK_WEATHER) | (0 if what is None else BLOCK_ACTORS)
    off = HEADER_BYTES
    buf[off:off + knots.nbytes] = knots.view(np.uint8).ravel()
    off += knots.nbytes
    views = []
    for dtype, count in (("<u4", n), ("<f4", n), ("<i2", 2 * n), (f"<u{id_bytes}", n)):
        size = np.dtype(dtype).itemsize * count
        views.append(buf[off:off + size].view(dtype))
        off += size
    codes = normal if normal.dtype == np.int16 else None
    fill_body(np.asarray(ray), true_range_m, np.zeros((0, 3)) if codes is not None else np.asarray(normal, np.float64),
              ids, weather is not None, *views)
    if codes is not None:
        views[2][:] = np.ascontiguousarray(codes, "<i2").ravel()
        if weather is not None:
            views[2].reshape(n, 2)[np.isnan(true_range_m)] = 0
    if weather is not None:
        buf[off:off + n] = weather
        off += n
    if what is not None:
        buf[off:off + n] = what
        off += n
        buf[off:off + velocity_cm.nbytes] = velocity_cm.view(np.uint8).ravel()
        off += velocity_cm.nbytes
    if compress:
        return buf[:HEADER_BYTES].tobytes() + zlib.compress(buf[HEADER_BYTES:], 1)
    return memoryview(buf) if scratch is not None else buf.tobytes()


def read_header(data: bytes, where) -> tuple[int, int, int, bytes]:
    """(returns, knots, id bytes, body) of a truth file's bytes, the body decompressed (with the optional
    blocks the header's byte ``BLOCKS_BYTE`` flags); DatasetError naming ``where`` if malformed."""
    if len(data) < HEADER_BYTES or data[:8] != MAGIC:
        raise DatasetError(f"{where}: not a truth file (no {MAGIC.decode()} header)")
    n, k = (int(v) for v in np.frombuffer(data[8:16], "<u4"))
    width, compression = data[16], data[17]
    if width not in (1, 2, 4):
        raise DatasetError(f"{where}: object-id width {width} bytes (1, 2 or 4 expected)")
    if compression not in (0, 1):
        raise DatasetError(f"{where}: unknown compression {compression} (0 or 1 expected)")
    blocks = data[BLOCKS_BYTE]
    if blocks & ~KNOWN_BLOCKS:
        raise DatasetError(f"{where}: optional truth blocks 0x{blocks & ~KNOWN_BLOCKS:02x} this version does not "
                           "read (written by a newer salo-bench?)")
    body = data[HEADER_BYTES:]
    if compression == 1:
        try:
            body = zlib.decompress(body)
        except zlib.error as exc:
            raise DatasetError(f"{where}: damaged compressed truth ({exc})") from None
    expected = k * KNOT_FLOATS * 4 + n * (4 + 4 + 4 + width + (1 if blocks & BLOCK_WEATHER else 0))
    if blocks & BLOCK_ACTORS and len(body) >= expected + n:  # the moving returns' velocities follow their classes
        what = np.frombuffer(body, "u1", n, expected)
        expected += n + 6 * int(np.count_nonzero(what))
    elif blocks & BLOCK_ACTORS:
        expected += n
    if len(body) != expected:
        raise DatasetError(f"{where}: {len(body) + HEADER_BYTES:,} bytes, the header's {n:,} returns and {k} knots "
                           f"need {expected + HEADER_BYTES:,} (truncated or damaged)")
    return n, k, width, body


def decode(data: bytes, xyz: np.ndarray, sensor, where="truth file", truth: bool = True) -> np.ndarray:
    """A truth file's bytes and its frame's (N, 3) ``.bin`` points -> (N,) ``sidecar_dtype`` records (with the
    ``weather`` field when the file has the weather block).

    sensor: the sequence's own ``LidarModel`` (its rings and firing table). truth: False gives only the
    firing fields (``FIRING_DTYPE``: ring, column, time, measured range), what a method reads, at a
    small part of the cost. Raises DatasetError naming ``where`` when the file is malformed or does
    not match the points.
    """
    blocks = data[BLOCKS_BYTE] if len(data) > BLOCKS_BYTE else 0
    n, k, width, data = read_header(data, where)
    if n != len(xyz):
        raise DatasetError(f"{where}: {n} returns but the scan has {len(xyz)} points")
    off = 0
    knots = np.frombuffer(data, "<f4", k * KNOT_FLOATS, off).reshape(k, KNOT_FLOATS)
    off += knots.nbytes
    ray = np.frombuffer(data, "<u4", n, off)
    off += 4 * n
    true_range = np.frombuffer(data, "<f4", n, off)
    off += 4 * n
    codes = np.frombuffer(data, "<i2", 2 * n, off).reshape(n, 2)
    off += 4 * n
    obj = np.frombuffer(data, f"<u{width}", n, off)
    off += width * n
    weather = None
    if blocks & BLOCK_WEATHER:
        weather = np.frombuffer(data, "u1", n, off)
        off += n
    what = None
    if blocks & BLOCK_ACTORS:
        what = np.frombuffer(data, "u1", n, off)
        off += n
        moved = what != 0
        velocity_cm = np.frombuffer(data, "<i2", 3 * int(moved.sum()), off).reshape(-1, 3)

    rings = sensor.rings
    ring, col = ray % rings, ray // rings
    if n and col.max() >= sensor.columns_per_sweep:
        raise DatasetError(f"{where}: firing index {int(ray.max())} beyond the sensor's "
                           f"{sensor.rays_per_sweep} rays per sweep")
    out = np.empty(n, sidecar_dtype(weather is not None, what is not None) if truth else FIRING_DTYPE)
    out["ring"], out["azimuth_index"] = ring, col
    out["time_s"] = sensor.firing_time_s(ring, col)
    xyz64 = np.asarray(xyz, dtype=np.float64)
    measured = np.linalg.norm(xyz64, axis=1)
    out["range_m"] = measured
    if not truth:
        return out
    out["true_range_m"] = true_range
    beam = xyz64 / np.where(measured > 0, measured, 1.0)[:, None]
    p = beam * true_range[:, None].astype(np.float64)
    if k:
        if n and col.max() + 1 >= k:
            raise DatasetError(f"{where}: column {int(col.max())} has no motion knot ({k} knots)")
        kn = knots.astype(np.float64)
        frac = (out["time_s"] - col * sensor.column_period_s) / sensor.column_period_s
        if np.any(frac > 0):
            motion = kn[col] + (kn[col + 1] - kn[col]) * frac[:, None]
        else:
            motion = kn[col]
        p = rotate(motion[:, :3], p) + motion[:, 3:]
    out["true_xyz"] = p
    out["normal"] = octahedral_decode(codes)
    out["object_id"] = obj
    if weather is not None:
        out["weather"] = weather
        bare = np.isnan(true_range)
        out["normal"][bare] = np.nan
        out["object_id"][bare] = -1
    if what is not None:
        out["object_class"] = what & ~np.uint8(MOVING_BIT)
        out["moving"] = (what & MOVING_BIT) != 0
        out["velocity"] = 0.0
        out["velocity"][moved] = velocity_cm * VELOCITY_STEP_M_S
    return out


__all__ = ["ACTOR_CLASSES", "BLOCK_ACTORS", "BLOCK_WEATHER", "FIRING_DTYPE", "HEADER_BYTES", "MAGIC",
           "MOVING_SPEED_M_S", "NORMAL_BOUND_DEG", "SIDECAR_DTYPE", "TRUE_XYZ_ABS_BOUND_M", "TRUE_XYZ_REL_BOUND",
           "VELOCITY_STEP_M_S", "WEATHER_DTYPE", "decode", "encode", "motion_knots", "object_id_bytes",
           "octahedral_decode", "octahedral_encode", "read_header", "rotate", "rotvec_of", "sidecar_dtype"]
