"""The per-point record the interchange formats carry: the Velodyne driver's layout, then the truth.

Packed, little-endian, in this order (fields a frame lacks are left out)::

    x f32 @0, y f32 @4, z f32 @8, intensity f32 @12, ring u16 @16, time f32 @18   (22 bytes, XYZIRT)
    azimuth_index u32 @22, true_range_m f32 @26, true_x/true_y/true_z f32 @30..38,
    normal_x/normal_y/normal_z f32 @42..50, object_id i32 @54                      (58 bytes)

``ring``: 0 = lowest beam; ``time``: s since the sweep start. Points are as
measured (in the sensor frame at each point's firing time); ``true_*`` is the
noise-free point in the sweep-start frame, ``normal_*`` the true surface
normal, ``object_id`` the world object hit: a simulated sequence's sidecar.
A ROS 2 bag carries it as a PointCloud2 (``simlidar.formats.rosbag``), a PLY or
PCD file as its vertex properties / fields.
"""

from __future__ import annotations

import numpy as np

from ..sequence import Frame

# the velodyne_pointcloud (ROS 2) XYZIRT layout, packed, then the simulator's ground truth
VELODYNE_FIELDS = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f4")]
TRUTH_FIELDS = [("azimuth_index", "<u4"), ("true_range_m", "<f4"), ("true_x", "<f4"), ("true_y", "<f4"),
                ("true_z", "<f4"), ("normal_x", "<f4"), ("normal_y", "<f4"), ("normal_z", "<f4"),
                ("object_id", "<i4")]
# per-point vectors written as three scalar fields (the PCL naming) and read back as one
VECTOR_FIELDS = {"true_xyz": ("true_x", "true_y", "true_z"), "normal": ("normal_x", "normal_y", "normal_z")}


def point_record(frame: Frame, truth: bool = True) -> np.ndarray:
    """One frame -> (N,) packed little-endian structured array in the layout above.

    x, y, z always; intensity, ring, time when the frame has them; the
    ground-truth fields when ``truth`` and the frame has all of them.
    """
    n = len(frame.points)
    columns: dict[str, np.ndarray] = {"x": frame.points[:, 0], "y": frame.points[:, 1], "z": frame.points[:, 2]}
    if frame.intensity is not None:
        columns["intensity"] = frame.intensity
    if frame.ring is not None:
        columns["ring"] = frame.ring
    if frame.time_s is not None:
        columns["time"] = frame.time_s
    names = frame.fields.dtype.names if frame.fields is not None and frame.fields.dtype.names else ()
    if truth and all(k in names for k in ("azimuth_index", "true_range_m", "true_xyz", "normal", "object_id")):
        columns["azimuth_index"] = frame.fields["azimuth_index"]
        columns["true_range_m"] = frame.fields["true_range_m"]
        for i, axis in enumerate("xyz"):
            columns[f"true_{axis}"] = frame.fields["true_xyz"][:, i]
            columns[f"normal_{axis}"] = frame.fields["normal"][:, i]
        columns["object_id"] = frame.fields["object_id"]
    dtype = [(name, t) for name, t in VELODYNE_FIELDS + TRUTH_FIELDS if name in columns]
    rec = np.empty(n, dtype=dtype)
    for name in rec.dtype.names:
        rec[name] = columns[name]
    return rec


__all__ = ["TRUTH_FIELDS", "VECTOR_FIELDS", "VELODYNE_FIELDS", "point_record"]
