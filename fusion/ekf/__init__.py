"""The EKF wing: the calibrated model inside a filterpy Extended Kalman Filter.

- :class:`ModelEKF` (:mod:`fusion.ekf.model_ekf`): the filterpy subclass, with its options
  (:class:`EKFOptions`, :mod:`fusion.ekf.ekf_options`) and the raw counts it holds between
  frames (:class:`EncoderCounts`, :mod:`fusion.ekf.encoder_counts`);
- :mod:`fusion.ekf.functions`: the same maths as plain functions, for a user's own
  filterpy EKF or UKF (:class:`FilterModel` lays a model out for a filter);
- :mod:`fusion.ekf.kernel`: the per-step arithmetic of the prediction and the encoder
  update, compiled with numba (on first use; cached on disk);
- :class:`VelocityModelEKF` (:mod:`fusion.ekf.velocity_ekf`): the textbook
  velocity-model EKF, the baseline;
- :mod:`fusion.ekf.updates`: what both filters share, the chi-square gate,
  :class:`UpdateRecord`, :class:`FilterStats` and the landmark updates
  (``update_landmark``, ``update_landmarks``);
- :mod:`fusion.ekf.resets`: the bounds on :class:`ModelEKF`'s scale-error states
  and its resets (:class:`FilterReset`);
- :mod:`fusion.scale_errors`: the odometry intrinsics the scale errors
  imply (:class:`IntrinsicsEstimate`, from :meth:`ModelEKF.intrinsics_estimate`).

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "GYRO_BIAS",
    "HEADING_CLONE",
    "N_SCALARS",
    "POSE",
    "SCALES",
    "DivergenceWatch",
    "EKFOptions",
    "EncoderCounts",
    "FilterModel",
    "FilterReset",
    "FilterStats",
    "GatedUpdates",
    "ModelEKF",
    "ResetCause",
    "ScaleBound",
    "UpdateKind",
    "UpdateReason",
    "UpdateRecord",
    "VelocityModelEKF",
    "check_counter_bits",
    "clone_heading",
    "discrepancy",
    "encoder_jacobian",
    "encoder_measurement",
    "encoder_speeds",
    "gyro_cov",
    "gyro_jacobian",
    "gyro_measurement",
    "heading_quantization_var",
    "initial_covariance",
    "initial_state",
    "innovation_covariance",
    "joseph_covariance",
    "kalman_gain",
    "kernel_array",
    "landmark_jacobian",
    "landmark_measurement",
    "landmark_residual",
    "landmark_terms",
    "pose_jacobian",
    "pose_measurement",
    "pose_residual",
    "predict_kernel",
    "predict_step",
    "predict_terms",
    "predict_terms_kernel",
    "process_noise",
    "propagate_covariance",
    "reset_scales",
    "rest_cov",
    "rest_jacobian",
    "rest_measurement",
    "scale_statistic",
    "selector_update_kernel",
    "span_verdict",
    "state_mean",
    "state_residual",
    "state_transition",
    "transition_jacobian",
    "widen_pose",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "fusion.ekf.ekf_options": ("EKFOptions",),
        "fusion.ekf.encoder_counts": (
            "EncoderCounts",
            "check_counter_bits",
        ),
        "fusion.ekf.functions": (
            "FilterModel",
            "GYRO_BIAS",
            "HEADING_CLONE",
            "POSE",
            "SCALES",
            "encoder_jacobian",
            "encoder_measurement",
            "encoder_speeds",
            "initial_covariance",
            "initial_state",
            "innovation_covariance",
            "joseph_covariance",
            "kalman_gain",
            "landmark_jacobian",
            "landmark_measurement",
            "landmark_residual",
            "landmark_terms",
            "pose_jacobian",
            "pose_measurement",
            "pose_residual",
            "predict_step",
            "predict_terms",
            "process_noise",
            "propagate_covariance",
            "span_verdict",
            "state_mean",
            "state_residual",
            "state_transition",
            "transition_jacobian",
        ),
        "fusion.ekf.gyro": (
            "clone_heading",
            "gyro_cov",
            "gyro_jacobian",
            "gyro_measurement",
            "heading_quantization_var",
            "rest_cov",
            "rest_jacobian",
            "rest_measurement",
        ),
        "fusion.ekf.kernel": (
            "N_SCALARS",
            "kernel_array",
            "predict_kernel",
            "predict_terms_kernel",
            "selector_update_kernel",
        ),
        "fusion.ekf.model_ekf": ("ModelEKF",),
        "fusion.ekf.resets": (
            "DivergenceWatch",
            "FilterReset",
            "ResetCause",
            "ScaleBound",
            "discrepancy",
            "reset_scales",
            "scale_statistic",
            "widen_pose",
        ),
        "fusion.ekf.updates": (
            "FilterStats",
            "GatedUpdates",
            "UpdateKind",
            "UpdateReason",
            "UpdateRecord",
        ),
        "fusion.ekf.velocity_ekf": ("VelocityModelEKF",),
    },
    __all__,
)

if TYPE_CHECKING:
    from fusion.ekf.ekf_options import EKFOptions
    from fusion.ekf.encoder_counts import EncoderCounts, check_counter_bits
    from fusion.ekf.functions import (
        GYRO_BIAS,
        HEADING_CLONE,
        POSE,
        SCALES,
        FilterModel,
        encoder_jacobian,
        encoder_measurement,
        encoder_speeds,
        initial_covariance,
        initial_state,
        innovation_covariance,
        joseph_covariance,
        kalman_gain,
        landmark_jacobian,
        landmark_measurement,
        landmark_residual,
        landmark_terms,
        pose_jacobian,
        pose_measurement,
        pose_residual,
        predict_step,
        predict_terms,
        process_noise,
        propagate_covariance,
        span_verdict,
        state_mean,
        state_residual,
        state_transition,
        transition_jacobian,
    )
    from fusion.ekf.gyro import (
        clone_heading,
        gyro_cov,
        gyro_jacobian,
        gyro_measurement,
        heading_quantization_var,
        rest_cov,
        rest_jacobian,
        rest_measurement,
    )
    from fusion.ekf.kernel import (
        N_SCALARS,
        kernel_array,
        predict_kernel,
        predict_terms_kernel,
        selector_update_kernel,
    )
    from fusion.ekf.model_ekf import ModelEKF
    from fusion.ekf.resets import (
        DivergenceWatch,
        FilterReset,
        ResetCause,
        ScaleBound,
        discrepancy,
        reset_scales,
        scale_statistic,
        widen_pose,
    )
    from fusion.ekf.updates import FilterStats, GatedUpdates, UpdateKind, UpdateReason, UpdateRecord
    from fusion.ekf.velocity_ekf import VelocityModelEKF
