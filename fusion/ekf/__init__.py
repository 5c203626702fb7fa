"""The EKF wing: the calibrated model inside a filterpy Extended Kalman Filter.

- :class:`ModelEKF` (:mod:`fusion.ekf.model_ekf`): the filterpy subclass;
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
- :mod:`fusion.ekf.intrinsics_estimate`: the odometry intrinsics the scale errors
  imply (:class:`IntrinsicsEstimate`, from :meth:`ModelEKF.intrinsics_estimate`).
"""

from fusion.ekf.functions import FilterModel
from fusion.ekf.intrinsics_estimate import IntrinsicsEstimate
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.resets import FilterReset
from fusion.ekf.updates import FilterStats, UpdateRecord
from fusion.ekf.velocity_ekf import VelocityModelEKF

__all__ = ["FilterModel", "FilterReset", "FilterStats", "IntrinsicsEstimate", "ModelEKF",
           "UpdateRecord", "VelocityModelEKF"]
