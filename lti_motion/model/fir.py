"""The moving-average (FIR) model: least squares on input lags, and its state space.

The paper's moving-average model (section II.B, eq. 2-10) *is* a 2x2 matrix of impulse
responses, measured as differenced step responses
(:func:`~lti_motion.model.fir_from_steps`) or fitted by least squares on any
data (:func:`estimate_fir`, a regression on input lags only). Its state space is a shift
register of past inputs (:func:`fir_state_space`).

Taps are stored as ``taps[i, out, in]``: ``y[n] = sum_i taps[i] @ u[n - i]``
with ``u = (L, R)`` and ``y = (v, w)``, so ``taps[:, 0, 0]`` is the paper's
``h_Lv``, ``taps[:, 0, 1]`` ``h_Rv``, ``taps[:, 1, 0]`` ``h_Lw`` and
``taps[:, 1, 1]`` ``h_Rw``.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.model.excitation import DEFAULT_MAX_CONDITION, check_excitation, check_runs
from lti_motion.model.least_squares import (
    block_condition,
    condition_number,
    qr_r_factor,
    regression_matrix,
    svd_least_squares,
)
from lti_motion.model.state_space import StateSpace

__all__ = ["FirFit", "estimate_fir", "fir_state_space"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FirFit:
    """A 2x2 finite impulse response (moving-average model, paper eq. 8-10).

    Attributes
    ----------
    taps : ndarray, shape (m, 2, 2)
        ``y[n] = sum_i taps[i] @ u[n - i]`` [(m/s or rad/s) per (m/s)].
    residual_cov : ndarray, shape (2, 2)
        Covariance of ``y - y_model`` on the data the taps came from.
    n_samples : int
        Samples used.
    source : {"steps", "lstsq"}
        Differenced step responses, or least squares on input lags.
    step_responses : ndarray, shape (k, 2, 2), or None
        For ``"steps"``: the normalised step responses before truncation
        (rising and falling edges averaged), for plots such as paper Fig. 6.
    condition_number : float or None
        For ``"lstsq"``: of the column-scaled regression matrix.
    """

    taps: np.ndarray
    residual_cov: np.ndarray
    n_samples: int
    source: Literal["steps", "lstsq"]
    step_responses: np.ndarray | None = None
    condition_number: float | None = None

    @property
    def n_taps(self) -> int:
        """FIR length ``m``."""
        return self.taps.shape[0]



def estimate_fir(
    runs: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    n_taps: int,
    delay: int = 0,
    rcond: float | None = None,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> FirFit:
    """Fit a 2x2 FIR by least squares on input lags ``delay .. delay + n_taps - 1``.

    Parameters
    ----------
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and body speeds (n_i, 2) [m/s, rad/s].
    n_taps : int
        Number of estimated taps.
    delay : int
        Taps ``0 .. delay-1`` are fixed at zero (transport delay) [samples].
    rcond : float, optional
        See :func:`svd_least_squares`.
    max_condition : float
        Excitation limit (:func:`lti_motion.model.check_excitation`).

    Returns
    -------
    FirFit
        With ``delay + n_taps`` taps and the residual covariance
        ``E^T E / (N - 2 n_taps)``.

    Raises
    ------
    ShapeError, NonFiniteError
        For malformed runs (:func:`lti_motion.model.check_runs`).
    CalibrationError
        If there are fewer samples than the model needs (the minimum is given).
    NotExcitedError
        If the commands do not excite ``n_taps`` lags of both wheels.

    Notes
    -----
    Paper eq. 12 without the output columns: each row is
    ``(u[n - delay], ..., u[n - delay - n_taps + 1])``. Unlike step data, the
    commands must be persistently exciting of order ``n_taps`` (Ljung 1999,
    section 13.2).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(300, 2))
    >>> y = np.zeros((300, 2)); y[2:] = 0.5 * u[:-2]
    >>> fit = estimate_fir([(u, y)], n_taps=3)
    >>> (np.round(fit.taps[2], 6) + 0.0).tolist()
    [[0.5, 0.0], [0.0, 0.5]]
    """
    n_taps, delay = int(n_taps), int(delay)
    if n_taps < 1 or delay < 0:
        raise ValueError(f"need n_taps >= 1 and delay >= 0, got {n_taps} and {delay}")
    runs = check_runs(runs)
    start = delay + n_taps - 1
    p = 2 * n_taps
    n_rows = sum(max(len(u) - start, 0) for u, _ in runs)
    if n_rows <= p:
        raise CalibrationError(
            f"a FIR with {n_taps} taps after a delay of {delay} needs more than {start + p} "
            f"samples in one run (at least {start + p + 1}); got {[len(u) for u, _ in runs]}"
        )
    scale = np.sqrt(np.mean(np.concatenate([u for u, _ in runs]) ** 2, axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    lags = range(delay, delay + n_taps)
    r = qr_r_factor(regression_matrix(runs, u_lags=lags, y_lags=(), start=start, scale_u=scale))
    cond_u = check_excitation([u for u, _ in runs], n_lags=n_taps, max_condition=max_condition,
                              condition_number=block_condition(r, p))
    ls = svd_least_squares(r, slice(0, p), slice(p, p + 2), n_rows=n_rows, rcond=rcond)
    theta = ls.theta / np.tile(scale, n_taps)[:, None]
    taps = np.zeros((delay + n_taps, 2, 2))
    taps[delay:] = theta.reshape(n_taps, 2, 2).transpose(0, 2, 1)  # theta[(lag, in), out]
    _log.debug("FIR lstsq: %d taps, rank %d, cond %.3g, input cond %.3g",
               n_taps, ls.rank, condition_number(ls.singular_values), cond_u)
    return FirFit(taps=taps, residual_cov=ls.rss / (n_rows - ls.rank), n_samples=n_rows,
                  source="lstsq", condition_number=condition_number(ls.singular_values))


def fir_state_space(taps: np.ndarray) -> StateSpace:
    """Shift-register realisation of a 2x2 FIR.

    Parameters
    ----------
    taps : ndarray, shape (m, 2, 2)
        ``taps[i, out, in]``.

    Returns
    -------
    StateSpace
        State ``z[n] = (u[n-1], ..., u[n-m+1])`` (``2 (m - 1)`` values, at
        least 2), ``D = taps[0]``, ``C = [taps[1], ..., taps[m-1]]``, ``K = 0``
        (no noise model).

    Examples
    --------
    >>> ss = fir_state_space(np.stack([np.zeros((2, 2)), np.eye(2), 2 * np.eye(2)]))
    >>> ss.A.shape, ss.C.tolist()
    ((4, 4), [[1.0, 0.0, 2.0, 0.0], [0.0, 1.0, 0.0, 2.0]])
    """
    taps = np.asarray(taps, dtype=float)
    if taps.ndim != 3 or taps.shape[1:] != (2, 2) or len(taps) < 1:
        raise ShapeError(f"expected taps of shape (m, 2, 2), got {taps.shape}")
    if len(taps) == 1:
        taps = np.concatenate([taps, np.zeros((1, 2, 2))])
    nz = 2 * (len(taps) - 1)
    a = np.eye(nz, k=-2)  # z_k[n+1] = z_{k-1}[n]
    b = np.zeros((nz, 2))
    b[:2] = np.eye(2)  # z_1[n+1] = u[n]
    c = np.concatenate(list(taps[1:]), axis=1)
    return StateSpace(a, b, c, taps[0].copy(), np.zeros((nz, 2)))


