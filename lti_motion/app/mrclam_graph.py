"""MRCLAM through the factor graph: landmark smoothing with ARX-model or raw-command motion.

Per robot, on the second half of its run (never used for fitting), two GTSAM
graphs get the same barcode sightings as range-bearing factors
(:func:`fusion.graph.range_bearing_factors`) to the surveyed landmarks, with
the same noise and the same robust kernel, and differ only in their motion
factors (:func:`fusion.graph.preintegrate`, one between-factor per
0.1 s grid step):

- ``"model"``: the speeds the ARX model of the first half predicts from the
  commands alone (free run, :func:`fusion.graph.preintegrate_model`;
  the MRCLAM robots report no encoders), its state set by the first
  :data:`~lti_motion.app.mrclam.WARMUP_S` of each segment as the EKF's is;
- ``"raw"``: the commands taken at face value.

Each motion's per-sample speed covariance is *measured the same way* on the
first half (:func:`~lti_motion.app.mrclam_noise.speed_covariances`, which
the landmark EKFs use too): the Newey-West long-run covariance
(:func:`fusion.graph.long_run_covariance`, 5 s bandwidth) of the speeds
differentiated from Vicon minus the predicted speeds (the model's free run, or
the commands), so that ``N Phi`` covers the error of ``N`` summed samples,
drift included (:mod:`fusion.graph.preintegration`, notes). The sighting noise is
that of the landmark EKFs (:func:`~lti_motion.app.mrclam_filters.
landmark_noise_from_truth`), and the kernel is a Huber one whose threshold is
the EKFs' 0.999 chi-square gate on two degrees of freedom (:data:`HUBER_K`).

Each segment's graph starts from the true pose after the warm-up, with the
EKFs' prior (:data:`~lti_motion.app.mrclam_filters.POSE_STD`). The
figure is the RMS position error against Vicon at every grid time after the
start, the same times the EKFs are scored at: of the batch
Levenberg-Marquardt solution (:func:`fusion.graph.smooth_batch`, every
sighting of the segment, past and future, informs each pose), and on request
of iSAM2 (:class:`fusion.graph.IncrementalSmoother`): its final estimate,
and its *online* one (each pose read right after its own update, causal like
the EKFs). Dead reckoning through the same motion factors is the baseline.

Run it: ``python -m lti_motion.app.mrclam_graph PATH [--incremental]``.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.stats

from drivers.datasets import (
    CREATE1_WHEEL_BASE_M,
    MrclamRobot,
    MrclamSegment,
    load_mrclam,
    resample_robot,
)
from fusion.graph import (
    IncrementalSmoother,
    Preintegrated,
    SmootherOptions,
    compose_motions,
    preintegrate,
    smooth_batch,
)
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing
from lti_motion.app.mrclam import WARMUP_S, split_halves
from lti_motion.app.mrclam_filters import (
    GATE_PROBABILITY,
    POSE_STD,
    landmark_noise_from_truth,
    sightings_in,
)
from lti_motion.app.mrclam_noise import VARIANTS, predicted_speeds, speed_covariances
from lti_motion.kinematics import wheel_from_body
from lti_motion.model import MotionModel, fit_arx

__all__ = ["GATE_PROBABILITY", "HUBER_K", "GraphResult", "evaluate_graph", "main",
           "speed_covariances"]

_log = logging.getLogger(__name__)

#: Huber threshold [whitened sigmas]: the EKFs' gate as a distance, sqrt(chi2_2(0.999)) = 3.72.
HUBER_K = float(np.sqrt(scipy.stats.chi2.ppf(GATE_PROBABILITY, df=2)))

@dataclass(frozen=True)
class GraphResult:
    """One robot's factor-graph figures on the second half.

    Attributes
    ----------
    robot : int
    rms_m : dict of str to float
        RMS position error [m] of the batch (Levenberg-Marquardt) smoother,
        ``"model"`` and ``"raw"``.
    rms_isam2_m, rms_online_m : dict of str to float, or None
        The same for iSAM2's final estimate and its online (causal) one;
        ``None`` unless run with ``incremental=True``.
    rms_dead_reckoning_m : dict of str to float
        RMS position error [m] of the motion factors chained from the start pose alone.
    n_sightings : int
        Range-bearing factors per variant (all sightings after each warm-up).
    noise : LandmarkNoise
        The measured sighting noise both graphs used.
    speed_cov : dict of str to ndarray, shape (2, 2)
        Per-sample long-run speed covariance [(m/s)^2, (rad/s)^2] of each motion.
    seconds : float
        Wall time of the smoothing [s].
    """

    robot: int
    rms_m: dict[str, float]
    rms_isam2_m: dict[str, float] | None
    rms_online_m: dict[str, float] | None
    rms_dead_reckoning_m: dict[str, float]
    n_sightings: int
    noise: LandmarkNoise
    speed_cov: dict[str, np.ndarray]
    seconds: float


def _observations(robot: MrclamRobot, seg: MrclamSegment, warmup: int) -> RangeBearing:
    """Sightings with ``t_(k-1) < t <= t_k`` on keyframe ``k - warmup``, for ``k > warmup``.

    The landmark EKFs fuse the same sightings at the same grid steps
    (:func:`~lti_motion.app.mrclam_filters.sightings_in`), with the same noise (the
    graph's ``options.landmark_noise``).
    """
    obs = sightings_in(robot, seg)
    after = obs.select(obs.index > warmup)
    return after.with_index(after.index - warmup)


def _rms(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Squared position errors [m^2] of keyframes 1.. (keyframe 0 is the given start)."""
    return np.sum((est[1:, :2] - truth[1:, :2]) ** 2, axis=1)


def _incremental(pre: Preintegrated, obs: RangeBearing, pose0: np.ndarray,
                 options: SmootherOptions, lmap: LandmarkMap) -> tuple[np.ndarray, np.ndarray]:
    """iSAM2 over one segment, one update per keyframe: (final poses, online poses)."""
    sm = IncrementalSmoother(initial_pose=pose0, options=options, landmarks=lmap)
    order = np.argsort(obs.index, kind="stable")
    obs = obs.select(order)
    bounds = np.searchsorted(obs.index, np.arange(len(pre) + 2))
    online = np.empty((len(pre) + 1, 3))
    online[0] = pose0
    for k in range(1, len(pre) + 1):
        sm.add_motion(pre[k - 1])
        if bounds[k + 1] > bounds[k]:
            sm.add_observations(obs.select(slice(bounds[k], bounds[k + 1])))
        sm.update()
        online[k] = sm.pose(k)
    return sm.result(covariances=False).poses, online


def evaluate_graph(robot: MrclamRobot, landmarks: dict[int, np.ndarray], arx: MotionModel, *,
                   dt_s: float = 0.1, incremental: bool = False,
                   huber_k: float | None = HUBER_K) -> GraphResult:
    """Smooth the second half of one robot with both motions (module docstring).

    Parameters
    ----------
    robot : MrclamRobot
    landmarks : dict of int to ndarray
        Subject -> (x [m], y [m], ...), as :func:`drivers.datasets.load_mrclam` gives.
    arx : MotionModel
        The ARX model calibrated on the first half
        (:func:`lti_motion.app.mrclam.evaluate_robot`).
    dt_s : float
        Grid step [s]; must be the model's.
    incremental : bool
        Also run iSAM2 (final and online estimates); 3-6x the batch's time.
    huber_k : float or None
        Huber threshold of the range-bearing factors [whitened sigmas]
        (:data:`HUBER_K`); ``None`` for plain Gaussian factors.

    Returns
    -------
    GraphResult

    Raises
    ------
    ValueError
        If ``dt_s`` is not the model's sample period, or a sighting names a
        landmark ``landmarks`` does not hold.
    """
    if not np.isclose(dt_s, arx.dt_s, rtol=1e-9, atol=0.0):
        raise ValueError(f"dt_s = {dt_s} s but the model was calibrated at {arx.dt_s} s; "
                         "resample at the model's period")
    unknown = set(np.unique(robot.sightings[:, 1]).astype(int).tolist()) - set(landmarks)
    if unknown:
        raise ValueError(f"robot {robot.robot} sights landmarks {sorted(unknown)} that the map "
                         f"({sorted(landmarks)}) does not hold")
    start = time.perf_counter()
    warmup = round(WARMUP_S / dt_s)
    train, test = split_halves(resample_robot(robot, dt_s=dt_s), min_samples=2 * warmup)
    noise = landmark_noise_from_truth(robot, train, landmarks)
    covs = speed_covariances(arx, train, warmup=warmup)
    lmap = LandmarkMap({lid: xy[:2] for lid, xy in landmarks.items()})
    options = SmootherOptions(initial_pose_sigmas=POSE_STD, calibrate=False,
                              landmark_huber_k=huber_k, landmark_noise=noise)
    sq: dict[str, dict[str, list[np.ndarray]]] = {
        kind: {name: [] for name in VARIANTS} for kind in ("batch", "isam2", "online", "dr")}
    n_obs = 0
    for seg in test:
        truth = seg.pose[warmup:]
        obs = _observations(robot, seg, warmup)
        n_obs += len(obs)
        keyframes = np.arange(len(truth))          # one keyframe per grid time
        for name, speeds in predicted_speeds(arx, seg, warmup).items():
            pre = preintegrate(speeds[:-1], dt_s, keyframes=keyframes, speed_covariance=covs[name])
            res = smooth_batch(pre, initial_pose=truth[0], observations=obs, landmarks=lmap,
                               options=options, covariances=False)
            sq["batch"][name].append(_rms(res.poses, truth))
            sq["dr"][name].append(_rms(compose_motions(pre.delta_pose, initial_pose=truth[0]),
                                       truth))
            if incremental:
                final, online = _incremental(pre, obs, truth[0], options, lmap)
                sq["isam2"][name].append(_rms(final, truth))
                sq["online"][name].append(_rms(online, truth))
    rms = {kind: {name: float(np.sqrt(np.mean(np.concatenate(v)))) for name, v in d.items()}
           for kind, d in sq.items() if all(d.values())}
    _log.info("robot %d: graph RMS model %.3f m, raw %.3f m", robot.robot,
             rms["batch"]["model"], rms["batch"]["raw"])
    return GraphResult(robot=robot.robot, rms_m=rms["batch"], rms_isam2_m=rms.get("isam2"),
                       rms_online_m=rms.get("online"), rms_dead_reckoning_m=rms["dr"],
                       n_sightings=n_obs, noise=noise, speed_cov=covs,
                       seconds=time.perf_counter() - start)


def main(argv: Sequence[str] | None = None) -> None:
    """Print the factor-graph table of docs/mrclam.md for an MRCLAM folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path", help="MRCLAM data set folder, e.g. .../MRCLAM_Dataset6")
    parser.add_argument("--incremental", action="store_true",
                        help="also run iSAM2 (final and online estimates)")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    args = parser.parse_args(argv)
    dataset = load_mrclam(args.path)
    print("robot | batch model / raw [m] | ratio | iSAM2 final model / raw | "
          "iSAM2 online model / raw | dead reckoning model / raw | sightings | s")
    for r in args.robots:
        robot = dataset.robots[r]
        train, _ = split_halves(resample_robot(robot, dt_s=0.1),
                                min_samples=2 * round(WARMUP_S / 0.1))
        runs = [(wheel_from_body(s.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M), s.speeds_vw)
                for s in train]
        arx = fit_arx(runs, dt_s=0.1, wheel_base_m=CREATE1_WHEEL_BASE_M)
        g = evaluate_graph(robot, dataset.landmarks, arx, incremental=args.incremental)

        def pair(d: dict[str, float] | None) -> str:
            return "-" if d is None else f"{d['model']:.3f} / {d['raw']:.3f}"

        print(f"{r} | {pair(g.rms_m)} | {g.rms_m['model'] / g.rms_m['raw']:.2f} | "
              f"{pair(g.rms_isam2_m)} | {pair(g.rms_online_m)} | "
              f"{pair(g.rms_dead_reckoning_m)} | {g.n_sightings} | {g.seconds:.1f}")


if __name__ == "__main__":
    main()
