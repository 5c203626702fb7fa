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
"""

from fusion.graph.factors import observe_landmarks
from fusion.graph.preintegration import Preintegrated, preintegrate, preintegrate_model
from fusion.graph.smoother import (
    IncrementalSmoother,
    SmootherOptions,
    SmootherResult,
    log_keyframes,
)

__all__ = [
    "IncrementalSmoother",
    "Preintegrated",
    "SmootherOptions",
    "SmootherResult",
    "log_keyframes",
    "observe_landmarks",
    "preintegrate",
    "preintegrate_model",
]
