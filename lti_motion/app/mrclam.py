"""The real-data experiment on UTIAS MRCLAM: self-calibrated models against raw commands.

Per robot: calibrate a FIR and an ARX model from the commands to the body speeds
derived from Vicon ground truth, on the first half of the run only; on the second
half, never used for fitting, compare three predictors of the motion from the
commands alone: (a) the raw commands taken at face value, (b) FIR, (c) ARX.

- Free-run fit [%] of v and of w (the model simulated from the commands alone, as
  system-identification tools report it).
- Sensor-less dead reckoning over 30 s windows, each started from the true pose:
  position and heading error at each window's end.

MRCLAM commands are body speeds (v, w); the models take wheel commands, so the
commands pass through the Create's 0.258 m wheel base, a lossless linear map.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.datasets import CREATE1_WHEEL_BASE_M, MrclamRobot, MrclamSegment, resample_robot
from lti_motion.kinematics import integrate_poses, wheel_from_body, wrap_angle
from lti_motion.metrics import fit_percent
from lti_motion.model import (
    Candidate,
    MotionModel,
    OutputErrorOptions,
    estimate_fir,
    fit_arx,
    fit_candidate,
    refine_model,
    score_structures,
)

__all__ = ["CANDIDATES", "RobotResult", "evaluate_robot", "split_halves"]

_log = logging.getLogger(__name__)

WARMUP_S = 2.0          # the start of each validation stretch only sets a model's state
WINDOW_S = 30.0


def _candidates() -> tuple[Candidate, ...]:
    oe = (OutputErrorOptions(offset=False), OutputErrorOptions(offset=True))
    out = [Candidate(0, 1, 0, commands=True)]                        # nothing fitted
    out += [Candidate(1, 1, 1), Candidate(2, 2, 1)]                 # least squares
    for opts in oe:
        out += [Candidate(0, 1, d, opts) for d in (0, 1, 2)]        # static gain, delay d
        out += [Candidate(0, 5, 0, opts), Candidate(1, 1, 1, opts)]
    return tuple(out)


#: ``criterion="selected"``: the structures scored on the first half (docs/mrclam.md rules).
CANDIDATES = _candidates()


@dataclass(frozen=True)
class RobotResult:
    """One robot's figures on the second half of its run.

    Attributes
    ----------
    robot : int
    fit : dict of str to ndarray, shape (2,)
        Free-run fit [%] of (v, w) for ``"raw"``, ``"fir"``, ``"arx"``.
    end_position_m, end_heading_rad : dict of str to ndarray
        Errors at the end of each 30 s dead-reckoning window, per predictor.
    arx : MotionModel
        The calibrated ARX model.
    n_train_s, n_test_s : float
        Seconds of data in each half.
    """

    robot: int
    fit: dict[str, np.ndarray]
    end_position_m: dict[str, np.ndarray]
    end_heading_rad: dict[str, np.ndarray]
    arx: MotionModel
    n_train_s: float
    n_test_s: float


def split_halves(segments: list[MrclamSegment], *, min_samples: int) -> tuple[list, list]:
    """Cut the robot's time span in two halves; a segment crossing the middle is split."""
    t_mid = 0.5 * (segments[0].t_s[0] + segments[-1].t_s[-1])
    first, second = [], []
    for seg in segments:
        k = int(np.searchsorted(seg.t_s, t_mid))
        parts = ((first, slice(0, k)), (second, slice(k, None)))
        for target, sl in parts:
            if seg.t_s[sl].size > min_samples:
                target.append(MrclamSegment(seg.t_s[sl], seg.commands_vw[sl], seg.pose[sl],
                                            seg.speeds_vw[sl]))
    return first, second


def _runs(segments: list[MrclamSegment]) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(wheel_from_body(s.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M), s.speeds_vw)
            for s in segments]


def _free_run(model: MotionModel | None, seg: MrclamSegment) -> np.ndarray:
    """Predicted body speeds from commands alone: the model's, or the commands themselves."""
    if model is None:
        return seg.commands_vw
    u = wheel_from_body(seg.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M)
    return model.simulate(u)


def evaluate_robot(robot: MrclamRobot, *, dt_s: float = 0.1, fir_length_s: float = 1.0,
                   criterion: Literal["equation", "output_error", "selected"] = "equation",
                   output_error: OutputErrorOptions | None = None) -> RobotResult:
    """Calibrate on the first half, evaluate on the second (module docstring).

    Parameters
    ----------
    robot : MrclamRobot
    dt_s : float
        Grid step of the resampled data [s].
    fir_length_s : float
        Length of the FIR model's impulse responses [s].
    criterion : {"equation", "output_error", "selected"}
        The ARX model's fit: least squares on the equation error (order and
        delay by held-out free-run fit); that model refined on the
        output-error criterion (:func:`lti_motion.model.refine_model`);
        or the one of :data:`CANDIDATES` with the least 3-fold cross-validated
        30 s path error on the first half
        (:func:`lti_motion.model.score_structures`), refitted on it.
    output_error : OutputErrorOptions, optional
        Settings of the output-error criterion.
    """
    if criterion not in ("equation", "output_error", "selected"):
        raise ValueError(f"criterion must be 'equation', 'output_error' or 'selected', got "
                         f"{criterion!r}")
    warmup = round(WARMUP_S / dt_s)
    segments = resample_robot(robot, dt_s=dt_s)
    train, test = split_halves(segments, min_samples=2 * warmup)
    runs = _runs(train)
    arx = fit_arx(runs, dt_s=dt_s, wheel_base_m=CREATE1_WHEEL_BASE_M)
    if criterion == "output_error":
        arx = refine_model(arx, runs, options=output_error, warmup=warmup)
    elif criterion == "selected":
        common = {"dt_s": dt_s, "wheel_base_m": CREATE1_WHEEL_BASE_M, "warmup": warmup}
        scores = score_structures(runs, CANDIDATES, horizon_s=WINDOW_S, **common)
        best = min(scores, key=lambda s: s.median_end_error_m)
        _log.info("robot %d: structure %s (first-half CV %.3f m)", robot.robot,
                  best.candidate.label, best.median_end_error_m)
        arx = fit_candidate(best.candidate, runs, **common)
    fir = MotionModel.from_fir(estimate_fir(runs, n_taps=round(fir_length_s / dt_s)),
                               dt_s=dt_s, wheel_base_m=CREATE1_WHEEL_BASE_M)
    predictors = {"raw": None, "fir": fir, "arx": arx}
    fit, end_pos, end_head = {}, {}, {}
    for name, model in predictors.items():
        preds = [_free_run(model, s) for s in test]
        y = np.concatenate([s.speeds_vw[warmup:] for s in test])
        yhat = np.concatenate([p[warmup:] for p in preds])
        fit[name] = np.asarray(fit_percent(y, yhat, axis=0))
        pos, head = [], []
        win = round(WINDOW_S / dt_s)
        for seg, pred in zip(test, preds, strict=True):
            for k0 in range(warmup, len(seg.t_s) - win, win):
                poses = integrate_poses(pred[k0:k0 + win], dt_s, initial_pose=seg.pose[k0])
                true_end = seg.pose[k0 + win]
                pos.append(np.linalg.norm(poses[-1, :2] - true_end[:2]))
                head.append(abs(float(wrap_angle(poses[-1, 2] - true_end[2]))))
        end_pos[name], end_head[name] = np.array(pos), np.array(head)
    _log.info("robot %d: fit raw %s arx %s", robot.robot, fit["raw"], fit["arx"])
    return RobotResult(robot=robot.robot, fit=fit, end_position_m=end_pos,
                       end_heading_rad=end_head, arx=arx,
                       n_train_s=sum(len(s.t_s) for s in train) * dt_s,
                       n_test_s=sum(len(s.t_s) for s in test) * dt_s)
