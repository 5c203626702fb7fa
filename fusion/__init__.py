"""Estimators that use a calibrated motion model, as wings over a small shared base.

The base (this package's modules) holds what every wing shares: the noise types
(:mod:`fusion.noise`), the landmark map (:mod:`fusion.landmark_map`), the
range-bearing measurement model and observation type (:mod:`fusion.range_bearing`), the
sensor's mount on the robot (:mod:`fusion.sensor_pose`)
and the exceptions (:mod:`fusion.exceptions`). The wings, each a subpackage whose
``__init__`` re-exports its public names:

- :mod:`fusion.ekf`: the filterpy EKF with the model inside, its plain functions,
  the textbook velocity-model EKF;
- :mod:`fusion.graph`: GTSAM preintegrated factors and the iSAM2 smoother;
- :mod:`fusion.monitoring`: residual, dynamics and scale tests, recalibration;
- :mod:`fusion.landmarks`: ArUco detection, a synthetic camera, marker maps.

Importing this package loads only the base (numpy and scipy); filterpy, gtsam and
OpenCV load with the wing that uses them.
"""

from fusion.exceptions import FusionError
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise, ScaleErrors, SlipNoise
from fusion.range_bearing import RangeBearing
from fusion.sensor_pose import SensorPose

__all__ = [
    "FusionError",
    "LandmarkMap",
    "LandmarkNoise",
    "RangeBearing",
    "ScaleErrors",
    "SensorPose",
    "SlipNoise",
]
