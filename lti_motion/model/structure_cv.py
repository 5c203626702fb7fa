"""Structure selection by cross-validated error of the integrated motion.

The ARX order and delay of :func:`~lti_motion.model.select_arx` are chosen by the
free-run *speed* fit on a held-out tail. What sensor-less dead reckoning needs
is the *path*: this module scores each candidate structure (orders, delay, FIR
length, fit criterion, affine offset) by K-fold cross-validation over
contiguous blocks of time (Ljung 1999, section 16.4, "cross-validation"; blocks,
not samples, because the errors are correlated in time): the model is fitted
on the other blocks and, on the held-out block, the measured and the predicted
speeds are each integrated (paper eq. 11) over consecutive windows of
``horizon_s`` from a common pose; the score is the median end-of-window
position difference [m].

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import CalibrationError
from lti_motion.kinematics import body_from_wheel_matrix, integrate_poses
from lti_motion.model.arx import estimate_arx
from lti_motion.model.excitation import check_runs
from lti_motion.model.motion_model import MotionModel
from lti_motion.model.output_error import OutputErrorOptions, refine_output_error

__all__ = ["Candidate", "StructureScore", "cv_blocks", "fit_candidate", "score_structures"]

_log = logging.getLogger(__name__)

Runs = Sequence[tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Candidate:
    """One model structure and fit criterion.

    Attributes
    ----------
    na, nb, delay : int
        ARX orders and input delay (``na = 0``: FIR of ``nb`` taps).
    output_error : OutputErrorOptions or None
        ``None``: least squares on the equation error; else the output-error
        refinement with these settings (its ``offset`` flag included).
    commands : bool
        Nothing fitted: the body speeds are the commands at face value,
        ``y[n] = M u[n - delay]`` (``M`` the wheel-to-body matrix); ``na`` must
        be 0 and ``nb`` 1. The reference every fitted structure must beat.
    """

    na: int
    nb: int
    delay: int
    output_error: OutputErrorOptions | None = None
    commands: bool = False

    def __post_init__(self) -> None:
        if self.commands and (self.na, self.nb, self.output_error) != (0, 1, None):
            raise ValueError("a commands-at-face-value candidate has na=0, nb=1 and no fit")

    @property
    def label(self) -> str:
        """Short name, e.g. ``"arx(2,2,1)+oe+c"``."""
        oe = self.output_error
        tail = "" if oe is None else "+oe" + ("+c" if oe.offset else "")
        if self.commands:
            return f"commands(delay {self.delay})"
        kind = "fir" if self.na == 0 else "arx"
        return f"{kind}({self.na},{self.nb},{self.delay}){tail}"


@dataclass(frozen=True)
class StructureScore:
    """A candidate's cross-validated score.

    Attributes
    ----------
    candidate : Candidate
    median_end_error_m : float
        Median end-of-window position difference over all held-out windows [m]
        (``inf`` if a fold could not be fitted).
    n_windows : int
    """

    candidate: Candidate
    median_end_error_m: float
    n_windows: int


def cv_blocks(runs: Runs, n_folds: int) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """Cut the runs (in time order) into ``n_folds`` contiguous blocks of near-equal length."""
    runs = check_runs(runs)
    total = sum(len(u) for u, _ in runs)
    edges = np.linspace(0, total, n_folds + 1).round().astype(int)
    out: list[list] = [[] for _ in range(n_folds)]
    offset = 0
    for u, y in runs:
        for k in range(n_folds):
            lo, hi = max(edges[k] - offset, 0), min(edges[k + 1] - offset, len(u))
            if hi - lo > 0:
                out[k].append((u[lo:hi], y[lo:hi]))
        offset += len(u)
    return out


def fit_candidate(c: Candidate, runs: Runs, *, dt_s: float, wheel_base_m: float,
                  warmup: int) -> MotionModel:
    """Fit one candidate on ``runs``: least squares, then the output-error refinement if set.

    Returns
    -------
    MotionModel
        ``kind="arx"`` (``na = 0`` for an FIR), ``offset_speeds`` as fitted
        (zeros without the offset term).
    """
    fit = estimate_arx(runs, na=c.na, nb=c.nb, delay=c.delay)
    offset = np.zeros(2)
    if c.commands:
        m = body_from_wheel_matrix(wheel_base_m)
        e = np.concatenate([y[c.delay:] - u[:len(u) - c.delay] @ m.T for u, y in runs])
        fit = dataclasses.replace(fit, b=m[None], residual_cov=np.cov(e.T, bias=True))
    elif c.output_error is not None:
        oe = refine_output_error(fit, runs, dt_s=dt_s, warmup=warmup, options=c.output_error)
        fit, offset = oe.fit, oe.offset_speeds
    model = MotionModel.from_arx(fit, dt_s=dt_s, wheel_base_m=wheel_base_m,
                                 calibrated_at="1970-01-01T00:00:00+00:00")
    return model.updated(offset_speeds=offset)


def _end_errors(model: MotionModel, runs: Runs, *, warmup: int, window: int) -> list[float]:
    out = []
    for u, y in runs:
        if len(u) < warmup + window:
            continue
        z0 = model.state_from_data(u[:warmup], y[:warmup])
        pred = model.simulate(u[warmup:], z0=z0)
        for k0 in range(0, len(pred) - window + 1, window):
            a = integrate_poses(y[warmup + k0:warmup + k0 + window], model.dt_s)[-1, :2]
            b = integrate_poses(pred[k0:k0 + window], model.dt_s)[-1, :2]
            out.append(float(np.hypot(*(a - b))))
    return out


def score_structures(runs: Runs, candidates: Sequence[Candidate], *, dt_s: float,
                     wheel_base_m: float, warmup: int, horizon_s: float = 30.0,
                     n_folds: int = 3) -> list[StructureScore]:
    """Cross-validated integrated-motion score of each candidate (module notes).

    Parameters
    ----------
    runs : sequence of (u, y)
        Calibration data in time order: commands (n_i, 2) [m/s], measured body
        speeds (n_i, 2) [m/s, rad/s].
    candidates : sequence of Candidate
    dt_s, wheel_base_m : float
        Sample period [s] and wheel base [m].
    warmup : int
        Samples at the start of each held-out run that set the model's state.
    horizon_s : float
        Window of the integrated paths [s].
    n_folds : int
        Contiguous blocks of time (at least 2).

    Returns
    -------
    list of StructureScore
        In the order of ``candidates``; pick the lowest ``median_end_error_m``.

    Raises
    ------
    CalibrationError
        If the held-out blocks hold no complete window.
    """
    if int(n_folds) < 2:
        raise ValueError(f"n_folds must be at least 2, got {n_folds}")
    blocks = cv_blocks(runs, int(n_folds))
    window = round(horizon_s / dt_s)
    scores = []
    for c in candidates:
        errors: list[float] = []
        failed = False
        for k, held in enumerate(blocks):
            train = [r for j, b in enumerate(blocks) if j != k for r in b]
            try:
                model = fit_candidate(c, train, dt_s=dt_s, wheel_base_m=wheel_base_m, warmup=warmup)
            except CalibrationError as exc:
                _log.info("candidate %s fails on fold %d: %s", c.label, k, exc)
                failed = True
                break
            errors += _end_errors(model, held, warmup=warmup, window=window)
        if not errors and not failed:
            raise CalibrationError(f"no held-out block holds a {horizon_s:g} s window after "
                                   f"the {warmup}-sample warm-up; record longer runs")
        score = np.inf if failed else float(np.median(errors))
        _log.info("candidate %s: median %g s end error %.4g m over %d windows", c.label,
                  horizon_s, score, len(errors))
        scores.append(StructureScore(c, score, len(errors)))
    return scores
