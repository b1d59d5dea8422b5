"""PCD v0.7 point clouds (the Point Cloud Library's format): binary (a packed record) or ASCII.

Fields are any scalar or fixed-length vector of float, unsigned or signed
integers (``SIZE`` 1, 2, 4 or 8 bytes, ``COUNT`` the vector length); one point
per record, ``HEIGHT 1``. ``binary_compressed`` is not read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..sequence import DatasetError
from .atomic import atomic_write_bytes

_PCD_TYPES = {"f": "F", "u": "U", "i": "I"}


def write_pcd(path: str | Path, record: np.ndarray, binary: bool = True) -> None:
    """Write a PCD v0.7 file: one point per record of ``record`` ((N,) structured, scalar or vector fields).

    Binary data is the packed little-endian record; ASCII writes floats with
    enough digits to read back the same value (9 for float32, 17 for float64).
    """
    path = Path(path)
    rec = np.ascontiguousarray(record)
    names, sizes, types, counts, formats = [], [], [], [], []
    for name in rec.dtype.names:
        sub = rec.dtype.fields[name][0]
        base = sub.base
        if base.kind not in _PCD_TYPES or base.itemsize not in (1, 2, 4, 8):
            raise DatasetError(f"{path}: field '{name}' has dtype {base}, which PCD cannot hold")
        count = int(np.prod(sub.shape)) if sub.shape else 1
        names.append(name)
        sizes.append(str(base.itemsize))
        types.append(_PCD_TYPES[base.kind])
        counts.append(str(count))
        fmt = "%.9g" if base == np.float32 else "%.17g" if base.kind == "f" else "%d"
        formats += [fmt] * count
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(names)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join(types)}\nCOUNT {' '.join(counts)}\n"
        f"WIDTH {len(rec)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(rec)}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    little = np.dtype([(n, rec.dtype.fields[n][0].newbyteorder("<")) for n in names])
    packed = rec.astype(little)  # drops any padding, fixes the byte order
    if binary:
        payload = packed.tobytes()
    else:
        columns = [packed[n].reshape(len(packed), -1).astype(np.float64 if packed[n].dtype.kind == "f" else np.int64)
                   for n in names]
        table = np.hstack(columns) if columns else np.zeros((len(packed), 0))
        lines = []
        for row in table:
            lines.append(" ".join(f % (v if f != "%d" else int(v)) for f, v in zip(formats, row, strict=True)))
        payload = ("\n".join(lines) + ("\n" if lines else "")).encode("ascii")
    try:
        atomic_write_bytes(path, header.encode("ascii") + payload)
    except OSError as exc:
        raise DatasetError(f"{path}: cannot write ({exc.strerror})") from None


def read_pcd(path: str | Path) -> np.ndarray:
    """Read a PCD v0.7 file (ascii or binary; not binary_compressed) -> (N,) structured array of its fields."""
    path = Path(path)
    try:
        blob = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read PCD ({exc.strerror})") from None
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = blob.find(b"\n", pos)
        if end < 0:
            raise DatasetError(f"{path}: PCD header has no DATA line")
        line = blob[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    try:
        names = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(names))]
        n = int(header.get("POINTS", [0])[0]) or int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
    except (KeyError, ValueError, IndexError):
        raise DatasetError(f"{path}: PCD header lacks or garbles FIELDS / SIZE / TYPE / COUNT / POINTS") from None
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise DatasetError(f"{path}: PCD header FIELDS, SIZE, TYPE and COUNT differ in length")
    kinds = {"F": "f", "U": "u", "I": "i"}
    dtype = []
    for name, size, t, count in zip(names, sizes, types, counts, strict=True):
        if t.upper() not in kinds:
            raise DatasetError(f"{path}: PCD field '{name}' has unknown TYPE {t}")
        base = np.dtype(f"<{kinds[t.upper()]}{size}")
        dtype.append((name, base, (count,)) if count > 1 else (name, base))
    dtype = np.dtype(dtype)
    kind = header["DATA"][0].lower() if header["DATA"] else ""
    if kind == "binary":
        if len(blob) - pos < n * dtype.itemsize:
            raise DatasetError(f"{path}: PCD data holds {len(blob) - pos} bytes, {n} points need {n * dtype.itemsize}")
        return np.frombuffer(blob, dtype=dtype, count=n, offset=pos).copy()
    if kind == "ascii":
        text = blob[pos:].decode("ascii", errors="replace").split()
        width = sum(counts)
        if len(text) < n * width:
            raise DatasetError(f"{path}: PCD ascii data holds {len(text)} values, {n} points need {n * width}")
        table = np.array(text[: n * width], dtype=np.float64).reshape(n, width)
        rec = np.empty(n, dtype=dtype)
        col = 0
        for name, count in zip(names, counts, strict=True):
            block = table[:, col:col + count]
            rec[name] = block[:, 0] if count == 1 else block
            col += count
        return rec
    raise DatasetError(f"{path}: PCD DATA '{kind}' is not supported (ascii or binary)")


__all__ = ["read_pcd", "write_pcd"]
