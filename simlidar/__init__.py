"""simlidar: a spinning-lidar simulator on Embree with known noise and ground truth.

Import the modules you need; ``simlidar.sensor``, ``simlidar.se3`` and
``simlidar.dataset`` import no Embree, so odometry can use them on real data.
"""

__version__ = "0.1.0"
