"""The model EKF's per-step arithmetic, compiled (numba): the prediction and the encoder update.

One :meth:`fusion.ekf.ModelEKF.predict` and one encoder update are a few
thousand multiply-adds on ``n = nz + 8`` (``+ 2`` with a gyro) states; done as
numpy calls they cost many times their arithmetic in per-call overhead
(``docs/ekf.md``, *The compiled step*). These kernels evaluate the same
expressions as explicit loops; their sums run in another order than numpy's
(BLAS) products, so they agree with them to rounding
(``tests/fusion/ekf/test_kernel.py``). The maths, its derivation and its
references are in :mod:`fusion.ekf.functions`; this module only evaluates:

- :func:`predict_terms_kernel`: ``x' = f(x, u)``, the pose rows of ``F`` and
  ``Q = G2 blkdiag(R, R_slip) G2^T + Q_c`` (:func:`~fusion.ekf.predict_terms`);
- :func:`predict_kernel`: that, then ``P' = F P F^T + Q``, symmetrised
  (Bar-Shalom, Li & Kirubarajan 2001, eq. 5.2.3-5), skipping ``F``'s zeros
  (adding an exact zero changes no rounding);
- :func:`selector_update_kernel`: the gated update of a 2-D reading of the
  last two states (``H = [0 I]``, the speed state): ``S`` from ``P``'s corner
  plus ``R``, its closed-form inverse, the NIS, and if it is inside the gate
  (or forced) ``K = P H^T S^-1``, ``x + K y`` and the Joseph form
  (eq. 5.2.3-18) by associativity.

Both covariances are computed on their lower triangle and mirrored: the
products are symmetric in exact arithmetic, so this changes them by rounding
only, and halves the work.

Numba compiles each kernel on its first call and caches the machine code
beside this file (``cache=True``); importing the module compiles nothing.
The constants come from :class:`~fusion.ekf.FilterModel`
(``kernel_constants``; ``nz`` and the layout follow from their shapes). A
kernel is compiled once per combination of argument types: the library passes
C-contiguous, writable float64 arrays (:func:`kernel_array` makes one of
anything else), so one compilation serves every layout. Numba's cache tracks
this file only: the series of ``sin(h)/h`` imported from
:mod:`lti_motion.kinematics` is frozen into the cached code (the test against
the numpy reference would catch a stale one).

References
----------
The paper: ``docs/architecture.md``, "The paper".
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, eqs. 5.2.3-5, 5.2.3-9, 5.2.3-18.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from lti_motion.kinematics import _DSINC_SERIES, _SERIES_BELOW

__all__ = ["N_SCALARS", "kernel_array", "predict_kernel", "predict_terms_kernel",
           "selector_update_kernel"]

# --- columns of the scalar constants (FilterModel.kernel_constants[0]) -------------------------
DT, V_FLOOR, V_FRAC, W_FLOOR, W_FRAC, W_PER_V, R0 = range(7)     # R: R0 .. R0 + 3, row-major
N_SCALARS = 10
_Z0 = 6                       # the pose and the three scale errors come first
_DSINC_REVERSED = tuple(reversed(_DSINC_SERIES))


def kernel_array(arr: np.ndarray) -> np.ndarray:
    """``arr`` if it is a C-contiguous, writable float64 array, else such a copy.

    The kernels are compiled for that one array type; a read-only or strided
    argument would compile (and cache) them a second time.
    """
    flags = arr.flags
    return (arr if flags.c_contiguous and flags.writeable and arr.dtype == np.float64
            else np.array(arr, dtype=float))


@njit(cache=True)
def _sinc_and_derivative(h):
    """``sin(h) / h`` and its derivative: :func:`lti_motion.kinematics.sinc_and_derivative`."""
    value = math.sin(h) / h if h != 0.0 else 1.0
    if abs(h) < _SERIES_BELOW:
        ds = 0.0
        for coeff in _DSINC_REVERSED:
            ds = ds * h * h + coeff
        return value, ds * h
    return value, (h * math.cos(h) - math.sin(h)) / (h * h)


@njit(cache=True)
def predict_terms_kernel(x, cmd, accumulate, scalars, ABo, G_template, Q_const, F, Q):
    """``x' = f(x, u)``; writes ``F``'s pose rows and speed diagonal, and all of ``Q``.

    ``scalars`` holds ``dt_s``, the slip parameters and ``R`` (columns
    :data:`DT` ... :data:`R0`); ``ABo`` is ``[[A, B, 0], [C, D, offset]]``,
    shape ``(nz + 2, nz + 3)``. ``F`` must hold the constant blocks already
    (``FilterModel.F_template`` or an earlier ``F`` of the same layout).
    Returns ``x'`` (a new array). The expressions are those of
    :func:`fusion.ekf.predict_terms` (module notes there: paper eq. 11
    in chord form, ``F``, ``G2``, ``Q``).
    """
    n = x.shape[0]
    nz = ABo.shape[0] - 2
    z0 = n - nz - 2
    dt = scalars[DT]
    x_new = np.empty(n)
    for i in range(nz + 2):                       # (A z + B u, C z + D u) + offset
        acc = 0.0
        for j in range(nz):
            acc += ABo[i, j] * x[z0 + j]
        acc = acc + (ABo[i, nz] * cmd[0] + ABo[i, nz + 1] * cmd[1])
        if i >= nz:
            acc += ABo[i, nz + 2]
        x_new[z0 + i] = acc
    v, w = x_new[z0 + nz], x_new[z0 + nz + 1]
    if accumulate:
        x_new[n - 2] += x[n - 2]
        x_new[n - 1] += x[n - 1]
    for i in range(_Z0, z0):                      # gyro bias and heading clone kept
        x_new[i] = x[i]
    px, py, theta, k_v, k_w, kappa = x[0], x[1], x[2], x[3], x[4], x[5]
    c_v, c_w = 1.0 + k_v, 1.0 + k_w
    vg, wg = c_v * v, c_w * w + kappa * v          # ground speeds g = D_c s
    h = 0.5 * wg * dt
    sinc, dsinc = _sinc_and_derivative(h)
    mid = theta + h
    cm, sm = math.cos(mid), math.sin(mid)
    chord = vg * dt * sinc                          # paper eq. 11, chord form
    x_new[0], x_new[1], x_new[2] = px + chord * cm, py + chord * sm, theta + 2.0 * h
    x_new[3], x_new[4], x_new[5] = k_v, k_w, kappa
    k = 0.5 * vg * dt * dt
    a, b = dt * sinc * cm, k * (dsinc * cm - sinc * sm)       # F_s = d pose / d g
    c, d = dt * sinc * sm, k * (dsinc * sm + sinc * cm)
    g2 = G_template.copy()                          # G2 = [[F_s D_c, F_s], ...]
    g2[0, 0], g2[0, 1], g2[0, 2], g2[0, 3] = a * c_v + b * kappa, b * c_w, a, b
    g2[1, 0], g2[1, 1], g2[1, 2], g2[1, 3] = c * c_v + d * kappa, d * c_w, c, d
    g2[2, 0], g2[2, 1], g2[2, 2], g2[2, 3] = dt * kappa, dt * c_w, 0.0, dt
    F[0, 0], F[0, 1], F[0, 2] = 1.0, 0.0, -chord * sm      # [F_p, F_s D_s]
    F[0, 3], F[0, 4], F[0, 5] = a * v, b * w, b * v
    F[1, 0], F[1, 1], F[1, 2] = 0.0, 1.0, chord * cm
    F[1, 3], F[1, 4], F[1, 5] = c * v, d * w, d * v
    F[2, 0], F[2, 1], F[2, 2] = 0.0, 0.0, 1.0
    F[2, 3], F[2, 4], F[2, 5] = 0.0, dt * w, dt * v
    for i in range(3):                              # F_s D_c C
        for j in range(nz):
            F[i, z0 + j] = g2[i, 0] * ABo[nz, j] + g2[i, 1] * ABo[nz + 1, j]
    r = 1.0 if accumulate else 0.0
    F[n - 2, n - 2] = r
    F[n - 1, n - 1] = r
    av = abs(v)                                     # SlipNoise.stds
    sv = scalars[V_FLOOR] + scalars[V_FRAC] * av
    sw = scalars[W_FLOOR] + scalars[W_FRAC] * abs(w) + scalars[W_PER_V] * av
    sv2, sw2 = sv * sv, sw * sw
    r00, r01, r10, r11 = scalars[R0], scalars[R0 + 1], scalars[R0 + 2], scalars[R0 + 3]
    gw = np.empty((n, 4))                           # G2 blkdiag(R, R_slip)
    for i in range(n):
        gw[i, 0] = g2[i, 0] * r00 + g2[i, 1] * r10
        gw[i, 1] = g2[i, 0] * r01 + g2[i, 1] * r11
        gw[i, 2] = g2[i, 2] * sv2
        gw[i, 3] = g2[i, 3] * sw2
    for i in range(n):                              # ... G2^T + Q_c
        for j in range(i + 1):
            q = (gw[i, 0] * g2[j, 0] + gw[i, 1] * g2[j, 1] + gw[i, 2] * g2[j, 2]
                 + gw[i, 3] * g2[j, 3]) + Q_const[i, j]
            Q[i, j] = q
            Q[j, i] = q
    return x_new


@njit(cache=True)
def _propagate(P, F, Q):
    """``F P F^T + Q``, symmetrised (eq. 5.2.3-5), over ``F``'s non-zero entries only.

    With ``P`` symmetric, ``(F P F^T)_ij = sum_k F_ik (F P)_jk``: the lower
    triangle is computed that way and mirrored.
    """
    n = P.shape[0]
    fp = np.zeros((n, n))                           # F P
    for i in range(n):
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    fp[i, j] += f * P[k, j]
    out = np.zeros((n, n))                          # F (F P)^T, lower triangle
    for i in range(n):
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(i + 1):
                    out[i, j] += f * fp[j, k]
    for i in range(n):                              # + Q, mirrored
        for j in range(i + 1):
            v = out[i, j] + Q[i, j]
            out[i, j] = v
            out[j, i] = v
    return out


@njit(cache=True)
def predict_kernel(x, P, cmd, accumulate, scalars, ABo, G_template, Q_const, F, Q):
    """:func:`predict_terms_kernel`, then ``P' = F P F^T + Q`` symmetrised; returns ``(x', P')``."""
    x_new = predict_terms_kernel(x, cmd, accumulate, scalars, ABo, G_template, Q_const, F, Q)
    return x_new, _propagate(P, F, Q)


@njit(cache=True)
def selector_update_kernel(x, P, innovation, R, gate, force):
    """Gate and fuse a 2-D reading of the last two states (``H = [0 I]``), Joseph form.

    Returns ``(ok, S, SI, nis, accepted, K, x', P')``. ``ok`` is False when ``S``
    has no positive finite determinant (the caller then takes the generic numpy
    path, ``np.linalg.inv``); when the reading is not accepted, ``K`` is zeros
    and ``x'``, ``P'`` are empty (the state stays as it is).
    """
    n = x.shape[0]
    m0 = n - 2
    S = np.empty((2, 2))                            # H P H^T + R (eq. 5.2.3-9)
    S[0, 0] = P[m0, m0] + R[0, 0]
    S[0, 1] = P[m0, m0 + 1] + R[0, 1]
    S[1, 0] = P[m0 + 1, m0] + R[1, 0]
    S[1, 1] = P[m0 + 1, m0 + 1] + R[1, 1]
    SI = np.empty((2, 2))
    K = np.zeros((n, 2))
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    if not (det > 0.0 and math.isfinite(det)):
        return False, S, SI, math.nan, False, K, np.empty(0), np.empty((0, 0))
    f = 1.0 / det                                   # closed-form 2 x 2 inverse
    SI[0, 0], SI[0, 1], SI[1, 0], SI[1, 1] = S[1, 1] * f, -S[0, 1] * f, -S[1, 0] * f, S[0, 0] * f
    n0, n1 = innovation[0], innovation[1]
    nis = SI[0, 0] * n0 * n0 + (SI[0, 1] + SI[1, 0]) * n0 * n1 + SI[1, 1] * n1 * n1
    accepted = nis <= gate or force
    if not accepted:
        return True, S, SI, nis, False, K, np.empty(0), np.empty((0, 0))
    x_new = np.empty(n)
    for i in range(n):                              # K = P H^T S^-1, x + K y
        K[i, 0] = P[i, m0] * SI[0, 0] + P[i, m0 + 1] * SI[1, 0]
        K[i, 1] = P[i, m0] * SI[0, 1] + P[i, m0 + 1] * SI[1, 1]
        x_new[i] = x[i] + (K[i, 0] * n0 + K[i, 1] * n1)
    mh = np.empty((n, 2))                           # M H^T, the last columns of M
    for i in range(n):
        for a in range(2):
            j = m0 + a
            mh[i, a] = P[i, j] - (K[i, 0] * P[j, m0] + K[i, 1] * P[j, m0 + 1])
    kr = np.empty((n, 2))                           # K R
    for i in range(n):
        kr[i, 0] = K[i, 0] * R[0, 0] + K[i, 1] * R[1, 0]
        kr[i, 1] = K[i, 0] * R[0, 1] + K[i, 1] * R[1, 1]
    out = np.empty((n, n))                          # M - (M H^T) K^T + (K R) K^T (5.2.3-18)
    for i in range(n):                              # with M = (I - K H) P = P - K (P H^T)^T
        for j in range(i + 1):                      # symmetric: the lower triangle, mirrored
            mij = P[i, j] - (K[i, 0] * P[j, m0] + K[i, 1] * P[j, m0 + 1])
            v = ((mij - (mh[i, 0] * K[j, 0] + mh[i, 1] * K[j, 1]))
                 + (kr[i, 0] * K[j, 0] + kr[i, 1] * K[j, 1]))
            out[i, j] = v
            out[j, i] = v
    return True, S, SI, nis, True, K, x_new, out
