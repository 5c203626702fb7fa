"""MRCLAM, filtered: landmark EKFs driven by the calibrated ARX model and by raw commands.

Per robot, on the second half of its run (never used for fitting), two filters
get the same landmark sightings (MRCLAM's barcode sightings, mapped to the
surveyed landmark positions) with the same noise settings and gate:

- ``"model"``: :class:`fusion.ekf.ModelEKF` driven by the ARX model calibrated
  on the first half (its own process noise, from the calibration);
- ``"raw"``: :class:`fusion.velocity_ekf.VelocityModelEKF`, the textbook
  velocity-model EKF on the commands taken at face value, its speed noise the
  covariance of (true speeds - commands) on the first half.

Both start each segment from the true pose (after the model's warm-up). The
landmark noise is measured on the first half: the standard deviation of the
sightings' range and bearing residuals against Vicon, outliers trimmed by the
median absolute deviation. The figure is the RMS position error against Vicon
over all grid times of the second half.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from drivers.datasets import CREATE1_WHEEL_BASE_M, MrclamRobot, MrclamSegment, resample_robot
from fusion.ekf import ModelEKF
from fusion.landmarks import LandmarkMap, LandmarkNoise, range_bearing, range_bearing_residual
from fusion.velocity_ekf import VelocityModelEKF
from lti_motion.experiments.mrclam import WARMUP_S, split_halves
from lti_motion.kinematics import wheel_from_body
from lti_motion.model import MotionModel

__all__ = ["FilterResult", "evaluate_filters", "landmark_noise_from_truth"]

log = logging.getLogger(__name__)

POSE_STD = (0.05, 0.05, 0.05)   # initial (x [m], y [m], theta [rad]) standard deviations


@dataclass(frozen=True)
class FilterResult:
    """One robot's landmark-EKF figures on the second half.

    Attributes
    ----------
    robot : int
    rms_m : dict of str to float
        RMS position error [m] of ``"model"`` and ``"raw"``.
    fused, gated : dict of str to int
        Landmark sightings fused and gated by each filter.
    noise : LandmarkNoise
        The measured sighting noise both filters used.
    """

    robot: int
    rms_m: dict[str, float]
    fused: dict[str, int]
    gated: dict[str, int]
    noise: LandmarkNoise


def _robust_std(x: np.ndarray) -> float:
    """Standard deviation from the median absolute deviation (x 1.4826, Gaussian)."""
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _sightings_in(robot: MrclamRobot, seg: MrclamSegment) -> list[list[tuple[int, np.ndarray]]]:
    """Sightings per grid step ``k``: those with ``t_(k-1) < t <= t_k``."""
    s = robot.sightings
    per: list[list[tuple[int, np.ndarray]]] = [[] for _ in seg.t_s]
    keep = (s[:, 0] > seg.t_s[0]) & (s[:, 0] <= seg.t_s[-1])
    for row in s[keep]:
        k = int(np.searchsorted(seg.t_s, row[0], side="left"))
        per[k].append((int(row[1]), row[2:4].copy()))
    return per


def landmark_noise_from_truth(robot: MrclamRobot, segments: list[MrclamSegment],
                              landmarks: dict[int, np.ndarray]) -> LandmarkNoise:
    """Sighting noise measured against Vicon on the given (training) segments."""
    res = []
    for seg in segments:
        for k, sightings in enumerate(_sightings_in(robot, seg)):
            for lid, z in sightings:
                res.append(range_bearing_residual(z, range_bearing(seg.pose[k],
                                                                   landmarks[lid][:2])))
    r = np.array(res)
    return LandmarkNoise(range_std_frac=0.0, range_std_m=_robust_std(r[:, 0]),
                         bearing_std_rad=_robust_std(r[:, 1]))


def evaluate_filters(robot: MrclamRobot, landmarks: dict[int, np.ndarray], arx: MotionModel,
                     *, dt_s: float = 0.1) -> FilterResult:
    """Run both landmark EKFs on the second half of one robot (module docstring).

    Parameters
    ----------
    robot : MrclamRobot
    landmarks : dict of int to ndarray
        Subject -> (x [m], y [m], ...), as :func:`drivers.datasets.load_mrclam` gives.
    arx : MotionModel
        The ARX model calibrated on the first half
        (:func:`lti_motion.experiments.mrclam.evaluate_robot`).
    dt_s : float
        Grid step [s]; must be the model's.
    """
    warmup = round(WARMUP_S / dt_s)
    train, test = split_halves(resample_robot(robot, dt_s=dt_s), min_samples=2 * warmup)
    noise = landmark_noise_from_truth(robot, train, landmarks)
    err = np.concatenate([s.speeds_vw - s.commands_vw for s in train])
    speed_cov = np.cov(err.T)
    lmap = LandmarkMap({lid: xy[:2] for lid, xy in landmarks.items()})
    sq = {"model": [], "raw": []}
    fused = {"model": 0, "raw": 0}
    gated = {"model": 0, "raw": 0}
    for seg in test:
        u = wheel_from_body(seg.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M)
        z0 = arx.state_from_data(u[:warmup], seg.speeds_vw[:warmup])
        model_ekf = ModelEKF(arx, initial_pose=seg.pose[warmup], pose_std=POSE_STD, z0=z0,
                             landmarks=lmap, landmark_noise=noise, history=0)
        raw_ekf = VelocityModelEKF(dt_s=dt_s, speed_cov=speed_cov, initial_pose=seg.pose[warmup],
                                   pose_std=POSE_STD, landmark_noise=noise)
        sightings = _sightings_in(robot, seg)
        for k in range(warmup + 1, len(seg.t_s)):
            model_ekf.predict(u[k - 1])
            raw_ekf.predict(seg.commands_vw[k - 1])
            for lid, z in sightings[k]:
                model_ekf.update_landmark(lid, z)
                raw_ekf.update_landmark(landmarks[lid][:2], z)
            sq["model"].append(np.sum((model_ekf.x[:2] - seg.pose[k, :2]) ** 2))
            sq["raw"].append(np.sum((raw_ekf.x[:2] - seg.pose[k, :2]) ** 2))
        fused["raw"] += raw_ekf.fused
        gated["raw"] += raw_ekf.gated
        fused["model"] += model_ekf.stats.count("landmark", "fused")
        gated["model"] += model_ekf.stats.count("landmark", "gated")
    rms = {name: float(np.sqrt(np.mean(v))) for name, v in sq.items()}
    log.info("robot %d: landmark EKF RMS model %.3f m, raw %.3f m", robot.robot,
             rms["model"], rms["raw"])
    return FilterResult(robot=robot.robot, rms_m=rms, fused=fused, gated=gated, noise=noise)
