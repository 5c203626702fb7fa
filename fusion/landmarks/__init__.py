"""The landmarks wing: range-bearing sightings from a camera (OpenCV ArUco) or a simulation.

- :mod:`fusion.landmarks.aruco`: marker detection to range-bearing with covariance (a
  :class:`fusion.range_bearing.RangeBearing`, the package's one observation type);
- :mod:`fusion.landmarks.camera`: a synthetic camera that renders markers;
- :mod:`fusion.landmarks.marker_map`: marker maps and their files;
- :mod:`fusion.landmarks.synthetic`: noisy sightings drawn from known poses.
"""

from fusion.landmarks.aruco import MarkerDetector, detection_diagnostics
from fusion.landmarks.camera import CameraIntrinsics, CameraMount, SyntheticCamera
from fusion.landmarks.marker_map import MarkerLandmark, MarkerMap, load_marker_map, save_marker_map
from fusion.landmarks.synthetic import synthetic_observations

__all__ = [
    "CameraIntrinsics",
    "CameraMount",
    "MarkerDetector",
    "MarkerLandmark",
    "MarkerMap",
    "SyntheticCamera",
    "detection_diagnostics",
    "load_marker_map",
    "save_marker_map",
    "synthetic_observations",
]
