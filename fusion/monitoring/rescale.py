"""A motion model with a new encoder scale and wheel base, predicting the same wheel counts.

A :class:`~lti_motion.model.MotionModel` predicts *encoder* body speeds
``y = (v, w)``: count changes times ``m_per_tick / dt_s``, combined with the
wheel base (paper eq. 11 and 13). On a new floor the wheel servos still
turn the wheels as commanded (the encoders count rotation), but the ground
moves by another distance per tick; a new ``m_per_tick`` (and, for turns, an
effective wheel base) converts counts to ground travel. Changing only those
two numbers would make the model's predictions disagree with the counts
converted by them; the outputs must be rescaled with them.

With ``m``, ``b`` the old and ``m'``, ``b'`` the new scale and wheel base,
the same counts give::

    v' = (m' / m) v,      w' = (m' b / (m b')) w,      y' = S y,
    S = diag(m' / m, m' b / (m b'))                                       (eq. 1)

An output scaling of the innovations-form state space ``z+ = A z + B u + K e``,
``y = C z + D u + e`` keeps the state and scales output, innovation and its
covariance (a similarity transform on the output space, Ljung 1999, section
4.3): ``C' = S C``, ``D' = S D``, ``K' = K S^-1``, ``R' = S R S``; ``A``,
``B`` and ``Q = alpha K R K^T`` are unchanged (eq. 2). The raw coefficients
follow: ARX ``A_k' = S A_k S^-1``, ``B_j' = S B_j``; FIR taps ``S h_i``, the
residual AR model ``S Phi_k S^-1``. The one-step predictor ``A - K C``, and so
every count a filter or monitor predicts from the model, is unchanged; the free-run
fit [%] of each channel is unchanged too (both measured and predicted speeds scale).

References
----------
The paper: ``docs/architecture.md``, "The paper".
Ljung, L. (1999). System Identification: Theory for the User, 2nd ed.,
section 4.3 (innovations form) and section 4.6 (similarity transforms).
"""

from __future__ import annotations

import math

import numpy as np

from fusion.exceptions import FilterOptionError
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel

__all__ = ["output_scaling", "rescaled_model"]


def output_scaling(model: MotionModel, *, m_per_tick: float, wheel_base_m: float) -> np.ndarray:
    """The diagonal ``S`` (eq. 1) that takes the model's outputs to the new scale and wheel base.

    Parameters
    ----------
    model : MotionModel
        The model in use; needs ``m_per_tick``.
    m_per_tick : float
        New encoder scale [m/tick].
    wheel_base_m : float
        New (effective) wheel base [m].

    Returns
    -------
    ndarray, shape (2,)
        ``(s_v, s_w)``.

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale.
    FilterOptionError
        If the new values are not positive and finite.

    Examples
    --------
    A carpet: 3.5% less ground per tick, turns 5% short (effective wheel base
    ``b 0.965 / 0.95``):

    >>> import numpy as np
    >>> from lti_motion.model.motion_model import MotionModel
    >>> m = MotionModel(kind="arx", A=0.5 * np.eye(2), B=np.eye(2), C=np.eye(2),
    ...                 D=np.zeros((2, 2)), K=0.5 * np.eye(2), Q=np.eye(2), R=np.eye(2),
    ...                 dt_s=0.015, wheel_base_m=0.235, m_per_tick=5e-4,
    ...                 coefficients={}, orders={}, calibrated_at="2026-01-01T00:00:00")
    >>> output_scaling(m, m_per_tick=0.965 * 5e-4, wheel_base_m=0.235 * 0.965 / 0.95).round(3)
    array([0.965, 0.95 ])
    """
    if model.m_per_tick is None:
        raise MissingEncoderScaleError.needed_by("rescaling the model to a new encoder scale")
    if not (math.isfinite(m_per_tick) and m_per_tick > 0 and math.isfinite(wheel_base_m)
            and wheel_base_m > 0):
        raise FilterOptionError(f"m_per_tick and wheel_base_m must be positive and finite, got "
                                f"{m_per_tick} and {wheel_base_m}")
    s_v = m_per_tick / model.m_per_tick
    return np.array([s_v, s_v * model.wheel_base_m / wheel_base_m])           # eq. 1


def rescaled_model(model: MotionModel, *, m_per_tick: float, wheel_base_m: float
                   ) -> MotionModel:
    """A copy of ``model`` with a new encoder scale and wheel base, predicting the same counts.

    Parameters
    ----------
    model : MotionModel
        The model in use; needs ``m_per_tick``.
    m_per_tick : float
        New encoder scale [m/tick] (ground travel per tick).
    wheel_base_m : float
        New effective wheel base [m].

    Returns
    -------
    MotionModel
        Outputs scaled by ``S`` (eq. 2); ``diagnostics["rescaled_v"]`` and
        ``["rescaled_w"]`` hold the two factors of ``S`` (multiplied over
        successive rescalings).

    Raises
    ------
    FilterOptionError
        As :func:`output_scaling`.

    Examples
    --------
    >>> import numpy as np
    >>> from lti_motion.model.motion_model import MotionModel
    >>> m = MotionModel(kind="arx", A=0.5 * np.eye(2), B=np.eye(2), C=np.eye(2),
    ...                 D=np.zeros((2, 2)), K=0.5 * np.eye(2), Q=np.eye(2), R=np.eye(2),
    ...                 dt_s=0.015, wheel_base_m=0.235, m_per_tick=5e-4,
    ...                 coefficients={}, orders={}, calibrated_at="2026-01-01T00:00:00")
    >>> new = rescaled_model(m, m_per_tick=4.8e-4, wheel_base_m=0.235)
    >>> np.diag(new.C).round(3).tolist(), np.allclose(new.A - new.K @ new.C, m.A - m.K @ m.C)
    ([0.96, 0.96], True)
    """
    s = output_scaling(model, m_per_tick=m_per_tick, wheel_base_m=wheel_base_m)
    S, S_inv = np.diag(s), np.diag(1.0 / s)
    r = S @ model.R @ S
    coef = {}
    for name, arr in model.coefficients.items():
        arr = np.asarray(arr, dtype=float)
        if name in ("a", "noise_a"):                 # output lags: S A_k S^-1
            coef[name] = S @ arr @ S_inv if arr.size else arr
        elif name in ("b", "taps"):                  # input lags: S B_j
            coef[name] = S @ arr if arr.size else arr
        else:
            coef[name] = arr
    diag = dict(model.diagnostics)
    diag["rescaled_v"] = diag.get("rescaled_v", 1.0) * float(s[0])
    diag["rescaled_w"] = diag.get("rescaled_w", 1.0) * float(s[1])
    return model.updated(C=S @ model.C, D=S @ model.D, K=model.K @ S_inv,           # eq. 2
                         R=0.5 * (r + r.T), coefficients=coef, m_per_tick=float(m_per_tick),
                         offset_speeds=S @ model.offset_speeds,
                         wheel_base_m=float(wheel_base_m), diagnostics=diag)
