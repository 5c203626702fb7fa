"""MRCLAM, filtered: landmark EKFs driven by the calibrated ARX model and by raw commands.

Per robot, on the second half of its run (never used for fitting), two filters
get the same landmark sightings (MRCLAM's barcode sightings, mapped to the
surveyed landmark positions) with the same noise settings and the same 0.999
chi-square gate (:data:`GATE_PROBABILITY`):

- ``"model"``: :class:`fusion.ekf.ModelEKF` driven by the ARX model calibrated
  on the first half (free run: MRCLAM's robots report no encoders);
- ``"raw"``: :class:`fusion.ekf.VelocityModelEKF`, the textbook
  velocity-model EKF on the commands taken at face value (Thrun, Burgard & Fox
  2005, table 7.2).

**Motion noise** (``motion_noise``), one rule for both filters:

- ``"long_run"`` (default): each motion's speed error is white per 0.1 s
  sample with covariance ``Phi``, the Newey-West long-run covariance of (Vicon
  speeds - that motion's predicted speeds) on the first half
  (:func:`~lti_motion.app.mrclam_noise.speed_covariances`, 5 s
  bandwidth), as the factor graphs use it (:mod:`~lti_motion.app.
  mrclam_graph`). For white noise of covariance ``Phi`` per sample the error of
  ``N`` summed samples has covariance ``N Phi``, which is what the measured
  error's long-run covariance gives for large ``N`` (Newey & West 1987): the
  drift between sightings is counted, not just the one-step scatter. The raw
  filter takes ``Phi`` as its speed noise ``M_t`` (Thrun's table 7.2, line 5).
  The model filter takes it through the model's noise inputs
  (:func:`output_error_model`): the model's deterministic part ``(A, B, C, D)``
  unchanged, its output noise ``R = Phi`` with ``K = 0`` and ``Q`` at the jitter
  floor, so the speed state carries ``C z + D u`` plus white noise of
  covariance ``Phi`` per period, the raw filter's structure (module notes of
  :mod:`fusion.ekf.functions`: ``Q = G2 blkdiag(R, R_slip) G2^T + Q_c``). Its
  slip noise is zero and its scale-error states are held (prior 1e-9, no walk):
  both model ground against *encoder* speeds, and without encoders the
  measured ``Phi`` (not demeaned, so a scale error counts as drift) already
  holds them; leaving them on would count that error twice and give the
  model filter a self-calibration the raw filter lacks.
- ``"legacy"``: the rule before; the model filter with the model's own noise
  (its one-step ``R``, ``Q = alpha K R K^T``, default :class:`~fusion.
  ekf_functions.SlipNoise` and :class:`~fusion.ekf.functions.ScaleErrors`),
  the raw filter with the sample covariance of (true speeds - commands).
  Kept to reproduce the earlier figures (docs/mrclam.md).

Both start each segment from the true pose (after the model's warm-up). The
landmark noise is measured on the first half: the standard deviation of the
sightings' range and bearing residuals against Vicon, outliers trimmed by the
median absolute deviation. The figures are the RMS position error against
Vicon over all grid times of the second half, the mean position NEES at the
same times (2 degrees of freedom: 2 if consistent) and the mean NIS of the
fused sightings (2 if consistent, 1.99 after the gate's truncation)
from fusion.ekf.ekf_options import EKFOptions
(Bar-Shalom, Li & Kirubarajan 2001, section 5.4.2).

Run it: ``python -m lti_motion.app.mrclam_filters PATH [--motion-noise legacy]``.
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.datasets import (
    CREATE1_WHEEL_BASE_M,
    MrclamRobot,
    MrclamSegment,
    load_mrclam,
    resample_robot,
)
from fusion.ekf import EKFOptions, ModelEKF, VelocityModelEKF
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise, ScaleErrors, SlipNoise
from fusion.range_bearing import RangeBearing, range_bearing, range_bearing_residual
from lti_motion.app.mrclam import WARMUP_S, evaluate_robot, split_halves
from lti_motion.app.mrclam_noise import VARIANTS, speed_covariances
from lti_motion.kinematics import wheel_from_body
from lti_motion.model import COVARIANCE_JITTER, MotionModel

__all__ = ["GATE_PROBABILITY", "FilterResult", "MotionNoise", "evaluate_filters",
           "landmark_noise_from_truth", "main", "output_error_model", "sightings_in"]

_log = logging.getLogger(__name__)

POSE_STD = (0.05, 0.05, 0.05)   # initial (x [m], y [m], theta [rad]) standard deviations
#: Chi-square gate probability of both filters' landmark updates (2 degrees of freedom).
GATE_PROBABILITY = 0.999

MotionNoise = Literal["long_run", "legacy"]

#: ``"long_run"``: no slip noise beyond the measured ``Phi`` (module notes).
NO_SLIP = SlipNoise(v_frac=0.0, w_frac=0.0, w_per_v_rad_m=0.0, v_floor_m_s=0.0,
                    w_floor_rad_s=0.0)
#: ``"long_run"``: scale-error states held at zero (module notes).
HELD_SCALES = ScaleErrors(prior_std=(1e-9, 1e-9), walk_per_sqrt_s=(0.0, 0.0),
                          ratio_prior_std=1e-9, ratio_walk_per_sqrt_s=0.0)


@dataclass(frozen=True)
class FilterResult:
    """One robot's landmark-EKF figures on the second half.

    Attributes
    ----------
    robot : int
    motion_noise : {"long_run", "legacy"}
        The rule that set both filters' motion noise (module notes).
    rms_m : dict of str to float
        RMS position error [m] of ``"model"`` and ``"raw"``.
    nees_mean : dict of str to float
        Mean position NEES ``e^T P_xy^-1 e`` over the same grid times (2 if consistent).
    nis_mean : dict of str to float
        Mean NIS of the fused sightings (1.99 if consistent, after the gate; NaN if
        none was fused).
    fused, gated : dict of str to int
        Landmark sightings fused and gated by each filter.
    noise : LandmarkNoise
        The measured sighting noise both filters used.
    speed_cov : dict of str to ndarray, shape (2, 2)
        Per-period speed-error covariance [(m/s)^2, (rad/s)^2] each filter was
        given: ``Phi`` under ``"long_run"``; under ``"legacy"`` the sample
        covariance (raw) and the model's one-step ``R`` (model; its ``Q``, slip
        and scale states add to it).
    """

    robot: int
    motion_noise: MotionNoise
    rms_m: dict[str, float]
    nees_mean: dict[str, float]
    nis_mean: dict[str, float]
    fused: dict[str, int]
    gated: dict[str, int]
    noise: LandmarkNoise
    speed_cov: dict[str, np.ndarray]


def _robust_std(x: np.ndarray) -> float:
    """Standard deviation from the median absolute deviation (x 1.4826, Gaussian)."""
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def sightings_in(robot: MrclamRobot, seg: MrclamSegment) -> RangeBearing:
    """The robot's sightings in a segment, on grid step ``k`` (their ``index``) for
    ``t_(k-1) < t <= t_k``; without a covariance (the filters' measured noise applies)."""
    s = robot.sightings
    keep = (s[:, 0] > seg.t_s[0]) & (s[:, 0] <= seg.t_s[-1])
    return RangeBearing(np.searchsorted(seg.t_s, s[keep, 0], side="left"),
                        s[keep, 1].astype(np.int64), s[keep, 2], s[keep, 3])


def landmark_noise_from_truth(robot: MrclamRobot, segments: list[MrclamSegment],
                              landmarks: dict[int, np.ndarray]) -> LandmarkNoise:
    """Sighting noise measured against Vicon on the given (training) segments."""
    res = []
    for seg in segments:
        obs = sightings_in(robot, seg)
        for k, (lid, z, _) in zip(obs.index.tolist(), obs, strict=True):
            res.append(range_bearing_residual(z, range_bearing(seg.pose[k], landmarks[lid][:2])))
    r = np.array(res)
    return LandmarkNoise(range_std_frac=0.0, range_std_m=_robust_std(r[:, 0]),
                         bearing_std_rad=_robust_std(r[:, 1]))


def output_error_model(model: MotionModel, speed_cov: np.ndarray) -> MotionModel:
    """The model with its noise replaced by white speed noise of covariance ``speed_cov``.

    Parameters
    ----------
    model : MotionModel
        A calibrated model; its deterministic part ``(A, B, C, D)`` is kept, so
        its free-run speeds are unchanged.
    speed_cov : ndarray, shape (2, 2)
        Per-period covariance of the speed error ``(v [m/s], w [rad/s])``,
        symmetric positive definite.

    Returns
    -------
    MotionModel
        ``K = 0``, ``R = speed_cov``, ``Q = jitter I``, ``q_scale = 1``: in
        :class:`fusion.ekf.ModelEKF` the speed state is ``C z + D u + e`` with
        ``e ~ N(0, speed_cov)`` white and the model state deterministic, i.e.
        the output-error form of the model (Ljung 1999, section 4.2).

    Raises
    ------
    ValueError
        If ``speed_cov`` is not (2, 2), symmetric and positive definite.

    Examples
    --------
    >>> from lti_motion.model.fir import FirFit
    >>> model = MotionModel.from_fir(
    ...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
    ...            residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
    ...     dt_s=0.1, wheel_base_m=0.25, calibrated_at="2026-01-01T00:00:00+00:00")
    >>> oe = output_error_model(model, np.diag([4e-4, 9e-4]))
    >>> bool(np.all(oe.K == 0)), oe.R.diagonal().tolist()
    (True, [0.0004, 0.0009])
    """
    cov = np.asarray(speed_cov, dtype=float)
    if cov.shape != (2, 2):
        raise ValueError(f"speed_cov must have shape (2, 2), got {cov.shape}")
    if not (np.all(np.isfinite(cov)) and np.allclose(cov, cov.T, rtol=1e-9, atol=0.0)
            and np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() > 0):
        raise ValueError(f"speed_cov must be symmetric positive definite, got {cov.tolist()}")
    nz = model.n_states
    return model.updated(K=np.zeros((nz, 2)), R=0.5 * (cov + cov.T),
                         Q=COVARIANCE_JITTER * np.eye(nz), q_scale=1.0)


def _motion_noise(rule: MotionNoise, arx: MotionModel, train: list[MrclamSegment], warmup: int
                  ) -> tuple[dict[str, np.ndarray], MotionModel, SlipNoise | None,
                             ScaleErrors | None]:
    """Under ``rule``: the per-period speed covariances, and the model filter's model, slip
    noise and scale errors (``None``: ModelEKF's defaults)."""
    if rule == "long_run":
        cov = speed_covariances(arx, train, warmup=warmup)
        return cov, output_error_model(arx, cov["model"]), NO_SLIP, HELD_SCALES
    if rule == "legacy":
        err = np.concatenate([s.speeds_vw - s.commands_vw for s in train])
        return {"model": np.array(arx.R), "raw": np.cov(err.T)}, arx, None, None
    raise ValueError(f"motion_noise must be 'long_run' or 'legacy', got {rule!r}")


def evaluate_filters(robot: MrclamRobot, landmarks: dict[int, np.ndarray], arx: MotionModel,
                     *, dt_s: float = 0.1, motion_noise: MotionNoise = "long_run"
                     ) -> FilterResult:
    """Run both landmark EKFs on the second half of one robot (module docstring).

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
    motion_noise : {"long_run", "legacy"}
        The one rule that sets both filters' motion noise (module notes).

    Returns
    -------
    FilterResult

    Raises
    ------
    ValueError
        If ``dt_s`` is not the model's sample period or ``motion_noise`` is unknown.
    """
    if not np.isclose(dt_s, arx.dt_s, rtol=1e-9, atol=0.0):
        raise ValueError(f"dt_s = {dt_s} s but the model was calibrated at {arx.dt_s} s; "
                         "resample at the model's period")
    warmup = round(WARMUP_S / dt_s)
    train, test = split_halves(resample_robot(robot, dt_s=dt_s), min_samples=2 * warmup)
    noise = landmark_noise_from_truth(robot, train, landmarks)
    speed_cov, model, slip, scales = _motion_noise(motion_noise, arx, train, warmup)
    lmap = LandmarkMap({lid: xy[:2] for lid, xy in landmarks.items()})
    sq: dict[str, list[float]] = {name: [] for name in VARIANTS}
    nees: dict[str, list[float]] = {name: [] for name in VARIANTS}
    nis: dict[str, list[float]] = {name: [] for name in VARIANTS}
    gated = {name: 0 for name in VARIANTS}
    for seg in test:
        u = wheel_from_body(seg.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M)
        z0 = arx.state_from_data(u[:warmup], seg.speeds_vw[:warmup])
        model_ekf = ModelEKF(model, initial_pose=seg.pose[warmup], pose_std=POSE_STD, z0=z0,
                             landmarks=lmap,
                             options=EKFOptions(landmark_noise=noise, slip=slip, scales=scales,
                                                gate_probability=GATE_PROBABILITY, history=0))
        raw_ekf = VelocityModelEKF(dt_s=dt_s, speed_cov=speed_cov["raw"],
                                   initial_pose=seg.pose[warmup], pose_std=POSE_STD,
                                   landmarks=lmap, landmark_noise=noise,
                                   gate_probability=GATE_PROBABILITY, history=0)
        filters = {"model": model_ekf, "raw": raw_ekf}
        sightings = sightings_in(robot, seg).by_index()
        none = RangeBearing.empty()
        for k in range(warmup + 1, len(seg.t_s)):
            model_ekf.predict(u[k - 1])
            raw_ekf.predict(seg.commands_vw[k - 1])
            for name, ekf in filters.items():
                nis[name] += [rec.nis for rec in ekf.update_landmarks(sightings.get(k, none))
                              if rec.accepted]
                e = ekf.x[:2] - seg.pose[k, :2]
                sq[name].append(float(e @ e))
                # position NEES (Bar-Shalom et al. 2001, section 5.4.2)
                nees[name].append(float(e @ np.linalg.solve(ekf.P[:2, :2], e)))
        for name, ekf in filters.items():
            gated[name] += ekf.stats.count("landmark", "gated")
    rms = {name: float(np.sqrt(np.mean(v))) for name, v in sq.items()}
    _log.info("robot %d (%s): landmark EKF RMS model %.3f m, raw %.3f m", robot.robot,
             motion_noise, rms["model"], rms["raw"])
    return FilterResult(robot=robot.robot, motion_noise=motion_noise, rms_m=rms,
                        nees_mean={n: float(np.mean(v)) for n, v in nees.items()},
                        nis_mean={n: float(np.mean(v)) if v else math.nan
                                  for n, v in nis.items()},
                        fused={n: len(v) for n, v in nis.items()}, gated=gated, noise=noise,
                        speed_cov=speed_cov)


def main(argv: Sequence[str] | None = None) -> None:
    """Print the landmark-EKF table of docs/mrclam.md for an MRCLAM folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path", help="MRCLAM data set folder, e.g. .../MRCLAM_Dataset6")
    parser.add_argument("--motion-noise", choices=("long_run", "legacy"), default="long_run",
                        help="the rule that sets both filters' motion noise (default long_run)")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    args = parser.parse_args(argv)
    dataset = load_mrclam(args.path)
    print(f"motion noise: {args.motion_noise}")
    print("robot | RMS model / raw [m] | ratio | NEES model / raw | NIS model / raw | "
          "fused model / raw | speed std model / raw (v [m/s], w [rad/s])")
    for r in args.robots:
        robot = dataset.robots[r]
        f = evaluate_filters(robot, dataset.landmarks, evaluate_robot(robot).arx,
                             motion_noise=args.motion_noise)
        std = {n: np.sqrt(np.diag(c)) for n, c in f.speed_cov.items()}
        print(f"{r} | {f.rms_m['model']:.3f} / {f.rms_m['raw']:.3f} | "
              f"{f.rms_m['model'] / f.rms_m['raw']:.2f} | "
              f"{f.nees_mean['model']:.1f} / {f.nees_mean['raw']:.1f} | "
              f"{f.nis_mean['model']:.2f} / {f.nis_mean['raw']:.2f} | "
              f"{f.fused['model']} / {f.fused['raw']} | "
              f"{std['model'][0]:.3f}, {std['model'][1]:.3f} / "
              f"{std['raw'][0]:.3f}, {std['raw'][1]:.3f}")


if __name__ == "__main__":
    main()
