"""The factor-graph wing (GTSAM): the model's speeds preintegrated between keyframes.

- :mod:`fusion.graph.preintegration`: relative poses, covariances and calibration
  Jacobians between keyframes;
- :mod:`fusion.graph.factors`, :mod:`fusion.graph.calibrated_factors`: native and
  calibration-aware motion factors, range-bearing factors (from the package's one
  observation type, :class:`fusion.range_bearing.RangeBearing`);
- :mod:`fusion.graph.speed_noise`, :mod:`fusion.graph.transient_noise`: the speed-error
  covariances to preintegrate with, measured from calibration data;
- :mod:`fusion.graph.builder`, :mod:`fusion.graph.smoother`,
  :mod:`fusion.graph.smoother_options`: the graph and the iSAM2 smoother.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "CONSTANT_SIGMA_M",
    "DEFAULT_BANDWIDTH_S",
    "DEFAULT_ENCODER_STD",
    "DEFAULT_SLIP",
    "DEFAULT_WINDOW_S",
    "FILTERED_SLIP_DENSITY",
    "SLIP_DENSITY",
    "GraphBuilder",
    "IncrementalSmoother",
    "Preintegrated",
    "SmootherOptions",
    "SmootherResult",
    "SpeedMode",
    "TransientSpeedCovariance",
    "calibrated_motion_error",
    "calibrated_motion_errors",
    "calibrated_motion_factor",
    "calibrated_motion_group_factor",
    "calibration_intrinsics_estimate",
    "calibration_key",
    "calibration_walk_factor",
    "compose_motions",
    "filtered_speeds",
    "fit_calibration",
    "landmark_key",
    "log_keyframes",
    "long_run_contributions",
    "long_run_covariance",
    "mean_squared_tracking_error",
    "model_speed_errors",
    "motion_factor",
    "mounted_range_bearing_factor",
    "observe_landmarks",
    "pose2_log",
    "pose2_log_derivative",
    "pose_key",
    "predict_range_bearing",
    "preintegrate",
    "preintegrate_model",
    "range_bearing_factors",
    "relative_pose_errors",
    "slip_covariance",
    "smooth_batch",
    "smooth_log",
    "smoother_ates",
    "speed_covariance_from_data",
    "speed_error_covariance",
    "transient_speed_covariance_from_data",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "fusion.graph.builder": ("GraphBuilder",),
        "fusion.graph.calibrated_factors": (
            "calibrated_motion_error",
            "calibrated_motion_errors",
            "calibrated_motion_factor",
            "calibrated_motion_group_factor",
            "pose2_log",
            "pose2_log_derivative",
        ),
        "fusion.graph.factors": (
            "CONSTANT_SIGMA_M",
            "calibration_key",
            "calibration_walk_factor",
            "landmark_key",
            "motion_factor",
            "mounted_range_bearing_factor",
            "observe_landmarks",
            "pose_key",
            "predict_range_bearing",
            "range_bearing_factors",
        ),
        "fusion.graph.preintegration": (
            "FILTERED_SLIP_DENSITY",
            "Preintegrated",
            "SLIP_DENSITY",
            "SpeedMode",
            "compose_motions",
            "fit_calibration",
            "preintegrate",
            "preintegrate_model",
            "relative_pose_errors",
            "speed_error_covariance",
        ),
        "fusion.graph.smoother": (
            "IncrementalSmoother",
            "log_keyframes",
            "smooth_batch",
            "smooth_log",
            "smoother_ates",
        ),
        "fusion.graph.smoother_options": (
            "SmootherOptions",
            "SmootherResult",
            "calibration_intrinsics_estimate",
        ),
        "fusion.graph.speed_noise": (
            "DEFAULT_BANDWIDTH_S",
            "DEFAULT_ENCODER_STD",
            "filtered_speeds",
            "long_run_contributions",
            "long_run_covariance",
            "model_speed_errors",
            "slip_covariance",
            "speed_covariance_from_data",
        ),
        "fusion.graph.transient_noise": (
            "DEFAULT_SLIP",
            "DEFAULT_WINDOW_S",
            "TransientSpeedCovariance",
            "mean_squared_tracking_error",
            "transient_speed_covariance_from_data",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from fusion.graph.builder import GraphBuilder
    from fusion.graph.calibrated_factors import (
        calibrated_motion_error,
        calibrated_motion_errors,
        calibrated_motion_factor,
        calibrated_motion_group_factor,
        pose2_log,
        pose2_log_derivative,
    )
    from fusion.graph.factors import (
        CONSTANT_SIGMA_M,
        calibration_key,
        calibration_walk_factor,
        landmark_key,
        motion_factor,
        mounted_range_bearing_factor,
        observe_landmarks,
        pose_key,
        predict_range_bearing,
        range_bearing_factors,
    )
    from fusion.graph.preintegration import (
        FILTERED_SLIP_DENSITY,
        SLIP_DENSITY,
        Preintegrated,
        SpeedMode,
        compose_motions,
        fit_calibration,
        preintegrate,
        preintegrate_model,
        relative_pose_errors,
        speed_error_covariance,
    )
    from fusion.graph.smoother import (
        IncrementalSmoother,
        log_keyframes,
        smooth_batch,
        smooth_log,
        smoother_ates,
    )
    from fusion.graph.smoother_options import (
        SmootherOptions,
        SmootherResult,
        calibration_intrinsics_estimate,
    )
    from fusion.graph.speed_noise import (
        DEFAULT_BANDWIDTH_S,
        DEFAULT_ENCODER_STD,
        filtered_speeds,
        long_run_contributions,
        long_run_covariance,
        model_speed_errors,
        slip_covariance,
        speed_covariance_from_data,
    )
    from fusion.graph.transient_noise import (
        DEFAULT_SLIP,
        DEFAULT_WINDOW_S,
        TransientSpeedCovariance,
        mean_squared_tracking_error,
        transient_speed_covariance_from_data,
    )
