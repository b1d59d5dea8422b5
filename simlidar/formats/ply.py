"""PLY point clouds: one vertex per point, with any per-point scalar properties.

Read through trimesh (any PLY a scanner or a mesh tool writes); written as
binary little-endian with the fields given. Meshes (the worlds) are
``simlidar.world``'s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..sequence import DatasetError
from .atomic import atomic_write_bytes

# Export names of per-point vector fields that mesh tools expect under other names.
PLY_FIELD_NAMES = {"normal_x": "nx", "normal_y": "ny", "normal_z": "nz"}


def read_ply_scan(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A PLY point cloud -> (points (N, 3) float64, intensity (N,) or None, vertex record or None).

    The vertex record keeps every per-point property of the file (``ring``,
    ``time``, ...), as named there.
    """
    import trimesh

    path = Path(path)
    try:
        cloud = trimesh.load(str(path), process=False)
    except Exception as exc:
        raise DatasetError(f"{path}: cannot read PLY ({type(exc).__name__}: {exc})") from None
    points = np.asarray(getattr(cloud, "vertices", np.zeros((0, 3))), dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise DatasetError(f"{path}: no x y z vertices in the PLY file")
    raw = cloud.metadata.get("_ply_raw", {}) if isinstance(cloud.metadata, dict) else {}
    record = raw.get("vertex", {}).get("data") if isinstance(raw, dict) else None
    intensity = None
    if record is not None and record.dtype.names:
        for name in ("intensity", "reflectance", "scalar_intensity"):
            if name in record.dtype.names:
                intensity = np.asarray(record[name], dtype=np.float32).reshape(-1)
                break
    return points, intensity, record


def write_ply_scan(path: str | Path, xyz: np.ndarray, fields: dict[str, np.ndarray]) -> None:
    """Binary little-endian PLY of points with extra per-point scalar properties.

    xyz: (N, 3) points, m (written as float32). fields: name -> (N,) array (its
    dtype decides the PLY type: f4, f8, u1, u2, u4, i4).
    """
    types = {"f4": "float", "f8": "double", "u1": "uchar", "u2": "ushort", "u4": "uint",
             "i4": "int", "i2": "short", "i1": "char"}
    cols = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    for name, arr in fields.items():
        code = np.asarray(arr).dtype.str.lstrip("<>|=")
        if code == "i8":
            code = "i4"
        if code == "u8":
            code = "u4"
        if code not in types:
            raise DatasetError(f"{path}: field '{name}' has unsupported dtype {arr.dtype}")
        cols.append((name, "<" + code))
    rec = np.empty(len(xyz), dtype=cols)
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    for name, arr in fields.items():
        rec[name] = arr
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {len(xyz)}\n"
    header += "".join(f"property {types[t.lstrip('<')]} {n}\n" for n, t in cols)
    header += "end_header\n"
    atomic_write_bytes(path, header.encode("ascii") + rec.tobytes())


__all__ = ["PLY_FIELD_NAMES", "read_ply_scan", "write_ply_scan"]
