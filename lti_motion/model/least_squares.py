"""Least squares on lagged data, shared by the FIR and ARX fits (paper eq. 12).

The regression matrix of a tall data set is reduced to its triangular factor (QR in
chunks), then solved by SVD with a relative singular-value cut-off, so a poorly excited
direction is reported (rank, condition number) instead of amplified (Golub & Van Loan
2013, section 5.5).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = [
    "LeastSquares",
    "block_condition",
    "condition_number",
    "lagged_columns",
    "qr_r_factor",
    "regression_matrix",
    "svd_least_squares",
]


class LeastSquares(NamedTuple):
    """Solution of a least-squares problem given by its triangular factor."""

    theta: np.ndarray  #: (p, k) minimum-norm solution
    rank: int  #: numerical rank of the regression matrix
    singular_values: np.ndarray  #: (p,) of the (scaled) regression matrix
    rss: np.ndarray  #: (k, k) residual cross-product E^T E
    vt: np.ndarray  #: (rank, p) right singular vectors kept



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


def condition_number(s: np.ndarray) -> float:
    """Ratio of the largest to the smallest singular value (``inf`` for a singular matrix)."""
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
    return condition_number(np.linalg.svd(r[:k, :k], compute_uv=False))


