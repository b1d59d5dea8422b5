"""``tracks.csv``: every moving object's box near the sensor, per frame (a sequence folder's, beside ``poses.txt``).

Written when the world has moving objects (``simlidar.actors``); one row per frame and
object whose box comes within the sensor's maximum range at the sweep's start, or that the
frame's returns hit (one that came into the world during the sweep)::

    frame,object_id,class,moving,returns,x,y,z,qw,qx,qy,qz,length,width,height,vx,vy,vz

- ``frame``: the frame (0-based); ``object_id``: the object's id, as in the truth files (an index
  into the manifest's ``object_labels``; the manifest's ``actors`` describes each);
  ``class``: car, van, lorry, bus, cyclist or pedestrian; ``moving``: 1 when the object moved
  faster than 1 cm/s at the sweep's start; ``returns``: the frame's returns off it;
- ``x, y, z``: the centre of the object's box, and ``qw, qx, qy, qz`` its orientation (a unit
  quaternion, box axes: x forward, y left, z up), in the frame's scan frame (the sensor at the
  sweep's start, ``poses.txt``'s frame) at the sweep's start, m;
- ``length, width, height``: the box's size along its x, y, z, m;
- ``vx, vy, vz``: the velocity of the box's centre in the world, along the scan frame's axes, m/s.

A box in the first frame's frame is ``T_first_k @ [R(q) | centre]``; in the world, with the manifest's
``T_world_first_lidar`` in front.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..sequence import DatasetError
from .truth import ACTOR_CLASSES

FILE = "tracks.csv"
HEADER = "frame,object_id,class,moving,returns,x,y,z,qw,qx,qy,qz,length,width,height,vx,vy,vz"
TRACK_DTYPE = np.dtype([("object_id", "<i4"), ("object_class", "u1"), ("moving", "?"), ("returns", "<i4"),
                        ("centre", "<f8", (3,)), ("quaternion", "<f8", (4,)), ("size", "<f8", (3,)),
                        ("velocity", "<f8", (3,))])


def format_rows(frame: int, rows: np.ndarray) -> str:
    """One frame's lines of ``tracks.csv`` (each ending in a newline) from (n,) ``TRACK_DTYPE`` rows."""
    out = []
    for r in rows:
        c, q, s, v = r["centre"], r["quaternion"], r["size"], r["velocity"]
        out.append(f"{frame},{r['object_id']},{ACTOR_CLASSES[r['object_class']]},{int(r['moving'])},{r['returns']},"
                   f"{c[0]:.4f},{c[1]:.4f},{c[2]:.4f},{q[0]:.7f},{q[1]:.7f},{q[2]:.7f},{q[3]:.7f},"
                   f"{s[0]:.3f},{s[1]:.3f},{s[2]:.3f},{v[0]:.4f},{v[1]:.4f},{v[2]:.4f}\n")
    return "".join(out)


def read_tracks(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(frames (n,) int, rows (n,) ``TRACK_DTYPE``) of a ``tracks.csv``; DatasetError naming the file if malformed."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read tracks ({exc.strerror})") from None
    if not lines or lines[0].strip() != HEADER:
        raise DatasetError(f"{path}: not a tracks file (its first line is not '{HEADER}')")
    frames = np.empty(len(lines) - 1, np.int64)
    rows = np.zeros(len(lines) - 1, TRACK_DTYPE)
    for i, line in enumerate(lines[1:]):
        cells = line.split(",")
        try:
            if len(cells) != 18:
                raise ValueError(f"{len(cells)} fields, 18 expected")
            frames[i] = int(cells[0])
            rows[i]["object_id"] = int(cells[1])
            rows[i]["object_class"] = ACTOR_CLASSES.index(cells[2])
            rows[i]["moving"] = cells[3] == "1"
            rows[i]["returns"] = int(cells[4])
            values = [float(x) for x in cells[5:]]
        except ValueError as exc:
            raise DatasetError(f"{path}: line {i + 2}: {exc}") from None
        rows[i]["centre"], rows[i]["quaternion"] = values[0:3], values[3:7]
        rows[i]["size"], rows[i]["velocity"] = values[7:10], values[10:13]
    return frames, rows


__all__ = ["FILE", "HEADER", "TRACK_DTYPE", "format_rows", "read_tracks"]
