"""A stand-in for your odometry: replace it with your own program (any language).

salo regress runs it once per sequence as the workflow's SALO_COMMAND says, with
{sequence}: a folder of what a real sensor gives and nothing else:

    velodyne/NNNNNN.bin   float32 x y z intensity per point, lidar frame, as measured
    times.txt             each scan's sweep start, s
    sensor.yaml           the sensor model (rings, vertical angles, rate, range limits)
    fields/NNNNNN.npy     per-point ring and time_s (SALO_FIELDS / the suite's fields)

and {out}: the file to write, one line per scan, the 3x4 row-major lidar pose in
the first scan's frame (KITTI poses). This one reads the folder with salo's own
reader and registers the scans with salo's scan-to-scan baseline, frame by frame.
"""

import sys

import numpy as np

from odometry.config import variant
from odometry.pipeline import Odometry
from simlidar.dataset import open_sequence
from simlidar.formats.kitti import write_kitti_poses


def main(folder: str, out: str) -> None:
    sequence = open_sequence(folder)  # no poses in it: sequence.poses is None
    odometry = Odometry(variant("bl"), sequence.sensor)
    for k, frame in enumerate(sequence):
        odometry.register_frame(frame, stamp_s=float(sequence.times[k]))
    write_kitti_poses(out, np.stack(odometry.poses))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
