"""The ARX model (paper section II.C, eq. 1 and 12): estimation, order selection, stability, RLS.

The model, with full 2x2 coefficient matrices per lag, inputs ``u = (L, R)``
[m/s] and outputs ``y = (v [m/s], w [rad/s])``:

.. math::

    y[n] = \\sum_{k=1}^{n_a} A_k\\, y[n-k] + \\sum_{j=0}^{n_b-1} B_j\\, u[n-d-j] + e[n]

``d`` is the input delay: the lag of the first input coefficient (for a plant
sampled with a zero-order hold, the transport delay in samples plus one).
The paper calls this model ARMA; its order 9 is ``n_a = 9``, ``n_b = 10``,
``d = 0``. Here the order is ``n_a = n_b`` and ``d`` is chosen separately.

Regression rows follow paper eq. 12: ``(u[n-d], ..., u[n-d-n_b+1], y[n-1],
..., y[n-n_a])``; ``theta`` stacks ``B_j^T`` then ``A_k^T`` so that
``y[n]^T = phi[n]^T theta`` and both outputs are solved at once.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import (
    CalibrationError,
    NonFiniteError,
    ShapeError,
    UnstableModelError,
)
from lti_motion.metrics import fit_percent
from lti_motion.model.excitation import DEFAULT_MAX_CONDITION, check_excitation, check_runs
from lti_motion.model.least_squares import (
    block_condition,
    qr_r_factor,
    regression_matrix,
    svd_least_squares,
)
from lti_motion.model.state_space import StateSpace, simulate_state_space

__all__ = [
    "ArxFit",
    "ArxSelection",
    "RecursiveARX",
    "arx_regression",
    "arx_state_space",
    "check_stable",
    "estimate_arx",
    "free_run_errors",
    "one_step_predictor",
    "rls_update",
    "select_arx",
    "split_runs",
]

_log = logging.getLogger(__name__)

Runs = Sequence[tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class ArxFit:
    """A fitted MIMO ARX model.

    Attributes
    ----------
    a : ndarray, shape (na, 2, 2)
        Output coefficients ``A_1 .. A_na`` (``a[k-1][out, out']``).
    b : ndarray, shape (nb, 2, 2)
        Input coefficients ``B_0 .. B_{nb-1}`` (``b[j][out, in]``).
    delay : int
        Input delay ``d`` [samples].
    residual_cov : ndarray, shape (2, 2)
        One-step residual covariance ``E^T E / (N - rank)``.
    n_rows : int
        Regression rows ``N`` used.
    rank : int
        Numerical rank of the regression matrix.
    condition_number : float
        Of the column-scaled regression matrix.
    input_condition_number : float or None
        Of the lagged commands (:func:`~lti_motion.model.excitation_condition_number`).
    information_inv : ndarray, shape (p, p)
        ``(Phi^T Phi)^+``: times ``residual_cov[i, i]``, the covariance of
        column ``i`` of ``theta`` (Ljung 1999, chapter 9); the starting ``P``
        of :class:`RecursiveARX`.
    """

    a: np.ndarray
    b: np.ndarray
    delay: int
    residual_cov: np.ndarray
    n_rows: int
    rank: int
    condition_number: float
    input_condition_number: float | None
    information_inv: np.ndarray

    @property
    def na(self) -> int:
        """Number of output lags."""
        return self.a.shape[0]

    @property
    def nb(self) -> int:
        """Number of input coefficients."""
        return self.b.shape[0]

    @property
    def theta(self) -> np.ndarray:
        """Parameters ``(2 nb + 2 na, 2)`` in regression order (paper eq. 12)."""
        return _theta(self.a, self.b)

    def state_space(self) -> StateSpace:
        """Observable-form realisation (:func:`arx_state_space`)."""
        return arx_state_space(self.a, self.b, delay=self.delay)

    def poles(self) -> np.ndarray:
        """Eigenvalues of the block companion matrix of ``A_1 .. A_na`` (``2 na`` values)."""
        if self.na == 0:
            return np.empty(0, complex)
        return np.linalg.eigvals(arx_state_space(self.a, np.zeros((0, 2, 2)), delay=0).A)


def _theta(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([b.transpose(0, 2, 1).reshape(-1, 2),
                           a.transpose(0, 2, 1).reshape(-1, 2)])


def _split_theta(theta: np.ndarray, na: int, nb: int) -> tuple[np.ndarray, np.ndarray]:
    b = theta[: 2 * nb].reshape(nb, 2, 2).transpose(0, 2, 1)
    a = theta[2 * nb :].reshape(na, 2, 2).transpose(0, 2, 1)
    return np.ascontiguousarray(a), np.ascontiguousarray(b)


def _start(na: int, nb: int, delay: int) -> int:
    return max(na, delay + nb - 1 if nb else 0)


def _check_orders(na: int, nb: int, delay: int) -> tuple[int, int, int]:
    na, nb, delay = int(na), int(nb), int(delay)
    if na < 0 or nb < 0 or delay < 0 or na + nb == 0:
        raise ValueError(f"need na >= 0, nb >= 0, delay >= 0 and na + nb > 0; got na={na}, "
                         f"nb={nb}, delay={delay}")
    return na, nb, delay


def _design(runs: Runs, *, u_lags: Iterable[int], y_lags: Iterable[int], start: int,
            scale_u: np.ndarray, scale_y: np.ndarray) -> np.ndarray:
    """Rows ``(u lags / scale_u, y lags / scale_y, y)`` of all runs; rows never straddle runs."""
    return regression_matrix(runs, u_lags=list(u_lags), y_lags=list(y_lags), start=start,
                             scale_u=scale_u, scale_y=scale_y)


def arx_regression(runs: Runs, *, na: int, nb: int, delay: int = 0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares system of paper eq. 12 over one or many runs.

    Parameters
    ----------
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and body speeds (n_i, 2) [m/s, rad/s].
    na, nb, delay : int
        Output lags, input coefficients, input delay.

    Returns
    -------
    phi : ndarray, shape (N, 2 nb + 2 na)
        Rows ``(u[n-d], ..., u[n-d-nb+1], y[n-1], ..., y[n-na])``.
    y : ndarray, shape (N, 2)
        Targets ``y[n]``. Each run contributes ``n_i - max(na, d + nb - 1)``
        rows; no row mixes samples of two runs.

    Examples
    --------
    >>> u = np.arange(8.0).reshape(4, 2); y = -u
    >>> phi, target = arx_regression([(u, y)], na=1, nb=1, delay=1)
    >>> (phi[0] + 0.0).tolist(), target[0].tolist()
    ([0.0, 1.0, 0.0, -1.0], [-2.0, -3.0])
    """
    na, nb, delay = _check_orders(na, nb, delay)
    runs = check_runs(runs)
    start = _start(na, nb, delay)
    one = np.ones(2)
    m = _design(runs, u_lags=range(delay, delay + nb), y_lags=range(1, na + 1), start=start,
                scale_u=one, scale_y=one)
    return m[:, :-2], m[:, -2:]


def _scales(runs: Runs) -> tuple[np.ndarray, np.ndarray]:
    """Root mean square of each input and output channel (column scaling)."""
    u = np.concatenate([u for u, _ in runs])
    y = np.concatenate([y for _, y in runs])
    su, sy = np.sqrt(np.mean(u * u, axis=0)), np.sqrt(np.mean(y * y, axis=0))
    return np.where(su > 0, su, 1.0), np.where(sy > 0, sy, 1.0)


def _fit_from_factor(r, cols, p_total, *, na, nb, delay, n_rows, col_scale, rcond, cond_u):
    ls = svd_least_squares(r, cols, slice(p_total, p_total + 2), n_rows=n_rows, rcond=rcond)
    theta = ls.theta / col_scale[:, None]
    a, b = _split_theta(theta, na, nb)
    s = ls.singular_values
    info = (ls.vt.T / s[: ls.rank] ** 2) @ ls.vt  # (Phi_s^T Phi_s)^+ in scaled units
    info = info / np.outer(col_scale, col_scale)
    return ArxFit(a=a, b=b, delay=delay, residual_cov=ls.rss / max(n_rows - ls.rank, 1),
                  n_rows=n_rows, rank=ls.rank,
                  condition_number=float(s[0] / s[-1]) if len(s) and s[-1] > 0 else float("inf"),
                  input_condition_number=cond_u, information_inv=info)


def _too_short(runs: Runs, start: int, p: int, what: str) -> CalibrationError:
    return CalibrationError(
        f"{what} needs more rows than its {p} parameters per output: at least {start + p + 1} "
        f"samples in one run ({start} to fill the lags), got runs of {[len(u) for u, _ in runs]} "
        "samples; record longer or lower the order"
    )


def estimate_arx(
    runs: Runs,
    *,
    na: int,
    nb: int | None = None,
    delay: int = 0,
    rcond: float | None = None,
    max_condition: float = DEFAULT_MAX_CONDITION,
    require_stable: bool = True,
) -> ArxFit:
    """Least-squares ARX fit (paper eq. 12), both outputs in one SVD solve.

    Parameters
    ----------
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and body speeds (n_i, 2) [m/s, rad/s].
    na : int
        Output lags (0 gives an FIR).
    nb : int, optional
        Input coefficients, default ``na`` (0 gives a pure vector AR model).
    delay : int
        Input delay ``d`` [samples].
    rcond : float, optional
        Relative singular-value cut-off (:func:`~lti_motion.model.svd_least_squares`).
    max_condition : float
        Excitation limit (:func:`~lti_motion.model.check_excitation`).
    require_stable : bool
        Raise :class:`UnstableModelError` for poles on or outside the unit circle.

    Returns
    -------
    ArxFit

    Raises
    ------
    ShapeError, NonFiniteError
        For malformed runs.
    CalibrationError
        If the runs are too short for the order (the minimum is given).
    NotExcitedError
        If the commands are not persistently exciting of order ``nb``.
    UnstableModelError
        If ``require_stable`` and a pole has ``|p| >= 1`` (magnitudes listed).

    Notes
    -----
    Columns are scaled to unit RMS per channel, the tall matrix
    ``[Phi | Y]`` is reduced to its triangular factor and the problem is
    solved by SVD on that factor (Golub & Van Loan 2013, sections 5.3-5.5);
    ``R = E^T E / (N - rank)`` estimates the innovation covariance (Ljung
    1999, sections 7.3-7.4, with the usual degrees-of-freedom correction).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(500, 2)); y = np.zeros((500, 2))
    >>> for n in range(2, 500): y[n] = 0.5 * y[n - 1] + 0.2 * u[n - 2]
    >>> fit = estimate_arx([(u, y)], na=1, delay=2)
    >>> (np.round(fit.a[0], 6) + 0.0).tolist(), (np.round(fit.b[0], 6) + 0.0).tolist()
    ([[0.5, 0.0], [0.0, 0.5]], [[0.2, 0.0], [0.0, 0.2]])
    """
    na, nb, delay = _check_orders(na, na if nb is None else nb, delay)
    runs = check_runs(runs)
    start, p = _start(na, nb, delay), 2 * (na + nb)
    n_rows = sum(max(len(u) - start, 0) for u, _ in runs)
    if n_rows <= p:
        raise _too_short(runs, start, p, f"an ARX model with na={na}, nb={nb}, delay={delay}")
    su, sy = _scales(runs)
    m = _design(runs, u_lags=range(delay, delay + nb), y_lags=range(1, na + 1), start=start,
                scale_u=su, scale_y=sy)
    r = qr_r_factor(m)
    cond_u = (check_excitation([u for u, _ in runs], n_lags=nb, max_condition=max_condition,
                               condition_number=block_condition(r, 2 * nb)) if nb else None)
    fit = _fit_from_factor(r, slice(0, p), p, na=na, nb=nb, delay=delay,
                           n_rows=n_rows, col_scale=np.concatenate([np.tile(su, nb),
                                                                    np.tile(sy, na)]),
                           rcond=rcond, cond_u=cond_u)
    if require_stable:
        check_stable(fit.poles(), what=f"the ARX fit (na={na}, nb={nb}, delay={delay})")
    return fit


def check_stable(poles: np.ndarray, *, what: str = "the model") -> None:
    """Raise :class:`UnstableModelError` listing the pole magnitudes if any ``|p| >= 1``.

    Examples
    --------
    >>> check_stable(np.array([0.5, 1.2]))
    Traceback (most recent call last):
    ...
    lti_motion.exceptions.UnstableModelError: the model is unstable: pole magnitudes [1.2, 0.5] ...
    """
    mags = np.sort(np.abs(np.asarray(poles)))[::-1]
    if mags.size and mags[0] >= 1.0:
        raise UnstableModelError(
            f"{what} is unstable: pole magnitudes {np.round(mags, 6).tolist()} (all must be < 1). "
            "Check the data for saturation, slip or a stalled wheel, record more random "
            "excitation, or use a lower order"
        )


def arx_state_space(a: np.ndarray, b: np.ndarray, *, delay: int) -> StateSpace:
    """Observable canonical realisation of the MIMO ARX model, delay included.

    Parameters
    ----------
    a : ndarray, shape (na, 2, 2)
    b : ndarray, shape (nb, 2, 2)
    delay : int

    Returns
    -------
    StateSpace
        With ``r = max(na, d + nb - 1, 1)`` blocks of 2 states,
        ``C = [I 0 ... 0]``, ``D = Bt_0``, ``A`` the block companion with
        ``A_k`` in the first block column and identities above the diagonal,
        ``B_k = Bt_k + A_k Bt_0`` and the innovation gain ``K = [A_1; ...; A_r]``
        (``Bt_i = B_{i-d}``, zero outside ``d .. d+nb-1``).

    Notes
    -----
    State block ``k`` is ``z_k[n] = sum_{j >= 0} (A_{k+j} y[n-1-j] + Bt_{k+j}
    u[n-1-j])``; then ``y[n] = z_1[n] + Bt_0 u[n] + e[n]`` reproduces eq. 1.
    Because the recursion runs on the *measured* ``y``, the equation error
    enters the state through ``K``: this is the ARX model's innovations form
    (Ljung 1999, sections 4.2-4.3). ``A - K C`` is
    nilpotent, so the one-step predictor forgets its initial state after
    ``r`` samples.

    Examples
    --------
    >>> ss = arx_state_space(np.array([0.5 * np.eye(2)]), np.array([np.eye(2)]), delay=2)
    >>> ss.A.shape, ss.D.tolist(), ss.K[:2].tolist()
    ((4, 4), [[0.0, 0.0], [0.0, 0.0]], [[0.5, 0.0], [0.0, 0.5]])
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    na, nb, delay = a.shape[0], b.shape[0], int(delay)
    r = max(na, delay + nb - 1 if nb else 0, 1)
    a_pad = np.zeros((r + 1, 2, 2))  # a_pad[k] = A_k, A_0 unused
    a_pad[1 : na + 1] = a
    bt = np.zeros((r + 1, 2, 2))  # bt[i] = B_{i-d}
    bt[delay : delay + nb] = b
    nz = 2 * r
    A = np.eye(nz, k=2)
    A[:, :2] = a_pad[1:].reshape(nz, 2)
    B = (bt[1:] + a_pad[1:] @ bt[0]).reshape(nz, 2)
    C = np.eye(2, nz)
    return StateSpace(A, B, C, bt[0].copy(), a_pad[1:].reshape(nz, 2).copy())


def one_step_predictor(ss: StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The one-step predictor as a state-space system with input ``(u, y)``.

    Returns
    -------
    (A - K C, [B - K D, K], C, [D, 0])
        ``z[n+1] = (A - K C) z + (B - K D) u + K y``, ``yhat[n] = C z + D u``
        (Ljung 1999, sections 3.2 and 4.3).
    """
    a, b, c, d, k = ss
    return (a - k @ c, np.hstack([b - k @ d, k]), c, np.hstack([d, np.zeros_like(d)]))


def free_run_errors(
    ss: StateSpace, runs: Runs, *, warmup: int
) -> list[np.ndarray]:
    """Free-run (sensor-less) errors after a warm-up that sets the initial state.

    Parameters
    ----------
    ss : StateSpace
        The model.
    runs : sequence of (u, y)
        Validation runs; the first ``warmup`` samples of each only set the
        state (one-step predictor), the rest is simulated from ``u`` alone.
    warmup : int
        Samples; at least the model's lag ``r`` so the state is exact.

    Returns
    -------
    list of ndarray, shape (n_i - warmup, 2)
        ``y - y_free`` of each run.
    """
    pa, pb, pc, pd = one_step_predictor(ss)
    out = []
    for u, y in runs:
        z = simulate_state_space(pa, pb, pc, pd, np.hstack([u[:warmup], y[:warmup]]))[1]
        out.append(y[warmup:] - simulate_state_space(ss.A, ss.B, ss.C, ss.D, u[warmup:],
                                                     z0=z)[0])
    return out


def split_runs(runs: Runs, validation: float | Runs, *, warmup: int) -> tuple[list, list]:
    """Estimation and validation runs.

    Parameters
    ----------
    runs : sequence of (u, y)
        Checked runs.
    validation : float or sequence of (u, y)
        A fraction in (0, 1): the last part of each run is held out (its
        validation run starts ``warmup`` samples earlier, to set the state);
        or separate validation runs.
    warmup : int
        Samples of each validation run used only to set the state.

    Returns
    -------
    (estimation runs, validation runs)

    Raises
    ------
    CalibrationError
        If no run is long enough to hold out a validation part.
    """
    if not isinstance(validation, (int, float)):
        val = check_runs(validation, min_samples=warmup + 2)
        return list(runs), val
    frac = float(validation)
    if not 0 < frac < 1:
        raise ValueError(f"validation must be a fraction in (0, 1) or runs, got {validation!r}")
    est, val = [], []
    for u, y in runs:
        n_est = len(u) - round(frac * len(u))
        if n_est >= warmup and len(u) - n_est >= 2:
            est.append((u[:n_est], y[:n_est]))
            val.append((u[n_est - warmup :], y[n_est - warmup :]))
        else:
            est.append((u, y))
    if not val:
        raise CalibrationError(f"no run is long enough to hold out {frac:.0%} for validation "
                               f"after a warm-up of {warmup} samples; record longer runs")
    return est, val


@dataclass(frozen=True)
class ArxSelection:
    """Order and delay selection on held-out data: the whole grid and the choice.

    Attributes
    ----------
    orders, delays : ndarray of int, shapes (n_o,), (n_d,)
        The grid (order ``na = nb``).
    fit_percent : ndarray, shape (n_o, n_d, 2)
        Free-run validation fit of ``(v, w)`` [%] (``-inf`` where unstable).
    nrmse : ndarray, shape (n_o, n_d)
        ``1 - mean(fit_percent) / 100`` (``inf`` where unstable).
    stable : ndarray of bool, shape (n_o, n_d)
    order, delay : int
        The choice.
    tolerance : float
        Relative tolerance of the choice.
    fit : ArxFit
        The chosen candidate, fitted on the estimation part only.
    warmup : int
        Samples at the start of each validation run that only set the state.
    """

    orders: np.ndarray
    delays: np.ndarray
    fit_percent: np.ndarray
    nrmse: np.ndarray
    stable: np.ndarray
    order: int
    delay: int
    tolerance: float
    fit: ArxFit
    warmup: int

    @property
    def curve(self) -> np.ndarray:
        """Best validation NRMSE per order (over delays), shape (n_o,)."""
        return self.nrmse.min(axis=1)

    @property
    def validation_fit_percent(self) -> np.ndarray:
        """Free-run validation fit ``(v, w)`` [%] of the chosen model."""
        i = int(np.flatnonzero(self.orders == self.order)[0])
        j = int(np.flatnonzero(self.delays == self.delay)[0])
        return self.fit_percent[i, j]


def select_arx(
    runs: Runs,
    *,
    orders: Iterable[int] = range(1, 13),
    delays: Iterable[int] = range(0, 9),
    validation: float | Runs = 0.3,
    tolerance: float = 0.02,
    rcond: float | None = None,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> ArxSelection:
    """Choose the ARX order and delay by free-run error on held-out data.

    Parameters
    ----------
    runs : sequence of (u, y)
        Calibration runs (random excitation, paper section III.C).
    orders, delays : iterable of int
        The grid; order means ``na = nb``.
    validation : float or sequence of (u, y)
        Held-out fraction of each run, or separate validation runs.
    tolerance : float
        The chosen order is the smallest whose best validation NRMSE is
        within ``(1 + tolerance)`` of the best of the grid: where the curve
        levels off. At that order the delay is the largest within the same
        tolerance of that order's best (the longest dead time the data allow).
    rcond, max_condition : float
        As :func:`estimate_arx`.

    Returns
    -------
    ArxSelection

    Raises
    ------
    CalibrationError, NotExcitedError, ShapeError, NonFiniteError
        As :func:`estimate_arx`, for the largest order of the grid.
    UnstableModelError
        If every candidate is unstable.

    Notes
    -----
    Every candidate is fitted on the same rows (one triangular factor of the
    largest regression serves all of them) and scored by simulation from the
    commands only, after a warm-up that sets the state: the use the model is
    built for. One-step errors and AIC favour the highest order when the
    outputs are noisy (Ljung 1999, chapter 16: cross-validation).
    """
    orders = np.array(sorted({int(o) for o in orders}))
    delays = np.array(sorted({int(d) for d in delays}))
    if orders.size == 0 or delays.size == 0 or orders[0] < 1 or delays[0] < 0:
        raise ValueError(f"need orders >= 1 and delays >= 0, got {orders} and {delays}")
    runs = check_runs(runs)
    o_max, d_max = int(orders[-1]), int(delays[-1])
    start = _start(o_max, o_max, d_max)
    est, val = split_runs(runs, validation, warmup=start)
    n_u = d_max + o_max  # input lags 0 .. d_max + o_max - 1
    p_total = 2 * (n_u + o_max)
    n_rows = sum(max(len(u) - start, 0) for u, _ in est)
    if n_rows <= 4 * o_max:
        raise _too_short(est, start, 4 * o_max, f"order selection up to order {o_max}")
    su, sy = _scales(est)
    r = qr_r_factor(_design(est, u_lags=range(n_u), y_lags=range(1, o_max + 1), start=start,
                            scale_u=su, scale_y=sy))
    cond_u = check_excitation([u for u, _ in est], n_lags=o_max, max_condition=max_condition,
                              condition_number=block_condition(r, 2 * o_max))
    y_val = np.concatenate([y[start:] for _, y in val])
    fits = np.full((orders.size, delays.size, 2), -np.inf)
    stable = np.zeros((orders.size, delays.size), bool)
    cands: dict[tuple[int, int], ArxFit] = {}
    for i, o in enumerate(orders):
        for j, d in enumerate(delays):
            cols = np.r_[2 * d : 2 * (d + o), 2 * n_u : 2 * (n_u + o)]
            fit = _fit_from_factor(r, cols, p_total, na=o, nb=o, delay=d, n_rows=n_rows,
                                   col_scale=np.concatenate([np.tile(su, o), np.tile(sy, o)]),
                                   rcond=rcond, cond_u=cond_u)
            cands[i, j] = fit
            stable[i, j] = np.all(np.abs(fit.poles()) < 1.0)
            if stable[i, j]:
                err = np.concatenate(free_run_errors(fit.state_space(), val, warmup=start))
                fits[i, j] = fit_percent(y_val, y_val - err, axis=0)
    nrmse = np.where(stable, 1.0 - fits.mean(axis=2) / 100.0, np.inf)
    curve = nrmse.min(axis=1)
    if not np.isfinite(curve).any():
        check_stable(cands[0, 0].poles(), what=f"every ARX candidate (e.g. order {orders[0]}, "
                                                 f"delay {delays[0]})")
    limit = curve.min() * (1.0 + tolerance) if curve.min() > 0 else curve.min()
    i = int(np.flatnonzero(curve <= limit)[0])
    j = int(np.flatnonzero(nrmse[i] <= curve[i] * (1.0 + tolerance))[-1])
    _log.info("ARX selection: order %d, delay %d, validation fit %s %% (best NRMSE %.4g)",
              orders[i], delays[j], np.round(fits[i, j], 2).tolist(), curve.min())
    return ArxSelection(orders=orders, delays=delays, fit_percent=fits, nrmse=nrmse,
                        stable=stable, order=int(orders[i]), delay=int(delays[j]),
                        tolerance=float(tolerance), fit=cands[i, j], warmup=start)


def _rls_step(theta, p, phi, y, lam):
    """One RLS step; returns (theta, P, a-priori error). Ljung 1999, section 11.2."""
    p_phi = p @ phi
    den = lam + phi @ p_phi
    err = y - phi @ theta
    theta = theta + np.outer(p_phi / den, err)
    p = (p - np.outer(p_phi, p_phi) / den) / lam  # outer(p_phi, p_phi) keeps P symmetric
    return theta, p, err


def rls_update(
    theta: np.ndarray, p: np.ndarray, phi: np.ndarray, y: np.ndarray, *, lam: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """One recursive least-squares update with forgetting factor ``lam``.

    Parameters
    ----------
    theta : ndarray, shape (n_params, n_out)
        Parameters (one column per output; the regressor is shared).
    p : ndarray, shape (n_params, n_params)
        Symmetric "covariance" matrix ``(sum lam^(n-k) phi phi^T)^-1``.
    phi : ndarray, shape (n_params,)
        Regressor.
    y : ndarray, shape (n_out,)
        Measured outputs.
    lam : float
        Forgetting factor in (0, 1]; memory about ``1 / (1 - lam)`` samples.

    Returns
    -------
    (theta, p) : new arrays

    Notes
    -----
    ``K = P phi / (lam + phi^T P phi)``, ``theta += K (y - phi^T theta)``,
    ``P = (P - P phi phi^T P / (lam + phi^T P phi)) / lam`` (Ljung 1999,
    section 11.2).

    Examples
    --------
    >>> theta, p = rls_update(np.zeros((1, 1)), np.eye(1) * 1e6, np.array([2.0]),
    ...                       np.array([4.0]))
    >>> round(float(theta[0, 0]), 6)
    2.0
    """
    theta, p, _ = _rls_step(theta, p, phi, y, float(lam))
    return theta, p


class RecursiveARX:
    """Online ARX estimation by recursive least squares with forgetting.

    Parameters
    ----------
    na, nb, delay : int
        Model structure (as :func:`estimate_arx`).
    lam : float
        Forgetting factor in (0, 1].
    theta0 : ndarray, shape (2 nb + 2 na, 2), optional
        Initial parameters; zeros by default.
    p0 : float or ndarray
        Initial ``P``: a scalar times the identity (large: little trust in
        ``theta0``) or a matrix.

    Notes
    -----
    The signals before the first update count as zero (robot at rest). The
    residual covariance is the exponentially weighted mean of the a-priori
    errors (same ``lam``).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(400, 2)); y = np.zeros((400, 2))
    >>> for n in range(1, 400): y[n] = 0.5 * y[n - 1] + 0.2 * u[n - 1]
    >>> rls = RecursiveARX(na=1, nb=1, delay=1)
    >>> _ = rls.update_many(u, y)
    >>> (np.round(rls.to_fit().a[0], 4) + 0.0).tolist()
    [[0.5, 0.0], [0.0, 0.5]]
    """

    def __init__(self, *, na: int, nb: int, delay: int = 0, lam: float = 1.0,
                 theta0: np.ndarray | None = None, p0: float | np.ndarray = 1e6) -> None:
        self.na, self.nb, self.delay = _check_orders(na, nb, delay)
        if not 0 < lam <= 1:
            raise ValueError(f"lam must be in (0, 1], got {lam!r}")
        self.lam = float(lam)
        n_par = 2 * (self.na + self.nb)
        self._theta = np.zeros((n_par, 2)) if theta0 is None else np.array(theta0, dtype=float)
        self._p = np.eye(n_par) * p0 if np.ndim(p0) == 0 else np.array(p0, dtype=float)
        if self._theta.shape != (n_par, 2) or self._p.shape != (n_par, n_par):
            raise ShapeError(f"expected theta0 {(n_par, 2)} and p0 {(n_par, n_par)}, got "
                             f"{self._theta.shape} and {self._p.shape}")
        self._hist = _start(self.na, self.nb, self.delay)
        self._u = np.zeros((self._hist, 2))
        self._y = np.zeros((self._hist, 2))
        # rows of [history; new sample] that form one regressor (regression_matrix's order)
        self._u_rows = self._hist - np.arange(self.delay, self.delay + self.nb)
        self._y_rows = self._hist - np.arange(1, self.na + 1)
        self._u_now = np.zeros((self._hist + 1, 2))
        self._sum_ee = np.zeros((2, 2))
        self._weight = 0.0
        self.n_updates = 0

    @classmethod
    def from_fit(cls, fit: ArxFit, *, lam: float) -> RecursiveARX:
        """Continue a batch fit online, with ``P = (Phi^T Phi)^+`` of the batch."""
        return cls(na=fit.na, nb=fit.nb, delay=fit.delay, lam=lam, theta0=fit.theta,
                   p0=fit.information_inv)

    @property
    def theta(self) -> np.ndarray:
        """Current parameters (copy), regression order."""
        return self._theta.copy()

    @property
    def p(self) -> np.ndarray:
        """Current ``P`` (copy)."""
        return self._p.copy()

    def update(self, cmd_m_s: np.ndarray, speeds: np.ndarray) -> np.ndarray:
        """One sample: returns the a-priori prediction of ``speeds`` (2,).

        The same update as :meth:`update_many` on one row, with the regressor
        taken straight from the stored history (no regression matrix built).

        Raises
        ------
        ShapeError
            If ``cmd_m_s`` or ``speeds`` is not of shape (2,).
        NonFiniteError
            If either holds NaN or inf.
        """
        cmd_m_s = np.asarray(cmd_m_s, dtype=float)
        speeds = np.asarray(speeds, dtype=float)
        if cmd_m_s.shape != (2,) or speeds.shape != (2,):
            raise ShapeError(f"update() expects cmd_m_s and speeds of shape (2,), got "
                             f"{cmd_m_s.shape} and {speeds.shape}")
        if not (np.isfinite(cmd_m_s).all() and np.isfinite(speeds).all()):
            raise NonFiniteError(f"update() got non-finite samples cmd_m_s={cmd_m_s}, "
                                 f"speeds={speeds}")
        u_now = self._u_now
        u_now[:-1] = self._u
        u_now[-1] = cmd_m_s
        phi = np.concatenate([u_now[self._u_rows].ravel(), self._y[self._y_rows].ravel()])
        self._theta, self._p, err = _rls_step(self._theta, self._p, phi, speeds, self.lam)
        self._sum_ee = self.lam * self._sum_ee + np.outer(err, err)
        self._weight = self.lam * self._weight + 1.0
        self._u[:-1] = self._u[1:]
        self._u[-1] = cmd_m_s
        self._y[:-1] = self._y[1:]
        self._y[-1] = speeds
        self.n_updates += 1
        return speeds - err

    def update_many(self, cmd_m_s: np.ndarray, speeds: np.ndarray) -> np.ndarray:
        """Update with consecutive samples ``u, y`` (n, 2); returns the a-priori predictions."""
        ((cmd_m_s, speeds),) = check_runs([(cmd_m_s, speeds)])
        h = self._hist
        uu, yy = np.concatenate([self._u, cmd_m_s]), np.concatenate([self._y, speeds])
        phi = np.ascontiguousarray(regression_matrix(
            [(uu, yy)], u_lags=range(self.delay, self.delay + self.nb),
            y_lags=range(1, self.na + 1), start=h)[:, :-2])
        theta, p, lam = self._theta, self._p, self.lam
        err = np.empty((len(cmd_m_s), 2))
        for k in range(len(cmd_m_s)):  # inherently sequential; the body is one small update
            theta, p, err[k] = _rls_step(theta, p, phi[k], speeds[k], lam)
        self._theta, self._p = theta, p
        w = lam ** np.arange(len(cmd_m_s) - 1, -1, -1.0)
        decay = lam ** len(cmd_m_s)
        self._sum_ee = decay * self._sum_ee + (err * w[:, None]).T @ err
        self._weight = decay * self._weight + w.sum()
        self._u, self._y = uu[len(uu) - h :], yy[len(yy) - h :]
        self.n_updates += len(cmd_m_s)
        return speeds - err

    def to_fit(self) -> ArxFit:
        """The current estimate as an :class:`ArxFit` (rank and conditioning from ``P``)."""
        a, b = _split_theta(self._theta, self.na, self.nb)
        eig = np.linalg.eigvalsh(self._p)
        cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else float("inf")
        cov = self._sum_ee / self._weight if self._weight > 0 else np.zeros((2, 2))
        return ArxFit(a=a, b=b, delay=self.delay, residual_cov=cov, n_rows=self.n_updates,
                      rank=int(np.sum(eig > 0)), condition_number=cond,
                      input_condition_number=None, information_inv=self._p.copy())
