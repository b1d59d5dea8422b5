"""File formats, one module each, and the sequence readers ``simlidar.dataset.open_sequence`` consults.

- ``atomic``: atomic file writes, checksums, and the staged folder every folder writer builds in;
- ``kitti``: KITTI poses, times, calibration and ``.bin`` scans;
- ``tum``: TUM trajectories (for evo);
- ``number_lines``: the numbers-per-line text both pose formats are;
- ``ply``, ``pcd``: point clouds with per-point fields;
- ``points``: the per-point record the interchange formats carry (the Velodyne driver's layout plus truth);
- ``scan_folders``: ``Sequence`` (frames read from scan files) and the readers of real KITTI and plain scan folders;
- ``salo``: the simulator's own sequence folder (KITTI layout, sidecar, manifest): writer and reader;
- ``rosbag``: ROS 2 bags (``sensor_msgs/PointCloud2``): reader and writer.

None of them imports Embree, so the odometry reads real data without the simulator.
"""
