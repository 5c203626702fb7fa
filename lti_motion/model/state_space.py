"""State-space models simulated by their impulse response.

Every state-space model ``z[n+1] = A z + B u``, ``y = C z + D u`` has an impulse response
(its Markov parameters, :func:`markov_parameters`); :func:`simulate_state_space` runs a
model by convolving each block of commands with it and carrying the state across blocks,
which vectorises the simulation over samples (:func:`simulate_state_space_loop` is the
plain recursion, the reference it is tested against).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lti_motion.exceptions import ShapeError

__all__ = ["StateSpace", "markov_parameters", "simulate_state_space",
           "simulate_state_space_loop"]


class StateSpace(NamedTuple):
    """Matrices of ``z[n+1] = A z + B u + K e``, ``y[n] = C z + D u + e`` (innovations form)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray



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
