"""Physical structure imposed on an ARX fit: the wheel servos' DC gain.

It is a linear restriction on the parameters (paper eq. 12 order), so the
restricted fit is the free least-squares fit projected with the regression's
information matrix (restricted least squares, Greene 2012, eq. 5-23).

**Wheel-servo DC gain.** A robot whose wheels are each held by a speed servo
with integral action (the Roomba / Create 2, the simulator) reaches, in steady
state, encoder wheel speeds proportional to the commanded ones, the same factor
for both wheels. From commands ``u = (L, R)`` [m/s] to encoder body speeds
``y = (v [m/s], w [rad/s])`` the DC gain is therefore

.. math::

    G = c\\, M, \\qquad M = \\begin{pmatrix} 1/2 & 1/2 \\\\ -1/b & 1/b \\end{pmatrix},

with one scalar ``c`` (the ratio of the robot's internal millimetres per tick
to the calibrated ones, near 1) and the wheel base ``b`` used to compute ``y``.
A free fit estimates the straight-line yaw rate ``G[1, 0] + G[1, 1]`` as the
small difference of two large cross-gains (about +-4.3 rad/s per m/s); its
scatter of about 0.001 rad/s per calibration becomes decimetres at the end of a
ten-metre route (``docs/route.md``). The same restriction serves the FIR
model from steps (:func:`nearest_servo_gain`, :mod:`lti_motion.model.fir_steps`).

**Output scales refined on the output error.** ``fit_arx(...,
output_scale_horizons_s=...)`` then multiplies ``v`` and ``w`` by scales
``s = (s_v, s_w)`` (:func:`output_scales`, :func:`scale_outputs`), chosen to
minimise the low-frequency output-error criterion of
:mod:`lti_motion.model.output_error` (moving sums of the free-run error over the
horizons) with every other coefficient kept. The DC gain becomes
``diag(s) c M``: straight commands still give no steady yaw rate, and the
least-squares dynamics stay as fitted (docs/calibration.md has the
measurements).

References
----------
The paper: ``docs/architecture.md``, "The paper".
Greene, W. H. (2012). Econometric Analysis, 7th ed., section 5.5.1, eq. 5-23
(restricted least squares) and eq. 5-26 (its covariance).
Ljung, L. (1999). System Identification, 2nd ed., section 4.2 (static gain of
an ARX model), section 7.2, eq. 7.10 and 7.12 (the prefiltered output-error
criterion of the output scales), section 7.3 (the bias of equation-error fits).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.kinematics import body_from_wheel_matrix
from lti_motion.model.arx import ArxFit, _split_theta, free_run_errors

__all__ = [
    "dc_gain",
    "nearest_servo_gain",
    "output_scales",
    "restrict_dc_gain",
    "scale_outputs",
    "servo_dc_gain",
]


def dc_gain(fit: ArxFit) -> np.ndarray:
    """Steady-state gain ``G = (I - sum_k A_k)^-1 sum_j B_j`` (Ljung 1999, section 4.2).

    Parameters
    ----------
    fit : ArxFit
        A fitted model (paper eq. 1).

    Returns
    -------
    ndarray, shape (2, 2)
        Output per unit constant input: ``[m/s per m/s, rad/s per m/s]`` rows.

    Examples
    --------
    >>> from lti_motion.model.arx import estimate_arx
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(400, 2)); y = np.zeros((400, 2))
    >>> for n in range(1, 400): y[n] = 0.5 * y[n - 1] + 0.25 * u[n - 1]
    >>> (dc_gain(estimate_arx([(u, y)], na=1, delay=1)).round(6) + 0.0).tolist()
    [[0.5, 0.0], [0.0, 0.5]]
    """
    return np.linalg.solve(np.eye(2) - fit.a.sum(axis=0), fit.b.sum(axis=0))


def servo_dc_gain(fit: ArxFit, *, wheel_base_m: float) -> tuple[np.ndarray, float]:
    """The wheel-servo DC gain ``c M`` closest to a free fit's.

    Parameters
    ----------
    fit : ArxFit
        The free least-squares fit.
    wheel_base_m : float
        Wheel base used to compute the body speeds ``y`` [m].

    Returns
    -------
    gain : ndarray, shape (2, 2)
        ``c M``.
    c : float
        ``trace(G M^-1) / 2``: the mean of the two wheels' steady-state ratios
        of encoder speed to command [-].
    """
    return nearest_servo_gain(dc_gain(fit), wheel_base_m=wheel_base_m)


def nearest_servo_gain(gain: np.ndarray, *, wheel_base_m: float) -> tuple[np.ndarray, float]:
    """The wheel-servo gain ``c M`` nearest a 2x2 gain, in wheel coordinates.

    Shared by the ARX fit (:func:`servo_dc_gain`) and the FIR from steps
    (:func:`lti_motion.model.fir_from_steps`).

    Parameters
    ----------
    gain : array_like, shape (2, 2)
        Steady-state gain ``G`` from commands ``(L, R)`` [m/s] to body speeds
        ``(v [m/s], w [rad/s])``.
    wheel_base_m : float
        Wheel base used to compute the body speeds [m].

    Returns
    -------
    gain : ndarray, shape (2, 2)
        ``c M``.
    c : float
        ``trace(M^-1 G) / 2`` [-].

    Raises
    ------
    ShapeError
        If ``gain`` is not 2 x 2.
    ValueError
        If ``wheel_base_m`` is not positive.

    Notes
    -----
    ``M^-1 G`` is the gain from commands to the encoder *wheel* speeds, which
    the encoders measure independently, one per wheel; the restriction says it
    is ``c I``. The least-squares ``c`` (Frobenius norm, the orthogonal
    projection onto ``span(I)``; Greene 2012, eq. 5-23 with an identity
    information matrix) is ``trace(M^-1 G) / 2``.

    Examples
    --------
    >>> g, c = nearest_servo_gain([[0.5, 0.5], [-4.1, 4.3]], wheel_base_m=0.25)
    >>> round(c, 6), (g.round(6) + 0.0).tolist()
    (1.025, [[0.5125, 0.5125], [-4.1, 4.1]])
    """
    g = np.asarray(gain, float)
    if g.shape != (2, 2):
        raise ShapeError(f"gain must have shape (2, 2), got {g.shape}")
    m = body_from_wheel_matrix(wheel_base_m)
    c = float(np.trace(np.linalg.solve(m, g)) / 2.0)
    return c * m, c


def restrict_dc_gain(fit: ArxFit, gain: np.ndarray) -> ArxFit:
    """The least-squares ARX fit restricted to a given steady-state gain.

    Parameters
    ----------
    fit : ArxFit
        The free fit (its ``information_inv`` is ``(Phi^T Phi)^+``).
    gain : array_like, shape (2, 2)
        Required ``G`` (:func:`dc_gain` of the result).

    Returns
    -------
    ArxFit
        Same orders and delay; ``a``, ``b``, ``residual_cov`` and
        ``information_inv`` of the restricted estimate.

    Raises
    ------
    ShapeError
        If ``gain`` is not 2 x 2.

    Notes
    -----
    ``G = (I - sum A_k)^-1 sum B_j`` is equivalent to the linear restriction
    ``sum_j B_j + sum_k A_k G = G``; per output column of ``theta`` (paper
    eq. 12 order) that is ``C theta = G^T`` with ``C = [I .. I, G^T .. G^T]``.
    With ``P = (Phi^T Phi)^-1`` and ``r = C theta - G^T`` (Greene 2012,
    eq. 5-23 and 5-26):

    ``theta_R = theta - P C^T (C P C^T)^-1 r``, ``P_R = P - P C^T (C P C^T)^-1 C P``,

    and the residual sum of squares grows by ``r^T (C P C^T)^-1 r``.

    Examples
    --------
    >>> from lti_motion.model.arx import estimate_arx
    >>> rng = np.random.default_rng(1)
    >>> u = rng.normal(size=(2000, 2)); y = np.zeros((2000, 2))
    >>> for n in range(1, 2000):
    ...     y[n] = 0.5 * y[n - 1] + 0.25 * u[n - 1] + 0.01 * rng.normal(size=2)
    >>> fit = restrict_dc_gain(estimate_arx([(u, y)], na=1, delay=1), np.eye(2) * 0.5)
    >>> (dc_gain(fit).round(12) + 0.0).tolist()
    [[0.5, 0.0], [0.0, 0.5]]
    """
    g = np.asarray(gain, float)
    if g.shape != (2, 2):
        raise ShapeError(f"gain must have shape (2, 2), got {g.shape}")
    c = np.concatenate([np.tile(np.eye(2), fit.nb), np.tile(g.T, fit.na)], axis=1)
    p = fit.information_inv
    pc = p @ c.T
    cpc_inv = np.linalg.inv(c @ pc)
    r = c @ fit.theta - g.T                         # (2, 2): one column per output
    theta = fit.theta - pc @ cpc_inv @ r            # Greene eq. 5-23
    a, b = _split_theta(theta, fit.na, fit.nb)
    extra = r.T @ cpc_inv @ r / max(fit.n_rows - fit.rank + 2, 1)
    return dataclasses.replace(
        fit, a=a, b=b, residual_cov=fit.residual_cov + (extra + extra.T) / 2.0,
        information_inv=p - pc @ cpc_inv @ pc.T)    # Greene eq. 5-26


def _moving_sums(x: np.ndarray, h: int) -> np.ndarray:
    """Sums of ``h`` consecutive rows (the prefilter ``L_h(q)``,
    :mod:`lti_motion.model.output_error`)."""
    cs = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    return cs[h:] - cs[:-h]


def output_scales(fit: ArxFit, runs: Sequence[tuple[np.ndarray, np.ndarray]], *, warmup: int,
                  horizons: Sequence[int]) -> np.ndarray:
    """Scales of ``v`` and ``w`` minimising the prefiltered output error of a fit.

    Parameters
    ----------
    fit : ArxFit
        The fit whose free run ``y_hat`` is scaled.
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and measured body speeds (n_i, 2) [m/s, rad/s].
    warmup : int
        Leading samples of each run that only set the state
        (:func:`~lti_motion.model.free_run_errors`).
    horizons : tuple of int
        Moving-sum lengths [samples] (1 is the plain simulation error).

    Returns
    -------
    ndarray, shape (2,)
        ``(s_v, s_w)`` [-].

    Raises
    ------
    CalibrationError
        If no run is longer than ``warmup`` plus the shortest horizon, or the
        free run is zero (nothing to scale).

    Notes
    -----
    The criterion is that of :mod:`lti_motion.model.output_error` (Ljung 1999,
    eq. 7.10 and 7.12) restricted to ``y_hat -> diag(s) y_hat``:
    ``V(s) = sum_h w_h^2 || L_h y - s L_h y_hat ||^2`` per channel, with
    ``w_h^2 = 1 / (N_h mean((L_h e)^2))`` the inverse mean square of the
    start's prefiltered error ``e = y - y_hat``. ``V`` is quadratic in each
    scale, so the minimum is the weighted least-squares ratio
    ``s = sum_h w_h^2 <L_h y, L_h y_hat> / sum_h w_h^2 <L_h y_hat, L_h y_hat>``
    (Greene 2012, eq. 3-6 with one regressor).

    Examples
    --------
    >>> from lti_motion.model.arx import estimate_arx
    >>> rng = np.random.default_rng(0)
    >>> u = np.repeat(rng.normal(size=(60, 2)), 10, axis=0); y = np.zeros((600, 2))
    >>> for n in range(1, 600): y[n] = 0.5 * y[n - 1] + 0.5 * u[n - 1]
    >>> fit = estimate_arx([(u, y)], na=1, delay=1)
    >>> s = output_scales(scale_outputs(fit, [0.9, 1.1]), [(u, y)], warmup=2, horizons=(1, 10))
    >>> np.round(s * [0.9, 1.1], 4).tolist()
    [1.0, 1.0]
    """
    errors = free_run_errors(fit.state_space(), runs, warmup=warmup)
    y = [yy[warmup:] for _, yy in runs]
    num, den = np.zeros(2), np.zeros(2)
    for h in horizons:
        pairs = [(_moving_sums(yy, h), _moving_sums(yy - e, h), _moving_sums(e, h))
                 for yy, e in zip(y, errors, strict=True) if len(e) >= h]
        if not pairs:
            continue
        ly, ls, le = (np.concatenate(p) for p in zip(*pairs, strict=True))
        w2 = 1.0 / (len(le) * np.mean(le * le, axis=0) + 1e-300)
        num += w2 * np.sum(ly * ls, axis=0)
        den += w2 * np.sum(ls * ls, axis=0)
    if not np.all(den > 0):
        raise CalibrationError(f"no run is longer than the {warmup}-sample warm-up plus "
                         f"{min(horizons)} samples, or the model predicts no motion; "
                         "record longer runs")
    return num / den


def scale_outputs(fit: ArxFit, scales: ArrayLike) -> ArxFit:
    """The ARX fit whose outputs are ``diag(scales)`` times the given fit's.

    Parameters
    ----------
    fit : ArxFit
        Paper eq. 1 coefficients.
    scales : array_like, shape (2,)
        ``(s_v, s_w)``, positive [-].

    Returns
    -------
    ArxFit
        ``A_k -> S A_k S^-1``, ``B_j -> S B_j`` (``S = diag(scales)``): the same
        poles and zeros, outputs ``S y``; ``residual_cov -> S R S`` and
        ``information_inv -> T^-1 P T^-1`` with ``T`` the scaling of the
        regressors (``1`` for commands, ``S`` for each output lag).

    Raises
    ------
    ValueError
        If ``scales`` are not two positive finite numbers.

    Examples
    --------
    >>> from lti_motion.model.arx import estimate_arx
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(300, 2)); y = np.zeros((300, 2))
    >>> for n in range(1, 300): y[n] = 0.5 * y[n - 1] + 0.5 * u[n - 1]
    >>> g = dc_gain(scale_outputs(estimate_arx([(u, y)], na=1, delay=1), [2.0, 0.5]))
    >>> (np.round(g, 6) + 0.0).tolist()
    [[2.0, 0.0], [0.0, 0.5]]
    """
    s = np.asarray(scales, float)
    if s.shape != (2,) or not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(f"scales must be two positive numbers, got {s.tolist()}")
    a = s[None, :, None] * fit.a / s[None, None, :]
    b = s[None, :, None] * fit.b
    t = np.concatenate([np.ones(2 * fit.nb), np.tile(s, fit.na)])
    return dataclasses.replace(fit, a=a, b=b, residual_cov=fit.residual_cov * np.outer(s, s),
                               information_inv=fit.information_inv / np.outer(t, t))
