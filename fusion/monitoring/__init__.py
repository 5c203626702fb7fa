"""The monitoring wing: residual tests on the filter's innovations, alarms, recalibration.

- :mod:`fusion.monitoring.residual`: :class:`ResidualMonitor`, the hub (per-sample
  gate, glitch bursts, windowed NIS, CUSUM, stuck encoder) and the alarm type;
- :mod:`fusion.monitoring.cusum`: CUSUM run lengths and thresholds;
- :mod:`fusion.monitoring.dynamics` (with ``dynamics_null`` and ``dynamics_start``):
  dynamics-change tests on integrated encoder residuals;
- :mod:`fusion.monitoring.change_time`: the posterior change time (with its
  interval) that dates a dynamics alarm;
- :mod:`fusion.monitoring.wheel_check`: a flat encoder count called a stalled wheel
  or a stuck encoder from the motor currents;
- :mod:`fusion.monitoring.scale` (with ``scale_odometry``): the landmark scale test
  (a floor: ``scale_changed``; one wheel's diameter: ``wheel_drift``);
- :mod:`fusion.monitoring.recalibration`, :mod:`fusion.monitoring.rescale`: the
  policy that answers alarms (its options: :class:`RecalibrationOptions`,
  :mod:`fusion.monitoring.recalibration_options`);
- :mod:`fusion.monitoring.phase_one`: the dynamics null and the encoder gate fitted
  on nominal drives;
- :mod:`fusion.monitoring.monitored_filter`: :class:`MonitoredFilter`, the model EKF
  and the monitor as one object with one call per frame.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "KAPPA",
    "KV",
    "KW",
    "MIN_START_INFORMATION",
    "N_STATE",
    "START_THRESHOLD",
    "START_WINDOWS",
    "AlarmEvent",
    "AlarmKind",
    "ChangeTime",
    "ChangeTimeRule",
    "ChangeTimeTracker",
    "DynamicsAlarm",
    "DynamicsMonitor",
    "DynamicsNull",
    "FrameResult",
    "MonitorOptions",
    "MonitoredFilter",
    "NominalFit",
    "RecalibrationAction",
    "RecalibrationOptions",
    "RecalibrationRecord",
    "Recalibrator",
    "ResidualMonitor",
    "ScaleAlarm",
    "ScaleMonitor",
    "ScaleOptions",
    "StartNull",
    "StartTracker",
    "Thresholds",
    "WheelCheck",
    "WheelCheckOptions",
    "WheelVerdict",
    "WindowIntegrator",
    "WindowResiduals",
    "WindowStatistics",
    "change_time_posterior",
    "cusum_arl",
    "cusum_llr_threshold",
    "cusum_threshold",
    "design_thresholds",
    "drive_start_anchors",
    "encoder_nis",
    "fit_dynamics_null",
    "fit_nominal",
    "fit_start_null",
    "integrated_residuals",
    "lag_cusum_threshold",
    "landmark_update",
    "landmark_update_compiled",
    "odometry_predict",
    "odometry_predict_into",
    "one_step_innovations",
    "output_scaling",
    "range_bearing_batch",
    "rescaled_model",
    "start_cusum_maxima",
    "start_evidence",
    "start_scores",
    "start_threshold_from_maxima",
    "whiten",
    "window_statistics",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "fusion.monitoring.change_time": (
            "ChangeTime",
            "ChangeTimeRule",
            "ChangeTimeTracker",
            "change_time_posterior",
        ),
        "fusion.monitoring.cusum": (
            "cusum_arl",
            "cusum_llr_threshold",
            "cusum_threshold",
            "lag_cusum_threshold",
        ),
        "fusion.monitoring.dynamics": (
            "DynamicsAlarm",
            "DynamicsMonitor",
            "START_THRESHOLD",
            "start_scores",
        ),
        "fusion.monitoring.dynamics_null": (
            "DynamicsNull",
            "WindowIntegrator",
            "WindowResiduals",
            "WindowStatistics",
            "fit_dynamics_null",
            "integrated_residuals",
            "window_statistics",
        ),
        "fusion.monitoring.dynamics_start": (
            "MIN_START_INFORMATION",
            "START_WINDOWS",
            "StartNull",
            "StartTracker",
            "drive_start_anchors",
            "fit_start_null",
            "start_cusum_maxima",
            "start_evidence",
            "start_threshold_from_maxima",
        ),
        "fusion.monitoring.monitored_filter": (
            "FrameResult",
            "MonitoredFilter",
        ),
        "fusion.monitoring.phase_one": (
            "NominalFit",
            "encoder_nis",
            "fit_nominal",
        ),
        "fusion.monitoring.recalibration": (
            "RecalibrationAction",
            "RecalibrationRecord",
            "Recalibrator",
        ),
        "fusion.monitoring.recalibration_options": ("RecalibrationOptions",),
        "fusion.monitoring.rescale": (
            "output_scaling",
            "rescaled_model",
        ),
        "fusion.monitoring.residual": (
            "AlarmEvent",
            "AlarmKind",
            "MonitorOptions",
            "ResidualMonitor",
            "Thresholds",
            "design_thresholds",
            "one_step_innovations",
            "whiten",
        ),
        "fusion.monitoring.scale": (
            "ScaleAlarm",
            "ScaleMonitor",
            "ScaleOptions",
        ),
        "fusion.monitoring.scale_odometry": (
            "KAPPA",
            "KV",
            "KW",
            "N_STATE",
            "landmark_update",
            "landmark_update_compiled",
            "odometry_predict",
            "odometry_predict_into",
            "range_bearing_batch",
        ),
        "fusion.monitoring.wheel_check": (
            "WheelCheck",
            "WheelCheckOptions",
            "WheelVerdict",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from fusion.monitoring.change_time import (
        ChangeTime,
        ChangeTimeRule,
        ChangeTimeTracker,
        change_time_posterior,
    )
    from fusion.monitoring.cusum import (
        cusum_arl,
        cusum_llr_threshold,
        cusum_threshold,
        lag_cusum_threshold,
    )
    from fusion.monitoring.dynamics import (
        START_THRESHOLD,
        DynamicsAlarm,
        DynamicsMonitor,
        start_scores,
    )
    from fusion.monitoring.dynamics_null import (
        DynamicsNull,
        WindowIntegrator,
        WindowResiduals,
        WindowStatistics,
        fit_dynamics_null,
        integrated_residuals,
        window_statistics,
    )
    from fusion.monitoring.dynamics_start import (
        MIN_START_INFORMATION,
        START_WINDOWS,
        StartNull,
        StartTracker,
        drive_start_anchors,
        fit_start_null,
        start_cusum_maxima,
        start_evidence,
        start_threshold_from_maxima,
    )
    from fusion.monitoring.monitored_filter import FrameResult, MonitoredFilter
    from fusion.monitoring.phase_one import NominalFit, encoder_nis, fit_nominal
    from fusion.monitoring.recalibration import (
        RecalibrationAction,
        RecalibrationRecord,
        Recalibrator,
    )
    from fusion.monitoring.recalibration_options import RecalibrationOptions
    from fusion.monitoring.rescale import output_scaling, rescaled_model
    from fusion.monitoring.residual import (
        AlarmEvent,
        AlarmKind,
        MonitorOptions,
        ResidualMonitor,
        Thresholds,
        design_thresholds,
        one_step_innovations,
        whiten,
    )
    from fusion.monitoring.scale import ScaleAlarm, ScaleMonitor, ScaleOptions
    from fusion.monitoring.scale_odometry import (
        KAPPA,
        KV,
        KW,
        N_STATE,
        landmark_update,
        landmark_update_compiled,
        odometry_predict,
        odometry_predict_into,
        range_bearing_batch,
    )
    from fusion.monitoring.wheel_check import WheelCheck, WheelCheckOptions, WheelVerdict
