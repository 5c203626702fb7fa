"""Estimators that use a calibrated motion model: the filterpy EKF plug-in, GTSAM
preintegrated factors and an iSAM2 smoother, ArUco landmarks, residual monitoring."""

from fusion.aruco import MarkerDetector, MarkerObservation
from fusion.dynamics_monitor import DynamicsMonitor, DynamicsNull, fit_dynamics_null
from fusion.ekf import ModelEKF, UpdateRecord
from fusion.landmarks import LandmarkMap, LandmarkNoise
from fusion.monitor import AlarmEvent, ResidualMonitor
from fusion.preintegration import preintegrate, preintegrate_model
from fusion.scale_monitor import ScaleMonitor, ScaleOptions
from fusion.smoother import IncrementalSmoother, SmootherOptions
from fusion.velocity_ekf import VelocityModelEKF

__all__ = [
    "AlarmEvent",
    "DynamicsMonitor",
    "DynamicsNull",
    "IncrementalSmoother",
    "LandmarkMap",
    "LandmarkNoise",
    "MarkerDetector",
    "MarkerObservation",
    "ModelEKF",
    "ResidualMonitor",
    "ScaleMonitor",
    "ScaleOptions",
    "SmootherOptions",
    "UpdateRecord",
    "VelocityModelEKF",
    "fit_dynamics_null",
    "preintegrate",
    "preintegrate_model",
]
