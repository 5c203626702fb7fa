"""The landmarks wing: range-bearing sightings from a camera (OpenCV ArUco) or a simulation.

- :mod:`fusion.landmarks.aruco`: marker detection to range-bearing with covariance (a
  :class:`fusion.range_bearing.RangeBearing`, the package's one observation type);
- :mod:`fusion.landmarks.camera`: a synthetic camera that renders markers;
- :mod:`fusion.landmarks.marker_map`: marker maps and their files;
- :mod:`fusion.landmarks.synthetic`: noisy sightings drawn from known poses.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "FILE_FORMAT",
    "FILE_VERSION",
    "OPTICAL_TO_ROBOT",
    "QUIET_ZONE_CELLS",
    "CameraIntrinsics",
    "CameraMount",
    "CornerNoise",
    "MarkerDetector",
    "MarkerLandmark",
    "MarkerMap",
    "SyntheticCamera",
    "check_camera_matrix",
    "check_dist_coeffs",
    "correct_edge_bias",
    "detect_markers",
    "detection_diagnostics",
    "dictionary_size",
    "edge_shift_directions",
    "load_marker_map",
    "marker_object_points",
    "observation_from_corners",
    "observations_from_pose",
    "save_marker_map",
    "synthetic_observations",
    "world_T_camera",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "fusion.landmarks.aruco": (
            "CornerNoise",
            "MarkerDetector",
            "correct_edge_bias",
            "detect_markers",
            "detection_diagnostics",
            "edge_shift_directions",
            "marker_object_points",
            "observation_from_corners",
            "observations_from_pose",
        ),
        "fusion.landmarks.camera": (
            "CameraIntrinsics",
            "CameraMount",
            "OPTICAL_TO_ROBOT",
            "QUIET_ZONE_CELLS",
            "SyntheticCamera",
            "check_camera_matrix",
            "check_dist_coeffs",
            "world_T_camera",
        ),
        "fusion.landmarks.marker_map": (
            "FILE_FORMAT",
            "FILE_VERSION",
            "MarkerLandmark",
            "MarkerMap",
            "dictionary_size",
            "load_marker_map",
            "save_marker_map",
        ),
        "fusion.landmarks.synthetic": ("synthetic_observations",),
    },
    __all__,
)

if TYPE_CHECKING:
    from fusion.landmarks.aruco import (
        CornerNoise,
        MarkerDetector,
        correct_edge_bias,
        detect_markers,
        detection_diagnostics,
        edge_shift_directions,
        marker_object_points,
        observation_from_corners,
        observations_from_pose,
    )
    from fusion.landmarks.camera import (
        OPTICAL_TO_ROBOT,
        QUIET_ZONE_CELLS,
        CameraIntrinsics,
        CameraMount,
        SyntheticCamera,
        check_camera_matrix,
        check_dist_coeffs,
        world_T_camera,
    )
    from fusion.landmarks.marker_map import (
        FILE_FORMAT,
        FILE_VERSION,
        MarkerLandmark,
        MarkerMap,
        dictionary_size,
        load_marker_map,
        save_marker_map,
    )
    from fusion.landmarks.synthetic import synthetic_observations
