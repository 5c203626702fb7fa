"""Output-error refinement of ARX and FIR fits: fit the motion, not the next sample.

Least squares on the ARX equation error (paper eq. 12) minimises the *one-step*
prediction error, which uses the measured past speeds. A sensor-less
prediction never sees them: its error is the *simulation* (output) error, and
what dead reckoning integrates is that error's slow part. This module refines a
least-squares fit by the prediction-error method with the output-error
predictor (Ljung 1999, section 7.2 with the output-error model structure of
section 4.2): the parameters ``theta = (A_1..A_na, B_0..B_nb-1, c)`` minimise

.. math::

    V(\\theta) = \\sum_{h \\in H} \\frac{1}{N_h} \\sum_{t}
        \\left\\| W_h \\sum_{k=t}^{t+h-1} \\varepsilon(k, \\theta) \\right\\|^2,
    \\qquad \\varepsilon(k, \\theta) = y[k] - \\hat y_{sim}(k \\mid \\theta)

(Ljung 1999, eq. 7.12 with a quadratic norm, applied to the prefiltered errors
``L_h(q) epsilon``, section 7.2 "prefiltering", eq. 7.10): ``L_h`` is the moving
sum over ``h`` samples, a low-pass filter, so the horizons ``H`` (1 sample and
1-30 s by default) weigh the errors that integrate into position and heading.
``W_h`` is diagonal, the inverse RMS of each channel's prefiltered error under
the starting fit, so every horizon and both channels enter with equal weight
at the start. ``c`` is an affine output offset: the model predicts
``y = G(q) u + c`` (a constant offset of v or w that commands never cause).
The simulation starts each run from the state the one-step predictor reaches
after ``warmup`` samples (as :func:`lti_motion.model.free_run_errors`).

The criterion is minimised by :func:`scipy.optimize.least_squares` (trust-region
reflective, finite-difference Jacobian) from the least-squares fit (Ljung
1999, section 10.2: an ARX estimate is the usual starting point for the
output-error search). Unstable iterates are rejected with a large residual.
An FIR is the case ``na = 0`` (its criterion is then linear in ``theta``).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lti_motion.exceptions import CalibrationError
from lti_motion.model.arx import (
    ArxFit,
    arx_regression,
    arx_state_space,
    estimate_arx,
    free_run_errors,
)
from lti_motion.model.excitation import check_runs
from lti_motion.model.motion_model import MotionModel

__all__ = ["OutputErrorFit", "OutputErrorOptions", "refine_model", "refine_output_error"]

_log = logging.getLogger(__name__)

Runs = Sequence[tuple[np.ndarray, np.ndarray]]

#: Residual given to an unstable iterate (whitened units), so the search backs off.
_UNSTABLE_RESIDUAL = 1e3


@dataclass(frozen=True)
class OutputErrorOptions:
    """Settings of the output-error criterion (module notes).

    Attributes
    ----------
    horizons_s : tuple of float
        Moving-sum horizons [s] besides the one-sample simulation error; the
        1-30 s by default.
    pose_horizons_s : tuple of float
        Horizons [s] of windows (one starting every second) over which the
        measured and the simulated speeds are integrated into a path from the
        origin (paper eq. 11); the end-point position difference [m] joins
        the criterion. Empty (default): speeds only.
    offset : bool
        Fit the affine output offset ``c`` [m/s, rad/s].
    max_nfev : int
        Limit on criterion evaluations of the search.
    """

    horizons_s: tuple[float, ...] = (1.0, 3.0, 10.0, 30.0)
    pose_horizons_s: tuple[float, ...] = ()
    offset: bool = True
    max_nfev: int = 60

    def __post_init__(self) -> None:
        for name in ("horizons_s", "pose_horizons_s"):
            h = tuple(float(x) for x in getattr(self, name))
            if not all(np.isfinite(x) and x > 0 for x in h):
                raise ValueError(f"{name} must be positive seconds, got {h}")
            object.__setattr__(self, name, h)
        if int(self.max_nfev) < 1:
            raise ValueError(f"max_nfev must be at least 1, got {self.max_nfev}")


@dataclass(frozen=True)
class OutputErrorFit:
    """A refined fit: the ARX coefficients and the output offset.

    Attributes
    ----------
    fit : ArxFit
        Refined ``a``, ``b`` (``delay`` and layout of the start); its
        ``residual_cov`` is the equation-error covariance of the refined
        coefficients on ``y - offset_speeds`` (the model's one-step noise).
    offset_speeds : ndarray, shape (2,)
        ``c`` = (v [m/s], w [rad/s]).
    cost_start, cost_end : float
        Criterion ``V`` at the start and the end (whitened, per horizon mean).
    n_evaluations : int
        Criterion evaluations used.
    """

    fit: ArxFit
    offset_speeds: np.ndarray
    cost_start: float
    cost_end: float
    n_evaluations: int


def _pack(a: np.ndarray, b: np.ndarray, c: np.ndarray, offset: bool) -> np.ndarray:
    parts = [a.ravel(), b.ravel()] + ([c] if offset else [])
    return np.concatenate(parts)


def _unpack(theta: np.ndarray, na: int, nb: int, offset: bool):
    a = theta[: 4 * na].reshape(na, 2, 2)
    b = theta[4 * na : 4 * (na + nb)].reshape(nb, 2, 2)
    c = theta[4 * (na + nb):] if offset else np.zeros(2)
    return a, b, c


def _errors(a, b, c, delay: int, runs: Runs, warmup: int) -> list[np.ndarray] | None:
    """Simulation errors ``y - (G u + c)`` per run after the warm-up; None if unstable."""
    ss = arx_state_space(a, b, delay=delay)
    if ss.A.size and np.max(np.abs(np.linalg.eigvals(ss.A))) >= 1.0:
        return None
    return free_run_errors(ss, [(u, y - c) for u, y in runs], warmup=warmup)


def _prefiltered(errors: list[np.ndarray], lengths: Sequence[int]) -> list[np.ndarray]:
    """Moving sums over each horizon (``L_h(q) epsilon``), pooled over runs, per horizon."""
    out = []
    for h in lengths:
        blocks = []
        for e in errors:
            if len(e) < h:
                continue
            cs = np.vstack([np.zeros((1, 2)), np.cumsum(e, axis=0)])
            blocks.append(cs[h:] - cs[:-h])
        out.append(np.concatenate(blocks) if blocks else np.zeros((0, 2)))
    return out


def _window_ends(speeds: np.ndarray, h: int, dt_s: float) -> np.ndarray:
    """End positions (m) of paths integrated from the origin over ``h``-sample windows."""
    starts = np.arange(0, len(speeds) - h + 1, max(1, round(1.0 / dt_s)))
    idx = starts[:, None] + np.arange(h)[None, :]
    v, w = speeds[idx, 0], speeds[idx, 1]
    theta = np.cumsum(w, axis=1) * dt_s - w * dt_s       # heading at each step's start
    mid = theta + 0.5 * w * dt_s                          # paper eq. 11, midpoint heading
    return np.stack([np.sum(v * np.cos(mid), axis=1), np.sum(v * np.sin(mid), axis=1)],
                    axis=1) * dt_s


def _pose_blocks(err: list[np.ndarray], runs: Runs, warmup: int, lengths: Sequence[int],
                 dt_s: float) -> list[np.ndarray]:
    """End-position differences (measured - simulated) per pose horizon, pooled over runs."""
    out = []
    for h in lengths:
        blocks = [_window_ends(y[warmup:], h, dt_s) - _window_ends(y[warmup:] - e, h, dt_s)
                  for (_, y), e in zip(runs, err, strict=True) if len(e) >= h]
        out.append(np.concatenate(blocks) if blocks else np.zeros((0, 2)))
    return out


def refine_output_error(start: ArxFit, runs: Runs, *, dt_s: float, warmup: int,
                        options: OutputErrorOptions | None = None) -> OutputErrorFit:
    """Refine a least-squares ARX (or FIR, ``na = 0``) fit on the output-error criterion.

    Parameters
    ----------
    start : ArxFit
        The least-squares fit (:func:`~lti_motion.model.estimate_arx`); its
        orders and delay are kept.
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and measured body speeds (n_i, 2) [m/s, rad/s].
    dt_s : float
        Sample period [s] (converts the horizons to samples).
    warmup : int
        Leading samples of each run that only set the state (at least the
        model's lag).
    options : OutputErrorOptions, optional
        Horizons, offset, evaluation limit.

    Returns
    -------
    OutputErrorFit

    Raises
    ------
    CalibrationError
        If no run is longer than ``warmup`` plus one sample, or the starting
        fit is unstable.

    Notes
    -----
    The criterion and its weights are in the module notes (Ljung 1999,
    eq. 7.10 and 7.12). The search is local: it returns the start when it
    finds nothing better (``cost_end <= cost_start`` always holds).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = np.repeat(rng.normal(size=(60, 2)), 10, axis=0)
    >>> y = np.zeros((600, 2))
    >>> for n in range(1, 600): y[n] = 0.5 * y[n - 1] + 0.5 * u[n - 1]
    >>> y += [0.01, -0.02]                                     # constant offsets
    >>> from lti_motion.model.arx import estimate_arx
    >>> ls = estimate_arx([(u, y)], na=1, delay=1)
    >>> oe = refine_output_error(ls, [(u, y)], dt_s=0.1, warmup=5)
    >>> np.round(oe.offset_speeds, 4).tolist()
    [0.01, -0.02]
    """
    opts = options or OutputErrorOptions()
    runs = [(u, y) for u, y in check_runs(runs) if len(u) > warmup + 1]
    if not runs:
        raise CalibrationError(f"no run is longer than the {warmup}-sample warm-up; record "
                               "longer runs")
    na, nb, delay = start.na, start.nb, start.delay
    lengths = [1] + [max(1, round(h / dt_s)) for h in opts.horizons_s]
    pose_lengths = [max(2, round(h / dt_s)) for h in opts.pose_horizons_s]

    def blocks(err: list[np.ndarray]) -> list[np.ndarray]:
        return (_prefiltered(err, lengths)
                + _pose_blocks(err, runs, warmup, pose_lengths, dt_s))

    e0 = _errors(start.a, start.b, np.zeros(2), delay, runs, warmup)
    if e0 is None:
        raise CalibrationError("the starting fit is unstable; refine a stable fit")
    # W_h: inverse RMS of each prefiltered channel under the start, 1/sqrt(N_h) per block
    start_blocks = blocks(e0)
    weights = [1.0 / (np.sqrt(np.mean(p * p, axis=0)) + 1e-12) / np.sqrt(max(len(p), 1))
               for p in start_blocks]
    n_res = sum(p.size for p in start_blocks)

    def residuals(theta: np.ndarray) -> np.ndarray:
        a, b, c = _unpack(theta, na, nb, opts.offset)
        err = _errors(a, b, c, delay, runs, warmup)
        if err is None:
            return np.full(n_res, _UNSTABLE_RESIDUAL)
        return np.concatenate([(p * w).ravel()
                               for p, w in zip(blocks(err), weights, strict=True)])

    theta0 = _pack(start.a, start.b, np.zeros(2), opts.offset)
    cost0 = float(np.sum(residuals(theta0) ** 2))
    sol = least_squares(residuals, theta0, method="trf", x_scale="jac", max_nfev=opts.max_nfev)
    theta = sol.x if 2 * sol.cost < cost0 else theta0
    a, b, c = _unpack(theta, na, nb, opts.offset)
    refined = dataclasses.replace(start, a=a, b=b,
                                  residual_cov=_equation_cov(a, b, c, delay, runs, start.rank))
    cost1 = min(2 * float(sol.cost), cost0)
    _log.info("output-error refinement (na=%d, nb=%d, delay=%d): cost %.4g -> %.4g in %d "
              "evaluations, offset %s", na, nb, delay, cost0, cost1, sol.nfev, np.round(c, 5))
    return OutputErrorFit(fit=refined, offset_speeds=np.array(c, dtype=float),
                          cost_start=cost0, cost_end=cost1, n_evaluations=int(sol.nfev))


def _equation_cov(a, b, c, delay: int, runs: Runs, rank: int) -> np.ndarray:
    """Equation-error covariance ``E^T E / (N - rank)`` of the coefficients on ``y - c``."""
    na, nb = a.shape[0], b.shape[0]
    phi, rhs = arx_regression([(u, y - c) for u, y in runs], na=na, nb=nb, delay=delay)
    theta = np.concatenate([b.transpose(0, 2, 1).reshape(-1, 2),   # paper eq. 12 layout
                            a.transpose(0, 2, 1).reshape(-1, 2)])
    e = rhs - phi @ theta
    cov = e.T @ e / max(len(e) - rank, 1)
    return 0.5 * (cov + cov.T)


def refine_model(model: MotionModel, runs: Runs, *, options: OutputErrorOptions | None = None,
                 warmup: int | None = None) -> MotionModel:
    """An ARX :class:`~lti_motion.model.MotionModel` refined on the output-error criterion.

    Parameters
    ----------
    model : MotionModel
        ``kind="arx"``, e.g. from :func:`~lti_motion.model.fit_arx`; its orders
        and delay are kept and its coefficients are the start.
    runs : sequence of (u, y)
        The calibration data [m/s; m/s, rad/s].
    options : OutputErrorOptions, optional
        The criterion (module notes).
    warmup : int, optional
        Samples that set each run's state; default the model's lag
        ``n_states // 2``.

    Returns
    -------
    MotionModel
        The refined coefficients, ``offset_speeds`` the fitted offset, ``R``
        their equation-error covariance and ``Q`` from it with the start's
        ``q_scale``; ``diagnostics["output_error_cost_ratio"]`` is
        ``cost_end / cost_start``.

    Raises
    ------
    ValueError
        If ``model`` is not an ARX model.
    CalibrationError
        See :func:`refine_output_error`.
    """
    if model.kind != "arx":
        raise ValueError(f"refine_model refines ARX models, got kind {model.kind!r}")
    runs = check_runs(runs)
    o = model.orders
    ls = estimate_arx(runs, na=o["na"], nb=o["nb"], delay=o["delay"], require_stable=False)
    start = dataclasses.replace(ls, a=np.array(model.coefficients["a"]),
                                b=np.array(model.coefficients["b"]))
    oe = refine_output_error(start, runs, dt_s=model.dt_s,
                             warmup=model.n_states // 2 if warmup is None else int(warmup),
                             options=options)
    diag = {**model.diagnostics, "output_error_cost_ratio": oe.cost_end / oe.cost_start}
    refined = MotionModel.from_arx(oe.fit, dt_s=model.dt_s, wheel_base_m=model.wheel_base_m,
                                   q_scale=model.q_scale, m_per_tick=model.m_per_tick,
                                   floor=model.floor, calibrated_at=model.calibrated_at,
                                   diagnostics=diag, selection=model.selection)
    return refined.updated(offset_speeds=oe.offset_speeds)
