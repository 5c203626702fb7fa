"""Estimators that use a calibrated motion model: filterpy EKF, GTSAM factors, monitoring."""

__all__: list[str] = []
