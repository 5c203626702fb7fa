"""One motion model for both seed models: a discrete state space with honest noise.

Both of the paper's models are linear and time-invariant, so both become

.. math::

    z[n+1] = A z[n] + B u[n] + K e[n], \\qquad y[n] = C z[n] + D u[n] + e[n]

with commands ``u = (L, R)`` [m/s], body speeds ``y = (v [m/s], w [rad/s])``
and ``e`` white with covariance ``R``: the *innovations form* (Ljung 1999,
section 4.3). The FIR model is a shift register of past commands
(:func:`~lti_motion.model.fir_state_space`), the ARX model its observable
canonical realisation (:func:`~lti_motion.model.arx_state_space`).
:class:`MotionModel` holds the matrices, the noise covariances ``Q`` and
``R``, and the calibration's metadata; everything downstream (EKF, factor
graph, monitor) speaks only this interface.

Modes of use (paper section III.C and IV): :meth:`MotionModel.simulate`
is the sensor-less free run (commands only); :meth:`MotionModel.predict_one_step`
is the hybrid filter mode (past outputs are the measured ones);
:meth:`MotionModel.predict_poses` integrates the predicted speeds (paper eq. 11).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

import numpy as np

from lti_motion.exceptions import (
    CalibrationError,
    MissingEncoderScaleError,
    ModelFileError,
    NonFiniteError,
    ShapeError,
    UnstableModelError,
)
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import integrate_poses
from lti_motion.metrics import fit_percent
from lti_motion.model.arx import (
    ArxFit,
    ArxSelection,
    arx_state_space,
    estimate_arx,
    free_run_errors,
    one_step_predictor,
    select_arx,
    split_runs,
)
from lti_motion.model.arx_structure import (
    output_scales,
    restrict_dc_gain,
    scale_outputs,
    servo_dc_gain,
)
from lti_motion.model.excitation import DEFAULT_MAX_CONDITION, StepSequence, check_runs
from lti_motion.model.fir import FirFit, fir_state_space
from lti_motion.model.fir_steps import fir_from_steps
from lti_motion.model.state_space import StateSpace, simulate_state_space
from lti_motion.odometry_errors import OdometryErrors
from lti_motion.persistence import decode_array, encode_array, read_document, write_document

__all__ = [
    "COVARIANCE_JITTER",
    "FORMAT",
    "READ_VERSIONS",
    "VERSION",
    "MotionModel",
    "fit_arx",
    "fit_fir_from_steps",
    "noise_covariances",
    "output_error_covariances",
    "q_scale_from_errors",
]

_log = logging.getLogger(__name__)

#: Added to the diagonals of ``Q`` and ``R`` so both are positive definite:
#: a standard deviation of 1e-6 (m/s or rad/s), far below encoder resolution.
COVARIANCE_JITTER = 1e-12
#: Format name and version of saved models. Version 2 adds ``"intrinsics"`` (each
#: wheel's scale and the wheel base, or null) and ``"offset_speeds"`` (the affine term of
#: the speeds); version 1 files are still read (no intrinsics, a zero offset).
FORMAT = "lti-motion/motion-model"
VERSION = 2
READ_VERSIONS = (1, 2)


def noise_covariances(k: np.ndarray, r: np.ndarray, *, q_scale: float = 1.0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Process and output noise covariances of an innovations-form model.

    Parameters
    ----------
    k : ndarray, shape (nz, 2)
        Innovation gain.
    r : ndarray, shape (2, 2)
        Innovation (one-step residual) covariance.
    q_scale : float
        Model-error inflation ``alpha >= 1`` (:func:`q_scale_from_errors`).

    Returns
    -------
    Q : ndarray, shape (nz, nz)
        ``alpha K R K^T + jitter I``.
    R : ndarray, shape (2, 2)
        ``r + jitter I``, symmetrised.

    Examples
    --------
    >>> q, r = noise_covariances(np.array([[0.5, 0.0], [0.0, 0.5]]), np.eye(2) * 1e-4)
    >>> bool(np.allclose(q, np.eye(2) * 2.5e-5))
    True
    """
    r = 0.5 * (r + r.T) + COVARIANCE_JITTER * np.eye(2)
    q = q_scale * (k @ r @ k.T)
    q = 0.5 * (q + q.T) + COVARIANCE_JITTER * np.eye(len(k))
    return q, r


def output_error_covariances(a: np.ndarray, c: np.ndarray, q: np.ndarray, r: np.ndarray,
                             n_steps: int) -> np.ndarray:
    """Covariance of the free-run output error ``h`` steps after a known state.

    Returns
    -------
    ndarray, shape (n_steps, ny, ny)
        ``S_h = C P_h C^T + R`` with ``P_0 = 0``, ``P_{h+1} = A P_h A^T + Q``
        (Kalman 1960 prediction without measurements).
    """
    out = np.empty((n_steps, c.shape[0], c.shape[0]))
    p = np.zeros_like(a)
    for h in range(n_steps):
        out[h] = c @ p @ c.T + r
        p_next = a @ p @ a.T + q
        if h > 8 and np.allclose(p_next, p, rtol=1e-12, atol=0.0):
            out[h + 1 :] = c @ p_next @ c.T + r  # converged to the stationary value
            break
        p = p_next
    return out


def q_scale_from_errors(ss: StateSpace, r: np.ndarray, errors: Sequence[np.ndarray]) -> float:
    """Inflation ``alpha >= 1`` of ``K R K^T`` that explains measured free-run errors.

    Parameters
    ----------
    ss : StateSpace
        The model (``A``, ``C``, ``K`` are used).
    r : ndarray, shape (2, 2)
        Innovation covariance.
    errors : sequence of ndarray, shape (n_i, 2)
        Free-run errors, each run starting from a known state
        (:func:`~lti_motion.model.free_run_errors`).

    Returns
    -------
    float
        Per channel, ``alpha_c = (sum e_c^2 - N R_cc) / sum_h N_h (C P_h C^T)_cc``
        with ``P_h`` propagated from ``Q = K R K^T`` and ``N_h`` the number of
        runs that reach horizon ``h``; the result is ``max(1, alpha_v, alpha_w)``.
    """
    lengths = np.array([len(e) for e in errors])
    if lengths.size == 0 or lengths.max() == 0:
        return 1.0
    g = output_error_covariances(ss.A, ss.C, ss.K @ r @ ss.K.T, np.zeros((2, 2)),
                                 int(lengths.max()))
    reach = (lengths[:, None] > np.arange(lengths.max())[None, :]).sum(axis=0)
    expected_model = np.einsum("h,hcc->c", reach, g)
    measured = sum(np.sum(e * e, axis=0) for e in errors)
    excess = measured - lengths.sum() * np.diag(r)
    ok = expected_model > 1e-300
    alpha = excess[ok] / expected_model[ok]
    return float(max(1.0, *alpha)) if alpha.size else 1.0


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class MotionModel:
    """A calibrated LTI motion model in state-space (innovations) form.

    Attributes
    ----------
    kind : {"fir", "arx"}
        Which seed model it realises.
    A, B, C, D : ndarray
        ``(nz, nz)``, ``(nz, 2)``, ``(2, nz)``, ``(2, 2)``.
    K : ndarray, shape (nz, 2)
        Innovation gain: how the one-step error ``e`` enters the state.
    Q : ndarray, shape (nz, nz)
        Process-noise covariance of ``z``, symmetric positive definite.
    R : ndarray, shape (2, 2)
        Output (innovation) noise covariance [(m/s)^2, (rad/s)^2], SPD.
    dt_s : float
        Sample period [s].
    wheel_base_m : float
        Wheel base [m].
    coefficients : mapping of str to ndarray
        Raw coefficients: ``{"a", "b"}`` (ARX, :class:`~lti_motion.model.ArxFit`
        layout) or ``{"taps", "noise_a"}`` (FIR taps and the residual AR model).
    orders : mapping of str to int
        ``{"na", "nb", "delay"}`` or ``{"n_taps", "noise_order"}``.
    calibrated_at : str
        ISO 8601 time of the calibration.
    m_per_tick : float or None
        Encoder scale [m/tick] (paper eq. 13), when measured.
    intrinsics : OdometryIntrinsics or None
        Each wheel's scale and the wheel base (:mod:`lti_motion.calibration.intrinsics_fit`),
        when calibrated against a pose reference; :attr:`encoder_intrinsics` falls back
        on ``m_per_tick`` and ``wheel_base_m``.
    floor : str or None
        The surface the model was calibrated on.
    q_scale : float
        Model-error inflation ``alpha`` used in ``Q``.
    diagnostics : mapping of str to float
        Fit figures (validation fit [%], condition numbers, rank ...).
    selection : ArxSelection or None
        The order/delay selection curve (not saved to files).
    offset_speeds : ndarray, shape (2,)
        Affine output offset ``c`` = (v [m/s], w [rad/s]): the model predicts
        ``y = C z + D u + c`` (:mod:`lti_motion.model.output_error`); zeros for a
        linear model and for files of version 1.
    odometry_errors : OdometryErrors or None
        Encoder odometry's error model measured with :attr:`intrinsics` against a pose
        reference (:mod:`lti_motion.odometry_errors`): what its dead-reckoned pose
        covariance grows with. None when not measured (files without the key).

    Notes
    -----
    **Noise model.** ``e[n]`` is the part of ``y[n]`` the model cannot predict
    from the past: its covariance ``R`` is that of the one-step-ahead
    residuals on the calibration data (degrees-of-freedom corrected). For the
    ARX model the equation error enters the observable realisation through
    ``K = [A_1; ...; A_r]`` exactly (the same channel as the measured output);
    for the FIR model the residuals are modelled as a vector AR process whose
    states are appended (``K = [0; Phi_1; ...; Phi_p]``). The process noise
    is ``w = K e`` plus model error, so ``Q = alpha K R K^T`` (+ jitter): the
    free-run output error then has covariance ``C P_h C^T + R`` with
    ``P_{h+1} = A P_h A^T + Q`` (:meth:`output_error_covariance`), which is the
    growth the model's own noise filter ``I + C (qI - A)^-1 K`` implies (Ljung
    1999, sections 4.3 and 3.2). ``alpha >= 1`` is fitted on held-out free-run
    errors (:func:`q_scale_from_errors`) to cover what a linear model misses.

    Because ``w`` and ``e`` share ``e``, they are correlated:
    ``E[w e^T] = K R`` (:attr:`S`). A filter that updates with the encoder
    speeds must use it, or the equivalent uncorrelated form
    ``z[n+1] = (A - K C) z + (B - K D) u + K y_meas + w'`` with
    ``cov(w') = Q - K R K^T`` (Anderson & Moore 1979, chapter 5; Simon 2006,
    section 7.1). Sensor-less, ``C z + D u`` is the predicted speed and
    ``C P C^T + R`` its error covariance.

    Limits. The ARX noise filter ``A(q)^-1`` is exact when the disturbance
    enters as an equation error (then predicted and measured free-run
    covariances agree within sampling error). When the noise is white on the
    *outputs* (a perfectly linear plant measured with noisy encoders), ``R``
    holds that noise slightly coloured and ``C P C^T`` overstates the speed
    error: about 1.7x in variance on the test suite's synthetic plant, so a
    filter is conservative there, never over-confident (``alpha`` is never
    below 1). Splitting white measurement noise from propagating process noise
    needs more than one-step residuals (e.g. autocovariance least squares,
    Odelson, Rajamani & Rawlings 2006).

    Instances are immutable; :meth:`updated` returns a changed copy.
    """

    kind: Literal["fir", "arx"]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    dt_s: float
    wheel_base_m: float
    coefficients: Mapping[str, np.ndarray]
    orders: Mapping[str, int]
    calibrated_at: str
    m_per_tick: float | None = None
    floor: str | None = None
    q_scale: float = 1.0
    intrinsics: OdometryIntrinsics | None = None
    diagnostics: Mapping[str, float] = field(default_factory=dict)
    selection: ArxSelection | None = field(default=None, repr=False)
    offset_speeds: np.ndarray = field(default_factory=lambda: np.zeros(2))
    odometry_errors: OdometryErrors | None = None

    def __post_init__(self) -> None:
        setf = object.__setattr__
        if self.kind not in ("fir", "arx"):
            raise ValueError(f"kind must be 'fir' or 'arx', got {self.kind!r}")
        for name in "ABCDKQR":
            setf(self, name, _frozen(getattr(self, name)))
        nz = self.A.shape[0] if self.A.ndim == 2 else -1
        want = {"A": (nz, nz), "B": (nz, 2), "C": (2, nz), "D": (2, 2), "K": (nz, 2),
                "Q": (nz, nz), "R": (2, 2)}
        for name, shape in want.items():
            if getattr(self, name).shape != shape:
                raise ShapeError(f"MotionModel.{name} must have shape {shape} for "
                                 f"A {self.A.shape}, got {getattr(self, name).shape}")
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"MotionModel.{name} holds NaN or infinite values")
        for name in "QR":
            m = getattr(self, name)
            if not np.array_equal(m, m.T) or np.any(np.linalg.eigvalsh(m) <= 0):
                raise ValueError(f"MotionModel.{name} must be symmetric positive definite")
        for name in ("dt_s", "wheel_base_m", "q_scale"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"MotionModel.{name} must be positive and finite, got {value}")
            setf(self, name, value)
        if self.m_per_tick is not None:
            if not (np.isfinite(self.m_per_tick) and self.m_per_tick > 0):
                raise ValueError(f"m_per_tick must be positive or None, got {self.m_per_tick}")
            setf(self, "m_per_tick", float(self.m_per_tick))
        if self.intrinsics is not None and not isinstance(self.intrinsics, OdometryIntrinsics):
            raise ValueError(f"intrinsics must be an OdometryIntrinsics or None, got "
                             f"{type(self.intrinsics).__name__}")
        if self.odometry_errors is not None and not isinstance(self.odometry_errors,
                                                               OdometryErrors):
            raise ValueError(f"odometry_errors must be an OdometryErrors or None, got "
                             f"{type(self.odometry_errors).__name__}")
        setf(self, "offset_speeds", _frozen(self.offset_speeds))
        if self.offset_speeds.shape != (2,) or not np.all(np.isfinite(self.offset_speeds)):
            raise ValueError(f"offset_speeds must be 2 finite numbers (v [m/s], w [rad/s]), "
                             f"got {self.offset_speeds.tolist()}")
        datetime.fromisoformat(self.calibrated_at)  # ValueError if not ISO 8601
        mags = np.abs(np.linalg.eigvals(self.A)) if nz else np.zeros(0)
        if mags.size and mags.max() >= 1:
            raise UnstableModelError(f"MotionModel.A is unstable: pole magnitudes "
                                     f"{np.round(np.sort(mags)[::-1], 6).tolist()}")
        setf(self, "coefficients",
             MappingProxyType({k: _frozen(v) for k, v in self.coefficients.items()}))
        setf(self, "orders", MappingProxyType({k: int(v) for k, v in self.orders.items()}))
        diag = {k: float(v) for k, v in self.diagnostics.items()}
        if not all(np.isfinite(v) for v in diag.values()):
            raise ValueError(f"diagnostics must be finite numbers, got {diag}")
        setf(self, "diagnostics", MappingProxyType(diag))

    # -- structure -------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """State dimension ``nz``."""
        return self.A.shape[0]

    @property
    def encoder_intrinsics(self) -> OdometryIntrinsics | None:
        """The counts-to-travel mapping: :attr:`intrinsics`, else both wheels at
        ``m_per_tick`` with ``wheel_base_m``; None without an encoder scale."""
        if self.intrinsics is not None:
            return self.intrinsics
        if self.m_per_tick is None:
            return None
        return OdometryIntrinsics.symmetric(m_per_tick=self.m_per_tick,
                                            wheel_base_m=self.wheel_base_m)

    @property
    def S(self) -> np.ndarray:
        """Cross-covariance ``E[w e^T] = K R`` of process and output noise, (nz, 2)."""
        return self.K @ self.R

    @property
    def state_space(self) -> StateSpace:
        """``(A, B, C, D, K)``."""
        return StateSpace(self.A, self.B, self.C, self.D, self.K)

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A``."""
        return np.linalg.eigvals(self.A)

    def updated(self, **changes: Any) -> MotionModel:
        """A copy with some fields changed (validated again), e.g. ``m_per_tick``."""
        return dataclasses.replace(self, **changes)

    def with_intrinsics(self, intrinsics: OdometryIntrinsics, *,
                        odometry_errors: OdometryErrors | None = None) -> MotionModel:
        """A copy that maps counts with ``intrinsics`` and predicts the same counts.

        The outputs are encoder body speeds, ``y = J n / dt`` for tick increments
        ``n`` (:meth:`OdometryIntrinsics.jacobian`); new intrinsics give
        ``y' = T y`` with ``T = J' J^-1`` from the same counts, so the outputs
        are transformed by ``T`` (a similarity transform on the output space of
        the innovations form, Ljung 1999, section 4.6): ``C' = T C``, ``D' = T D``,
        ``K' = K T^-1``, ``R' = T R T^T``, the offset ``T c``, ARX ``A_k' = T A_k
        T^-1``, ``B_j' = T B_j`` (FIR taps ``T h_i``, noise AR ``T Phi_k T^-1``);
        ``A``, ``B`` and ``Q = alpha K R K^T`` are unchanged, and so is the one-step
        predictor ``A - K C``. For a diagonal ``T`` this is
        :func:`fusion.monitoring.rescaled_model`.

        Parameters
        ----------
        intrinsics : OdometryIntrinsics
            Each wheel's ground travel per tick and the wheel base, e.g. from
            :meth:`fusion.ekf.ModelEKF.intrinsics_estimate` or
            :func:`lti_motion.calibration.calibrate_intrinsics`.
        odometry_errors : OdometryErrors, optional
            The odometry error model measured with ``intrinsics``
            (``IntrinsicsCalibration.odometry_errors``); any the model held belonged to
            its old intrinsics and is dropped.

        Returns
        -------
        MotionModel
            ``intrinsics`` set, ``m_per_tick`` their mean, ``wheel_base_m`` theirs.

        Raises
        ------
        MissingEncoderScaleError
            If this model has no encoder scale (nothing to transform from).
        ValueError
            If ``intrinsics`` is not an :class:`OdometryIntrinsics`.
        """
        if not isinstance(intrinsics, OdometryIntrinsics):
            raise ValueError(f"intrinsics must be an OdometryIntrinsics, got "
                             f"{type(intrinsics).__name__}")
        old = self.encoder_intrinsics
        if old is None:
            raise MissingEncoderScaleError.needed_by("moving the model to new intrinsics")
        T = intrinsics.jacobian() @ np.linalg.inv(old.jacobian())
        T_inv = np.linalg.inv(T)
        coef = {}
        for name, arr in self.coefficients.items():
            arr = np.asarray(arr, dtype=float)
            if name in ("a", "noise_a") and arr.size:      # output lags: T A_k T^-1
                coef[name] = T @ arr @ T_inv
            elif name in ("b", "taps") and arr.size:       # input lags: T B_j
                coef[name] = T @ arr
            else:
                coef[name] = arr
        r = T @ self.R @ T.T
        return self.updated(C=T @ self.C, D=T @ self.D, K=self.K @ T_inv, R=0.5 * (r + r.T),
                            coefficients=coef, offset_speeds=T @ self.offset_speeds,
                            intrinsics=intrinsics, m_per_tick=intrinsics.m_per_tick,
                            wheel_base_m=intrinsics.wheel_base_m,
                            odometry_errors=odometry_errors)

    # -- prediction ------------------------------------------------------------------------
    def propagate(self, cmd_m_s: np.ndarray, *, z0: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Free run from ``z0``: outputs ``(..., n, 2)`` and the state after the last command."""
        y, z = simulate_state_space(self.A, self.B, self.C, self.D, _commands(cmd_m_s), z0=z0)
        return y + self.offset_speeds, z

    def simulate(self, cmd_m_s: np.ndarray, *, z0: np.ndarray | None = None) -> np.ndarray:
        """Sensor-less prediction: body speeds from commands only.

        Parameters
        ----------
        cmd_m_s : ndarray, shape (..., n, 2)
            Commands ``(L, R)`` [m/s]; leading axes are independent sequences.
        z0 : ndarray, shape (nz,) or (..., nz), optional
            Initial state (zeros: robot at rest); see :meth:`state_from_data`.

        Returns
        -------
        ndarray, shape (..., n, 2)
            Predicted ``(v [m/s], w [rad/s])``.

        Raises
        ------
        ShapeError, NonFiniteError
            For malformed or non-finite commands.

        Examples
        --------
        >>> model = MotionModel.from_fir(
        ...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
        ...            residual_cov=np.eye(2) * 1e-6, n_samples=100, source="steps"),
        ...     dt_s=0.015, wheel_base_m=0.25, calibrated_at="2026-01-01T00:00:00+00:00")
        >>> (model.simulate(np.tile([0.2, 0.2], (3, 1))).round(12) + 0.0).tolist()
        [[0.0, 0.0], [0.2, 0.0], [0.2, 0.0]]
        """
        return self.propagate(cmd_m_s, z0=z0)[0]

    def predict_poses(self, cmd_m_s: np.ndarray, *, initial_pose: np.ndarray | None = None,
                      z0: np.ndarray | None = None) -> np.ndarray:
        """Sensor-less poses: :meth:`simulate`, then paper eq. 11 (``integrate_poses``).

        Returns
        -------
        ndarray, shape (..., n + 1, 3)
            ``(x [m], y [m], theta [rad])``, starting at ``initial_pose``.
        """
        return integrate_poses(self.simulate(cmd_m_s, z0=z0), self.dt_s,
                               initial_pose=initial_pose)

    def _predictor(self, cmd_m_s: np.ndarray, speeds: np.ndarray, z0: np.ndarray | None):
        u, y = _commands(cmd_m_s), np.asarray(speeds, dtype=float)
        if y.shape != u.shape:
            raise ShapeError(f"cmd_m_s has shape {u.shape} but speeds has shape {y.shape}; they "
                             "must match")
        _finite(y, "speeds")
        pa, pb, pc, pd = one_step_predictor(self.state_space)
        c = self.offset_speeds          # the linear part runs on y - c
        yhat, z = simulate_state_space(pa, pb, pc, pd, np.concatenate([u, y - c], axis=-1),
                                       z0=z0)
        return yhat + c, z

    def predict_one_step(self, cmd_m_s: np.ndarray, speeds: np.ndarray, *,
                         z0: np.ndarray | None = None) -> np.ndarray:
        """Hybrid (filter) mode: each prediction uses the measured past outputs.

        Parameters
        ----------
        cmd_m_s : ndarray, shape (..., n, 2)
            Commands [m/s].
        speeds : ndarray, same shape
            Measured body speeds (encoders) [m/s, rad/s].
        z0 : ndarray, optional
            State before the first sample (zeros: at rest); forgotten after
            ``n_states // 2`` samples.

        Returns
        -------
        ndarray, shape (..., n, 2)
            ``yhat[n | n-1] = C z[n] + D u[n]`` with the predictor
            ``z[n+1] = (A - K C) z + (B - K D) u + K y_meas`` (Ljung 1999,
            section 4.3). Readings far from it are suspect.
        """
        return self._predictor(cmd_m_s, speeds, z0)[0]

    def state_from_data(self, cmd_m_s: np.ndarray, speeds: np.ndarray, *,
                        z0: np.ndarray | None = None) -> np.ndarray:
        """The state after measured data (predictor run), to start a free run from.

        Exact (independent of ``z0``) once the data is at least
        ``n_states // 2`` samples long.
        """
        return self._predictor(cmd_m_s, speeds, z0)[1]

    def output_error_covariance(self, n_steps: int) -> np.ndarray:
        """Predicted covariance of the free-run speed error, ``(n_steps, 2, 2)``.

        ``C P_h C^T + R`` for ``h = 0 .. n_steps-1`` after a known state.
        """
        return output_error_covariances(self.A, self.C, self.Q, self.R, int(n_steps))

    def fit_percent(self, runs: Sequence[tuple[np.ndarray, np.ndarray]], *,
                    mode: Literal["free_run", "one_step"] = "free_run",
                    warmup: int | None = None) -> np.ndarray:
        """Fit [%] of ``(v, w)`` on runs (NRMSE, :func:`lti_motion.metrics.fit_percent`).

        Parameters
        ----------
        runs : sequence of (u, y)
            Validation data.
        mode : {"free_run", "one_step"}
            Sensor-less simulation, or hybrid one-step prediction.
        warmup : int, optional
            Samples of each run that only set the state; default
            ``n_states // 2`` (exact state). Use 0 for runs that start at rest.

        Returns
        -------
        ndarray, shape (2,)
        """
        runs = check_runs(runs)
        warm = self.n_states // 2 if warmup is None else int(warmup)
        if mode == "free_run":
            lin = [(u, y - self.offset_speeds) for u, y in runs]
            err = np.concatenate(free_run_errors(self.state_space, lin, warmup=warm))
        elif mode == "one_step":
            err = np.concatenate([y[warm:] - self.predict_one_step(u, y)[warm:] for u, y in runs])
        else:
            raise ValueError(f"mode must be 'free_run' or 'one_step', got {mode!r}")
        y_all = np.concatenate([y[warm:] for _, y in runs])
        return np.asarray(fit_percent(y_all, y_all - err, axis=0))

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def from_arx(cls, fit: ArxFit, *, dt_s: float, wheel_base_m: float, q_scale: float = 1.0,
                 m_per_tick: float | None = None, floor: str | None = None,
                 calibrated_at: str | None = None, diagnostics: Mapping[str, float] | None = None,
                 selection: ArxSelection | None = None) -> MotionModel:
        """Realise an ARX fit (observable form); ``R`` from its one-step residuals."""
        ss = fit.state_space()
        q, r = noise_covariances(ss.K, fit.residual_cov, q_scale=q_scale)
        diag = {"rank": fit.rank, "condition_number": fit.condition_number,
                "n_rows": fit.n_rows, **(diagnostics or {})}
        if fit.input_condition_number is not None:
            diag["input_condition_number"] = fit.input_condition_number
        return cls(kind="arx", A=ss.A, B=ss.B, C=ss.C, D=ss.D, K=ss.K, Q=q, R=r, dt_s=dt_s,
                   wheel_base_m=wheel_base_m, coefficients={"a": fit.a, "b": fit.b},
                   orders={"na": fit.na, "nb": fit.nb, "delay": fit.delay},
                   calibrated_at=calibrated_at or _now(), m_per_tick=m_per_tick, floor=floor,
                   q_scale=q_scale, diagnostics=diag, selection=selection)

    @classmethod
    def from_fir(cls, fit: FirFit, *, dt_s: float, wheel_base_m: float,
                 noise: ArxFit | None = None, q_scale: float = 1.0,
                 m_per_tick: float | None = None, floor: str | None = None,
                 calibrated_at: str | None = None,
                 diagnostics: Mapping[str, float] | None = None) -> MotionModel:
        """Realise an FIR (shift register), optionally with an AR model of its residuals.

        ``noise`` is a pure AR fit (``nb = 0``) of the FIR's residuals; its
        states are appended and its innovation covariance becomes ``R``.
        Without it, ``K = 0`` and ``R`` is the FIR's residual covariance.
        """
        ss = fir_state_space(fit.taps)
        a, b, c, k, r = ss.A, ss.B, ss.C, ss.K, fit.residual_cov
        noise_a = np.zeros((0, 2, 2))
        if noise is not None and noise.na > 0:
            if noise.nb != 0:
                raise ValueError("noise must be a pure AR fit (nb = 0) of the FIR residuals")
            ns = arx_state_space(noise.a, noise.b, delay=0)
            nz_f, nz_n = a.shape[0], ns.A.shape[0]
            a = np.block([[a, np.zeros((nz_f, nz_n))], [np.zeros((nz_n, nz_f)), ns.A]])
            b = np.vstack([b, np.zeros((nz_n, 2))])
            c = np.hstack([c, ns.C])
            k = np.vstack([k, ns.K])
            r, noise_a = noise.residual_cov, noise.a
        q, r = noise_covariances(k, r, q_scale=q_scale)
        return cls(kind="fir", A=a, B=b, C=c, D=ss.D, K=k, Q=q, R=r, dt_s=dt_s,
                   wheel_base_m=wheel_base_m,
                   coefficients={"taps": fit.taps, "noise_a": noise_a},
                   orders={"n_taps": fit.n_taps, "noise_order": len(noise_a)},
                   calibrated_at=calibrated_at or _now(), m_per_tick=m_per_tick, floor=floor,
                   q_scale=q_scale, diagnostics=dict(diagnostics or {}))

    # -- persistence -----------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write the model as versioned JSON, atomically (:mod:`lti_motion.persistence`).

        The selection curve is not saved; its outcome is in ``diagnostics``.
        """
        payload = {
            "kind": self.kind, "dt_s": self.dt_s, "wheel_base_m": self.wheel_base_m,
            "m_per_tick": self.m_per_tick, "floor": self.floor,
            "calibrated_at": self.calibrated_at, "q_scale": self.q_scale,
            "orders": dict(self.orders), "diagnostics": dict(self.diagnostics),
            "coefficients": {k: encode_array(v) for k, v in self.coefficients.items()},
            "matrices": {n: encode_array(getattr(self, n)) for n in "ABCDKQR"},
            "intrinsics": None if self.intrinsics is None else self.intrinsics.as_dict(),
            "offset_speeds": encode_array(self.offset_speeds),
        }
        if self.odometry_errors is not None:          # optional: older readers ignore it
            payload["odometry_errors"] = self.odometry_errors.as_dict()
        return write_document(path, payload, fmt=FORMAT, version=VERSION)

    @classmethod
    def load(cls, path: str | os.PathLike) -> MotionModel:
        """Read a model written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            If there is no such file.
        ModelFileError
            If the file is damaged or truncated, of another format or version,
            lacks keys, or holds an invalid model.
        """
        doc = read_document(path, fmt=FORMAT, versions=READ_VERSIONS)
        keys = ("kind", "dt_s", "wheel_base_m", "m_per_tick", "floor", "calibrated_at",
                "q_scale", "orders", "diagnostics", "coefficients", "matrices")
        matrices = doc.get("matrices") if isinstance(doc.get("matrices"), dict) else {}
        missing = [k for k in keys if k not in doc]
        missing += [f"matrices.{n}" for n in "ABCDKQR" if n not in matrices]
        if doc["version"] >= 2:
            missing += [k for k in ("intrinsics", "offset_speeds") if k not in doc]
        if missing:
            raise ModelFileError(f"{path} lacks the keys {missing}; it is not a model file "
                                 "that lti-motion wrote")
        try:
            intrinsics = doc.get("intrinsics")
            if intrinsics is not None:
                intrinsics = OdometryIntrinsics(**intrinsics)
            return cls(
                intrinsics=intrinsics,
                kind=doc["kind"], dt_s=doc["dt_s"], wheel_base_m=doc["wheel_base_m"],
                m_per_tick=doc["m_per_tick"], floor=doc["floor"],
                calibrated_at=doc["calibrated_at"], q_scale=doc["q_scale"],
                orders=doc["orders"], diagnostics=doc["diagnostics"],
                coefficients={k: decode_array(v, k) for k, v in doc["coefficients"].items()},
                **{n: decode_array(doc["matrices"][n], n) for n in "ABCDKQR"},
                offset_speeds=(decode_array(doc["offset_speeds"], "offset_speeds")
                               if "offset_speeds" in doc else np.zeros(2)),
                odometry_errors=(OdometryErrors.from_dict(doc["odometry_errors"])
                                 if doc.get("odometry_errors") is not None else None),
            )
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            if isinstance(exc, ModelFileError):
                raise
            raise ModelFileError(f"{path} holds an invalid model: {exc}") from None


def _finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise NonFiniteError(f"{name}{list(idx)} is {arr[idx]}; give finite samples")


def _commands(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim < 2 or u.shape[-1] != 2:
        raise ShapeError(f"expected commands u of shape (..., n, 2) (L, R), got {u.shape}")
    _finite(u, "u")
    return u


def fit_arx(
    runs: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    dt_s: float,
    wheel_base_m: float,
    orders: Sequence[int] = range(1, 13),
    delays: Sequence[int] = range(0, 9),
    validation: float | Sequence[tuple[np.ndarray, np.ndarray]] = 0.3,
    tolerance: float = 0.02,
    m_per_tick: float | None = None,
    floor: str | None = None,
    calibrated_at: str | None = None,
    max_condition: float = DEFAULT_MAX_CONDITION,
    dc_gain: Literal["free", "wheel_servo"] = "free",
    output_scale_horizons_s: Sequence[float] | None = None,
) -> MotionModel:
    """Calibrate an ARX motion model from random-excitation runs (paper section II.C, III.C).

    Parameters
    ----------
    runs : sequence of (u, y)
        Commands (n_i, 2) [m/s] and measured body speeds (n_i, 2) [m/s, rad/s].
    dt_s, wheel_base_m : float
        Sample period [s] and wheel base [m].
    orders, delays : sequence of int
        Selection grid (:func:`~lti_motion.model.select_arx`).
    validation : float or sequence of (u, y)
        Held-out fraction of each run, or separate validation runs.
    tolerance : float
        Relative tolerance of the "levels off" rule.
    m_per_tick, floor, calibrated_at
        Metadata (``calibrated_at`` defaults to now, UTC).
    max_condition : float
        Excitation limit.
    dc_gain : {"free", "wheel_servo"}
        ``"wheel_servo"`` restricts the steady-state gain to ``c M``, one
        scale ``c`` for both wheels (:mod:`lti_motion.model.arx_structure`): right for a
        robot whose wheel speeds are servoed on its encoders (Roomba, Create 2)
        and ``y`` measured by those encoders. ``"free"`` (default) for any
        other pairing, e.g. commands against motion capture.
    output_scale_horizons_s : sequence of float, optional
        Horizons [s] of the output-error criterion whose minimum sets scales
        of ``v`` and ``w`` (:func:`~lti_motion.model.output_scales`,
        the one-sample error added), applied after the gain restriction: the
        held-out fit's model takes them from the estimation part, the final
        one from all data (``diagnostics["output_scale_v"]``, ``["output_scale_w"]``).
        None (default): no scaling.

    Returns
    -------
    MotionModel
        ``kind="arx"``, refitted on all data at the chosen order and delay;
        ``selection`` holds the validation curve, ``diagnostics`` the held-out
        fit. ``q_scale`` comes from the held-out free-run errors of the model
        fitted without them.

    Raises
    ------
    ShapeError, NonFiniteError, CalibrationError, NotExcitedError, UnstableModelError
        For bad data (see :func:`~lti_motion.model.estimate_arx`).
    """
    if dc_gain not in ("free", "wheel_servo"):
        raise ValueError(f"dc_gain must be 'free' or 'wheel_servo', got {dc_gain!r}")
    runs = check_runs(runs)
    sel = select_arx(runs, orders=orders, delays=delays, validation=validation,
                     tolerance=tolerance, max_condition=max_condition)
    final = estimate_arx(runs, na=sel.order, nb=sel.order, delay=sel.delay,
                         max_condition=max_condition)
    probe_fit, diagnostics = sel.fit, {}
    if dc_gain == "wheel_servo":
        probe_fit = restrict_dc_gain(sel.fit, servo_dc_gain(sel.fit, wheel_base_m=wheel_base_m)[0])
        gain, diagnostics["dc_gain_scale"] = servo_dc_gain(final, wheel_base_m=wheel_base_m)
        final = restrict_dc_gain(final, gain)
    est, val = split_runs(runs, validation, warmup=sel.warmup)
    if output_scale_horizons_s is not None:
        lengths = (1, *(max(1, round(h / dt_s)) for h in output_scale_horizons_s))
        probe_fit = scale_outputs(probe_fit, output_scales(probe_fit, est, warmup=sel.warmup,
                                                           horizons=lengths))
        scales = output_scales(final, runs, warmup=sel.warmup, horizons=lengths)
        final = scale_outputs(final, scales)
        diagnostics["output_scale_v"], diagnostics["output_scale_w"] = (float(x) for x in scales)
    probe = probe_fit.state_space()
    errors = free_run_errors(probe, val, warmup=sel.warmup)
    alpha = q_scale_from_errors(probe, probe_fit.residual_cov, errors)
    y_val = np.concatenate([y[sel.warmup:] for _, y in val])
    fit_v, fit_w = (float(f) for f in fit_percent(y_val, y_val - np.concatenate(errors), axis=0))
    _log.info("ARX model: order %d, delay %d, validation fit %.2f / %.2f %%, q_scale %.3g",
              sel.order, sel.delay, fit_v, fit_w, alpha)
    return MotionModel.from_arx(
        final, dt_s=dt_s, wheel_base_m=wheel_base_m, q_scale=alpha, m_per_tick=m_per_tick,
        floor=floor, calibrated_at=calibrated_at, selection=sel,
        diagnostics={"validation_fit_v": fit_v, "validation_fit_w": fit_w, **diagnostics},
    )


def _ar_noise(residuals: list[np.ndarray], *, order: int | None, max_order: int
              ) -> ArxFit | None:
    """Vector AR model of residuals; order by BIC (Schwarz 1978) when not given."""
    runs = [(np.zeros_like(e), e) for e in residuals]
    n = sum(len(e) for e in residuals)
    if order is not None:
        return estimate_arx(runs, na=order, nb=0) if order > 0 else None
    best, best_bic = None, np.log(np.linalg.det(sum(e.T @ e for e in residuals) / n))
    for p in range(1, max_order + 1):
        try:
            fit = estimate_arx(runs, na=p, nb=0)
        except CalibrationError:  # too short or unstable at this order: stop growing
            break
        bic = np.log(np.linalg.det(fit.residual_cov)) + 4 * p * np.log(n) / n
        if bic < best_bic:
            best, best_bic = fit, bic
    return best


def fit_fir_from_steps(
    u: np.ndarray,
    y: np.ndarray,
    *,
    phases: StepSequence | Sequence[slice],
    dt_s: float,
    wheel_base_m: float,
    noise_runs: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
    noise_order: int | None = None,
    max_noise_order: int = 4,
    m_per_tick: float | None = None,
    floor: str | None = None,
    calibrated_at: str | None = None,
    **fir_options: Any,
) -> MotionModel:
    """Calibrate the moving-average (FIR) motion model from a step manoeuvre (paper section II.B).

    Parameters
    ----------
    u, y : ndarray, shape (n, 2)
        Commands sent and body speeds measured during the step sequence.
    phases : StepSequence or four slices
        Where the four phases lie.
    dt_s, wheel_base_m : float
        Sample period [s] and wheel base [m].
    noise_runs : sequence of (u, y), optional
        Data (starting at rest) on which the FIR's residuals define the noise
        model; default the step data. Random-excitation data gives the more
        honest ``Q`` and ``R``.
    noise_order : int, optional
        Order of the vector AR model of the residuals; by BIC up to
        ``max_noise_order`` when not given.
    m_per_tick, floor, calibrated_at
        Metadata.
    **fir_options
        Passed to :func:`~lti_motion.model.fir_from_steps` (``edges``,
        ``dc_gain``, ``rel_threshold``, ``margin_taps``, ``max_taps`` ...).

    Returns
    -------
    MotionModel
        ``kind="fir"``.

    Raises
    ------
    ShapeError, NonFiniteError, CalibrationError
        For bad data.
    """
    fir = fir_from_steps(u, y, phases=phases, wheel_base_m=wheel_base_m, **fir_options)
    ss = fir_state_space(fir.taps)
    skip = fir.n_taps - 1
    data = check_runs(noise_runs if noise_runs is not None else [(u, y)])
    resid = [yy[skip:] - simulate_state_space(ss.A, ss.B, ss.C, ss.D, uu)[0][skip:]
             for uu, yy in data]
    if noise_runs is not None:
        n = sum(len(e) for e in resid)
        fir = dataclasses.replace(fir, residual_cov=sum(e.T @ e for e in resid) / n)
    noise = _ar_noise(resid, order=noise_order, max_order=max_noise_order)
    probe = MotionModel.from_fir(fir, dt_s=dt_s, wheel_base_m=wheel_base_m, noise=noise,
                                 calibrated_at=calibrated_at)
    nz_f = ss.A.shape[0]
    # the residual *is* the free-run error from a known (rest) state of the noise states
    noise_ss = StateSpace(probe.A[nz_f:, nz_f:], probe.B[nz_f:], probe.C[:, nz_f:], probe.D,
                          probe.K[nz_f:])
    alpha = q_scale_from_errors(noise_ss, probe.R, resid)
    fits = [fit_percent(yy[skip:], yy[skip:] - e, axis=0)
            for (_, yy), e in zip(data, resid, strict=True)]
    return MotionModel.from_fir(
        fir, dt_s=dt_s, wheel_base_m=wheel_base_m, noise=noise, q_scale=alpha,
        m_per_tick=m_per_tick, floor=floor, calibrated_at=calibrated_at,
        diagnostics={"calibration_fit_v": float(np.mean([f[0] for f in fits])),
                     "calibration_fit_w": float(np.mean([f[1] for f in fits]))},
    )
