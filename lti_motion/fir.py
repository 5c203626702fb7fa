"""Impulse responses: the moving-average (FIR) model, least squares on lagged data, simulation.

Impulse responses are the common currency of the linear models here:

- the paper's moving-average model (II.B, eq. 2-10) *is* a 2x2 matrix of
  impulse responses, measured as differenced step responses
  (:func:`fir_from_steps`) or fitted by least squares on any data
  (:func:`estimate_fir`, a regression on input lags only);
- every state-space model has one (its Markov parameters,
  :func:`markov_parameters`), and :func:`simulate_state_space` runs a model
  by convolving each block of commands with it and carrying the state across
  blocks, which vectorises the simulation over samples.

The least-squares machinery that the ARX estimator shares (lagged columns,
the triangular factor of a tall regression, an SVD solve) lives here too.

Taps are stored as ``taps[i, out, in]``: ``y[n] = sum_i taps[i] @ u[n - i]``
with ``u = (L, R)`` and ``y = (v, w)``, so ``taps[:, 0, 0]`` is the paper's
``h_Lv``, ``taps[:, 0, 1]`` ``h_Rv``, ``taps[:, 1, 0]`` ``h_Lw`` and
``taps[:, 1, 1]`` ``h_Rw``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.excitation import DEFAULT_MAX_CONDITION, check_excitation, check_runs

__all__ = [
    "FirFit",
    "LeastSquares",
    "StateSpace",
    "block_condition",
    "estimate_fir",
    "fir_state_space",
    "lagged_columns",
    "markov_parameters",
    "qr_r_factor",
    "regression_matrix",
    "simulate_state_space",
    "simulate_state_space_loop",
    "svd_least_squares",
]

_log = logging.getLogger(__name__)


class StateSpace(NamedTuple):
    """Matrices of ``z[n+1] = A z + B u + K e``, ``y[n] = C z + D u + e`` (innovations form)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray


class LeastSquares(NamedTuple):
    """Solution of a least-squares problem given by its triangular factor."""

    theta: np.ndarray  #: (p, k) minimum-norm solution
    rank: int  #: numerical rank of the regression matrix
    singular_values: np.ndarray  #: (p,) of the (scaled) regression matrix
    rss: np.ndarray  #: (k, k) residual cross-product E^T E
    vt: np.ndarray  #: (rank, p) right singular vectors kept


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


def lagged_columns(x: np.ndarray, lags: Sequence[int], *, start: int) -> np.ndarray:
    """Stack lagged copies of a signal as regression columns (paper eq. 12).

    Parameters
    ----------
    x : ndarray, shape (n, c)
        Signal, time along axis 0.
    lags : sequence of int
        Lags ``l >= 0``; all ``<= start``.
    start : int
        First row's sample index; row ``k`` holds sample ``start + k``.

    Returns
    -------
    ndarray, shape (n - start, len(lags) * c)
        Row ``k`` is ``(x[t - lags[0]], x[t - lags[1]], ...)`` at ``t = start + k``
        (column-major, the layout LAPACK works in).

    Examples
    --------
    >>> lagged_columns(np.arange(5.0)[:, None], [0, 2], start=2).tolist()
    [[2.0, 0.0], [3.0, 1.0], [4.0, 2.0]]
    """
    return regression_matrix([(x, x[:, :0])], u_lags=lags, y_lags=(), start=start)


def regression_matrix(
    runs: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    u_lags: Sequence[int],
    y_lags: Sequence[int],
    start: int,
    scale_u: np.ndarray | None = None,
    scale_y: np.ndarray | None = None,
) -> np.ndarray:
    """Rows ``(u lags, y lags, y)`` of all runs, each channel divided by its scale.

    Parameters
    ----------
    runs : sequence of (u, y)
        Checked runs, ``u`` (n_i, cu) and ``y`` (n_i, cy).
    u_lags, y_lags : sequence of int
        Lags of the input and output columns (all ``<= start``).
    start : int
        First sample of each run that gets a row.
    scale_u, scale_y : ndarray, optional
        Per-channel divisors of the lagged columns (the target ``y`` columns
        are not scaled).

    Returns
    -------
    ndarray, shape (sum(n_i - start), (len(u_lags) cu + len(y_lags) cy) + cy)
        Column-major. Rows never mix samples of two runs.

    Notes
    -----
    Built in the transposed layout, where every lag is one contiguous copy
    per channel: no loop over samples.
    """
    cu, cy = runs[0][0].shape[1], runs[0][1].shape[1]
    width = len(u_lags) * cu + len(y_lags) * cy + cy
    rows = [len(u) - start for u, _ in runs if len(u) > start]
    out = np.empty((width, sum(rows)))
    r0 = 0
    for u, y in runs:
        n = len(u)
        if n <= start:
            continue
        ut = (u / (1.0 if scale_u is None else scale_u)).T
        yt = (y / (1.0 if scale_y is None else scale_y)).T
        blk = out[:, r0 : r0 + n - start]
        col = 0
        for xt, lags, c in ((ut, u_lags, cu), (yt, y_lags, cy)):
            for lag in lags:  # a loop over lags; each copy is vectorised over samples
                blk[col : col + c] = xt[:, start - lag : n - lag]
                col += c
        blk[col:] = y[start:].T
        r0 += n - start
    return out.T


def qr_r_factor(m: np.ndarray, *, chunk_rows: int = 1024) -> np.ndarray:
    """Triangular factor ``R`` of ``m = Q R`` without forming ``Q`` (tall-skinny QR).

    Parameters
    ----------
    m : ndarray, shape (n, p)
        Tall matrix, usually ``[regressors | targets]``.
    chunk_rows : int
        Rows per block (blocks that fit in cache are faster than one QR).

    Returns
    -------
    ndarray, shape (min(n, p), p)
        Upper triangular; ``||m x|| = ||R x||`` for every ``x``, so any least-
        squares problem on columns of ``m`` can be solved on ``R`` instead.

    Notes
    -----
    Householder QR of each block, then of the stacked block factors (TSQR,
    Demmel et al. 2012); Golub & Van Loan 2013, section 5.3.
    """
    if len(m) <= chunk_rows:
        return np.linalg.qr(m, mode="r")
    blocks = [np.linalg.qr(m[i : i + chunk_rows], mode="r") for i in range(0, len(m), chunk_rows)]
    return np.linalg.qr(np.vstack(blocks), mode="r")


def svd_least_squares(
    r: np.ndarray,
    cols: np.ndarray | slice,
    rhs_cols: np.ndarray | slice,
    *,
    n_rows: int,
    rcond: float | None = None,
) -> LeastSquares:
    """Minimum-norm least squares ``min ||M[:, cols] theta - M[:, rhs_cols]||`` from ``R``.

    Parameters
    ----------
    r : ndarray, shape (q, p_total)
        Triangular factor of ``M`` (:func:`qr_r_factor`).
    cols, rhs_cols : index arrays or slices
        Regressor and target columns of ``M``.
    n_rows : int
        Rows of ``M`` (for the default ``rcond``).
    rcond : float, optional
        Singular values below ``rcond * sigma_max`` count as zero; default
        ``eps * max(n_rows, p)`` as in ``numpy.linalg.lstsq``.

    Returns
    -------
    LeastSquares

    Notes
    -----
    SVD least squares (the paper's ``cv::solve`` with SVD) on the small factor
    instead of the tall matrix: Golub & Van Loan 2013, sections 5.4-5.5.
    """
    a = r[:, cols]
    b = r[:, rhs_cols]
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    if rcond is None:
        rcond = np.finfo(float).eps * max(n_rows, a.shape[1])
    keep = s > rcond * s[0] if s.size and s[0] > 0 else np.zeros(s.shape, bool)
    theta = vt[keep].T @ ((u[:, keep].T @ b) / s[keep, None])
    res = b - a @ theta
    return LeastSquares(theta, int(keep.sum()), s, res.T @ res, vt[keep])


def _condition(s: np.ndarray) -> float:
    return float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")


def block_condition(r: np.ndarray, k: int) -> float:
    """Condition number of the first ``k`` columns of ``M``, from its factor ``R``.

    The leading ``k x k`` block of ``R`` is the triangular factor of those
    columns alone, so this costs one tiny SVD (``inf`` when singular).

    Examples
    --------
    >>> round(block_condition(np.linalg.qr(np.diag([1.0, 4.0, 0.0]), mode="r"), 2), 12)
    4.0
    """
    return _condition(np.linalg.svd(r[:k, :k], compute_uv=False))


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
        Excitation limit (:func:`lti_motion.excitation.check_excitation`).

    Returns
    -------
    FirFit
        With ``delay + n_taps`` taps and the residual covariance
        ``E^T E / (N - 2 n_taps)``.

    Raises
    ------
    ShapeError, NonFiniteError
        For malformed runs (:func:`lti_motion.excitation.check_runs`).
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
               n_taps, ls.rank, _condition(ls.singular_values), cond_u)
    return FirFit(taps=taps, residual_cov=ls.rss / (n_rows - ls.rank), n_samples=n_rows,
                  source="lstsq", condition_number=_condition(ls.singular_values))


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


def markov_parameters(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, n: int
) -> np.ndarray:
    """Impulse response ``H[0] = D``, ``H[i] = C A^(i-1) B`` of a state-space model.

    Returns
    -------
    ndarray, shape (n, ny, nu)

    Examples
    --------
    >>> markov_parameters(np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]),
    ...                   np.array([[0.0]]), 4)[:, 0, 0].tolist()
    [0.0, 1.0, 0.5, 0.25]
    """
    h = np.empty((n, c.shape[0], b.shape[1]))
    if n == 0:
        return h
    h[0] = d
    g = b
    for i in range(1, n):
        h[i] = c @ g
        g = a @ g
    return h


def _block_operators(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, length: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Toeplitz (L nu, L ny), input-to-end-state (L nu, nz), and state-to-output (nz, L ny)."""
    nz, nu, ny = a.shape[0], b.shape[1], c.shape[0]
    obs = np.empty((length, ny, nz))  # C A^i
    ctr = np.empty((length, nz, nu))  # A^i B
    obs[0], ctr[0] = c, b
    for i in range(1, length):
        np.matmul(obs[i - 1], a, out=obs[i])
        np.matmul(a, ctr[i - 1], out=ctr[i])
    # Markov parameters H[k] = C A^(k-1) B, stored transposed after length - 1 zeros:
    # padded[length - 1 + k] = H[k]^T, so row block m of the Toeplitz matrix,
    # H[i - m]^T for i >= m and zero before, is the window padded[length - 1 - m:][:length]
    padded = np.zeros((2 * length - 1, nu, ny))
    padded[length - 1] = d.T
    padded[length:] = np.einsum("yz,izu->iuy", c, ctr[:-1])
    windows = np.lib.stride_tricks.sliding_window_view(padded, length, axis=0)  # (s, u, y, i)
    toep = windows[::-1].transpose(0, 1, 3, 2).reshape(length * nu, length * ny)
    to_state = ctr[::-1].transpose(0, 2, 1).reshape(length * nu, nz)  # A^(L-1-m) B
    from_state = obs.transpose(2, 0, 1).reshape(nz, length * ny)
    return toep, to_state, from_state


def _prepare(a, b, c, d, u, z0):
    a, b, c, d = (np.asarray(x, dtype=float) for x in (a, b, c, d))
    nz = a.shape[0]
    if a.shape != (nz, nz) or b.shape[0] != nz or c.shape[1] != nz or d.shape != (
        c.shape[0], b.shape[1]
    ):
        raise ShapeError(f"inconsistent state-space shapes A {a.shape}, B {b.shape}, "
                         f"C {c.shape}, D {d.shape}")
    u = np.asarray(u, dtype=float)
    if u.ndim < 2 or u.shape[-1] != b.shape[1]:
        raise ShapeError(f"expected u of shape (..., n, {b.shape[1]}), got {u.shape}")
    lead = u.shape[:-2]
    z = np.zeros((*lead, nz)) if z0 is None else np.asarray(z0, dtype=float)
    if z.shape[-1:] != (nz,):
        raise ShapeError(f"expected z0 of shape (..., {nz}), got {z.shape}")
    return a, b, c, d, u, np.broadcast_to(z, (*lead, nz)).copy()


def simulate_state_space(
    a: np.ndarray,
    b: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    u: np.ndarray,
    *,
    z0: np.ndarray | None = None,
    block_len: int = 128,
) -> tuple[np.ndarray, np.ndarray]:
    """Run ``z[n+1] = A z + B u``, ``y = C z + D u`` over a whole sequence, vectorised.

    Parameters
    ----------
    a, b, c, d : ndarray
        ``(nz, nz)``, ``(nz, nu)``, ``(ny, nz)``, ``(ny, nu)``.
    u : ndarray, shape (..., n, nu)
        Inputs; leading axes are independent sequences (for example robots).
    z0 : ndarray, shape (nz,) or (..., nz), optional
        Initial state; zeros by default.
    block_len : int
        Samples per block.

    Returns
    -------
    y : ndarray, shape (..., n, ny)
    z_end : ndarray, shape (..., nz)
        The state after the last input, ``z[n]``.

    Notes
    -----
    Splits the sequence into blocks of ``L`` samples. Within block ``k``
    starting at state ``s_k``,
    ``y[kL + i] = C A^i s_k + sum_{j <= i} H[i - j] u[kL + j]`` with the
    Markov parameters ``H`` (a block-Toeplitz matrix product), and
    ``s_{k+1} = A^L s_k + sum_j A^(L-1-j) B u[kL + j]``. Only the last
    recursion runs in Python, once per block; everything else is one matrix
    product over all blocks. The sums are the same as those of the plain
    recursion (:func:`simulate_state_space_loop`), grouped differently.

    Examples
    --------
    >>> a, b, c, d = np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])
    >>> simulate_state_space(a, b, c, d, np.ones((4, 1)))[0][:, 0].tolist()
    [0.0, 1.0, 1.5, 1.75]
    """
    a, b, c, d, u, z = _prepare(a, b, c, d, u, z0)
    lead, (n, nu) = u.shape[:-2], u.shape[-2:]
    ny, nz = c.shape[0], a.shape[0]
    if n == 0:
        return np.empty((*lead, 0, ny)), z
    length = max(1, min(int(block_len), n))
    n_blocks = -(-n // length)
    pad = n_blocks * length - n
    if pad:
        u = np.concatenate([u, np.zeros((*lead, pad, nu))], axis=-2)
    ub = u.reshape(*lead, n_blocks, length * nu)
    toep, to_state, from_state = _block_operators(a, b, c, d, length)
    forced = ub @ to_state  # (..., n_blocks, nz)
    a_len_t = np.linalg.matrix_power(a, length).T
    starts = np.empty((*lead, n_blocks, nz))
    for k in range(n_blocks):  # the only sequential part: one small product per block
        starts[..., k, :] = z
        z = z @ a_len_t + forced[..., k, :]
    y = ub @ toep + starts @ from_state
    y = y.reshape(*lead, n_blocks * length, ny)[..., :n, :]
    if pad:  # the state after the last real input, not after the padding
        rest = length - pad
        z = starts[..., -1, :] @ np.linalg.matrix_power(a, rest).T + ub[..., -1, : rest * nu] @ (
            to_state[pad * nu :]
        )
    return y, z


def simulate_state_space_loop(
    a: np.ndarray,
    b: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    u: np.ndarray,
    *,
    z0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Reference simulation: the plain recursion, one sample at a time.

    Same interface and result as :func:`simulate_state_space` (to rounding);
    slow, kept as the definition the fast path is tested against.

    Examples
    --------
    >>> a, b, c, d = np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])
    >>> simulate_state_space_loop(a, b, c, d, np.ones((4, 1)))[0][:, 0].tolist()
    [0.0, 1.0, 1.5, 1.75]
    """
    a, b, c, d, u, z = _prepare(a, b, c, d, u, z0)
    y = np.empty((*u.shape[:-1], c.shape[0]))
    for k in range(u.shape[-2]):
        y[..., k, :] = z @ c.T + u[..., k, :] @ d.T
        z = z @ a.T + u[..., k, :] @ b.T
    return y, z
