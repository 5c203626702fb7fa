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
  policy that answers alarms;
- :mod:`fusion.monitoring.phase_one`: the dynamics null and the encoder gate fitted
  on nominal drives;
- :mod:`fusion.monitoring.monitored_filter`: :class:`MonitoredFilter`, the model EKF
  and the monitor as one object with one call per frame.
"""

from fusion.monitoring.dynamics import DynamicsMonitor, DynamicsNull, fit_dynamics_null
from fusion.monitoring.monitored_filter import FrameResult, MonitoredFilter
from fusion.monitoring.phase_one import NominalFit, fit_nominal
from fusion.monitoring.recalibration import Recalibrator
from fusion.monitoring.residual import AlarmEvent, MonitorOptions, ResidualMonitor
from fusion.monitoring.scale import ScaleMonitor, ScaleOptions

__all__ = [
    "AlarmEvent",
    "DynamicsMonitor",
    "DynamicsNull",
    "FrameResult",
    "MonitorOptions",
    "MonitoredFilter",
    "NominalFit",
    "Recalibrator",
    "ResidualMonitor",
    "ScaleMonitor",
    "ScaleOptions",
    "fit_dynamics_null",
    "fit_nominal",
]
