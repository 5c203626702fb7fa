"""The model-based EKF as plain functions, for any filterpy filter (EKF or UKF).

:class:`fusion.ekf.ModelEKF` is a thin filterpy subclass that calls these
functions; users who keep their own ``ExtendedKalmanFilter`` or
``UnscentedKalmanFilter`` call them directly (see Examples).

**State** (``n = nz + 8`` entries, :class:`FilterModel` gives the slices)::

    x = (x, y, theta,  k_v, k_w, kappa,  z[k+1],  v, w)
         pose p[k]     scale errors c    model    speeds s[k]

the pose (m, m, rad; heading continuous, not wrapped) at the end of sensor
period ``k``; the scale errors of the ground speeds against the encoder
speeds (relative, relative, rad/m); the motion model's state; the body speeds
over period ``k``
[m/s, rad/s] (summed over the periods since the last fused encoder counts,
see *Gated readings*).

**The correlated noise, and why ``s`` is in the state.** The calibrated model
is in innovations form (:class:`lti_motion.model.MotionModel`; Ljung 1999,
section 4.3)::

    s[k]   = C z[k] + D u[k] + e[k]                  e ~ N(0, R)
    z[k+1] = A z[k] + B u[k] + K e[k] + m[k]         m ~ N(0, Q - K R K^T)

with ``m`` the model error beyond the one-step residual (``Q = alpha K R K^T``
+ jitter, ``alpha >= 1``). The same ``e[k]`` moves the speed the encoders
measure, the next model state and, through the speed, the pose: process and
output noise are correlated, ``E[w e^T] = K R`` (``MotionModel.S``). A
filter that treats them as independent gives the encoders too little weight
and keeps pose uncertainty it should have removed. Carrying ``s[k]`` in the
state makes every noise independent of every other and of the past, and the
encoders a *linear* measurement::

    y[k] = H x[k] + eps[k],   H = [0 0 0 I],   eps ~ N(0, R_enc)

with ``R_enc`` a tiny floor: the model's ``R`` already holds the encoders'
quantisation. This is the correlated-noise Kalman filter (Simon 2006, section
7.1; Anderson & Moore 1979, chapter 5) in a form every stock filter runs:
after an encoder update the speed state equals the reading, the model state
becomes the one-step predictor ``A z + B u + K (y - C z - D u)``
(``MotionModel.predict_one_step``), and the pose has moved by ``F_s`` times
the innovation, i.e. it is integrated from the *measured* speeds, with no
speed noise left in it. When a reading is gated or missing, the speed comes
from the model with covariance ``C P_zz C^T + R``, the pose takes it through
``F_s``, and the cross-covariances let later readings correct both.

**Pose noise.** Encoders count wheel rotation and cannot see the ground. The
ground speeds are::

    g[k] = D_c s[k] + eta[k],   D_c = [[1 + k_v, 0      ],   eta ~ N(0, R_slip(s))
                                       [kappa,   1 + k_w]]
    p[k] = pose_step(p[k-1], g[k])                      (paper eq. 11)
    c[k] = c[k-1] + b[k],                                b ~ N(0, diag(q_c) dt)

``c = (k_v, k_w, kappa)`` are what the encoder mapping (the model's
:attr:`~lti_motion.model.MotionModel.encoder_intrinsics`) leaves behind: a
scale calibration's few tenths of a percent of travel and turn (``docs/ekf.md``:
wheel base, creep on turns), and ``kappa`` [rad/m], the curvature a straight
run of equal counts drives, i.e. a left/right diameter ratio (UMBmark's "type
B" error; the definition, exact for per-wheel scales and a wheel base, is
:mod:`lti_motion.intrinsics`, *Scale errors*:
``ds_g = (1 + k_v) ds + kappa b' b dtheta / 4``,
``dtheta_g = (1 + k_w) dtheta + kappa ds``). The filter drops the second-order
term ``kappa b' b w / 4`` of the ground speed: at a 1% ratio it moves a Create
2 by 0.6 mm per radian turned, far below a landmark's noise; the estimated
errors still map exactly to intrinsics
(:meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected`). Being systematic
they grow the pose error linearly in distance, not as a random walk, so they
are states (odometry auto-calibration, Larsen et al. 1998), slow random walks
(:class:`ScaleErrors`: a prior of 1% for the travel and the turn, and a 1%
diameter ratio, ``0.01 / b`` rad/m, for ``kappa``). Encoders cannot observe
them: without absolute measurements their estimate stays 0 (the pose is
odometry's) while their variance makes the pose covariance grow as drift
does; landmarks estimate them. ``eta`` is white slip
(:class:`SlipNoise`: ``sigma_v = v0 + a_v |v|``, ``sigma_w = w0 + a_w |w| +
b_w |v|``, defaults from the simulator's floor roughness). The encoders'
quantisation error is a difference of rounding errors: it does not
accumulate in the integrated pose (below one tick) and adds no pose noise.

**Gated readings.** Encoder counts are cumulative, so a reading the gate
rejects (or a frame that is lost) loses no motion if the next counts are
taken against the last *fused* ones. The speed state then accumulates,
``a[k] = a[k-1] + s[k]`` (``accumulate=True`` in :func:`predict_terms`), and
the next reading measures the sum over the periods since, still linearly
(``H`` unchanged, counts through the intrinsics' Jacobian over ``dt_s``); the cross-covariances
carry the correction to the pose of every period in the sum. A single-frame
spike is rejected and the motion recovered at the next frame; a reading
rejected while it spans several periods (16 by default) renews the reference:
a stuck encoder's lost ticks are lost for good.

**A gyro** (``FilterModel(gyro=GyroNoise(...))``, :mod:`fusion.ekf.gyro`) adds
two states after ``c``: its bias ``b`` [rad/s], a random walk (``F = 1``,
``Q = q_b^2 dt``), and ``theta_c``, a copy of the heading taken at the start of
the gyro's integration window (a stochastic clone: ``F = 1``, no noise; Roumeliotis
& Burdick 2002), so that the integrated gyro measures ``theta - theta_c``, the
heading change, slip included, that the pose carries.

**Linearisation.** With ``F_p``, ``F_s`` the pose step's Jacobians with respect
to the pose and to the ground speeds at ``g_hat = D_c s_hat``
(:func:`lti_motion.kinematics.pose_step_jacobians`), ``D_c`` as above and
``D_s = dg/dc = [[v, 0, 0], [0, w, v]]`` (``g`` is bilinear in ``c`` and
``s``: ``dg/ds = D_c``)::

    F = [[F_p, F_s D_s, F_s D_c C, 0  ],   Q = G2 blkdiag(R, R_slip) G2^T + Q_c
         [0,   I,       0,         0  ],   G2 = [[F_s D_c, F_s],
         [0,   0,       A,         0  ],         [0,       0  ],
         [0,   0,       C,         r I]]         [K,       0  ],
                                                 [I,       0  ]]

(``r = 1`` when accumulating, else 0).

``Q_c = blkdiag(0, diag(q_c) dt, Q - K R K^T, 0)``, ``q_c`` the three walk
rates. Written out, with ``F_s = [[a, b], [c, d], [0, dt]]`` the pose rows are
``F_s D_c = [[a (1+k_v) + b kappa, b (1+k_w)], [c (1+k_v) + d kappa, d (1+k_w)],
[dt kappa, dt (1+k_w)]]`` and ``F_s D_s = [[a v, b w, b v], [c v, d w, d v],
[0, dt w, dt v]]``. ``A``, ``C``, ``K`` and
``Q_c`` are constant and precomputed (:class:`FilterModel`); per step only the
pose rows of ``F`` and ``G2`` change: no numerical Jacobian.

**Updates** use the Joseph form ``P = (I - K H) P (I - K H)^T + K R K^T``
(Bar-Shalom, Li & Kirubarajan 2001, eq. 5.2.3-18), which stays symmetric
positive semi-definite for any gain; predictions symmetrise ``F P F^T + Q``.

References
----------
The paper: ``docs/architecture.md``, "The paper".
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, eq. 5.2.3-18 (Joseph form) and section
5.4.2 (NEES, NIS). D. Simon, *Optimal State Estimation*, Wiley 2006, section
7.1. B. D. O. Anderson, J. B. Moore, *Optimal Filtering*, Prentice-Hall 1979.
L. Ljung, *System Identification*, 2nd ed., Prentice Hall 1999, section 4.3.
T. D. Larsen, M. Bak, N. A. Andersen, O. Ravn, "Location estimation for an
autonomously guided vehicle using an augmented Kalman filter to autocalibrate
the odometry", FUSION 1998.

Examples
--------
A stock filterpy EKF driven by these functions (``predict_x`` is filterpy's
documented extension point):

>>> from filterpy.kalman import ExtendedKalmanFilter
>>> from lti_motion.model.fir import FirFit
>>> from lti_motion.model.motion_model import MotionModel
>>> model = MotionModel.from_fir(
...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
...            residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
...     dt_s=0.015, wheel_base_m=0.25, m_per_tick=4.4e-4,
...     calibrated_at="2026-01-01T00:00:00+00:00")
>>> fm = FilterModel(model)
>>> class Stock(ExtendedKalmanFilter):
...     def predict_x(self, u=0):
...         self.x = state_transition(self.x, u, fm)
>>> ekf = Stock(dim_x=fm.n, dim_z=2)
>>> ekf.x, ekf.P = initial_state(fm, (0.0, 0.0, 0.0)), initial_covariance(fm)
>>> u = np.array([0.2, 0.2])
>>> for _ in range(3):
...     _, ekf.F, ekf.Q = predict_terms(ekf.x, u, fm)
...     ekf.predict(u)
...     ekf.update(np.array([0.2, 0.0]), encoder_jacobian, encoder_measurement,
...                R=fm.encoder_cov, args=(fm,), hx_args=(fm,))
>>> (ekf.x[:3].round(4) + 0.0).tolist()
[0.009, 0.0, 0.0]
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field

import numpy as np

from fusion.ekf.kernel import kernel_array, predict_kernel, predict_terms_kernel
from fusion.exceptions import (
    FilterOptionError,
    MeasurementShapeError,
    NonFiniteInputError,
    NotAModelError,
)
from fusion.noise import GyroNoise, ScaleErrors, SlipNoise
from fusion.range_bearing import (
    range_bearing,
    range_bearing_jacobian,
    range_bearing_residual,
    range_bearing_terms,
)
from fusion.sensor_pose import SensorPose
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import wrap_angle
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.ticks import tick_deltas

__all__ = [
    "GYRO_BIAS",
    "HEADING_CLONE",
    "POSE",
    "SCALES",
    "FilterModel",
    "encoder_jacobian",
    "encoder_measurement",
    "encoder_speeds",
    "initial_covariance",
    "initial_state",
    "innovation_covariance",
    "joseph_covariance",
    "kalman_gain",
    "landmark_jacobian",
    "landmark_measurement",
    "landmark_residual",
    "landmark_terms",
    "pose_jacobian",
    "pose_measurement",
    "pose_residual",
    "predict_step",
    "predict_terms",
    "process_noise",
    "propagate_covariance",
    "span_verdict",
    "state_mean",
    "state_residual",
    "state_transition",
    "transition_jacobian",
]

_log = logging.getLogger(__name__)





def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float)
    arr.flags.writeable = False
    return arr


#: Where the pose and the scale errors sit; the model state follows, the speeds close.
POSE = slice(0, 3)
SCALES = slice(3, 6)
#: With a gyro (``FilterModel(gyro=...)``): its bias [rad/s] and the heading at the start
#: of the gyro's window [rad] (``fusion.ekf.gyro``), between the scale errors and the model.
GYRO_BIAS, HEADING_CLONE = 6, 7
_Z0 = 6


@dataclass(frozen=True, eq=False)
class FilterModel:
    """A :class:`~lti_motion.model.MotionModel` laid out for a filter, constant blocks precomputed.

    Parameters
    ----------
    model : MotionModel
        The calibrated model.
    slip : SlipNoise, optional
        White ground-speed noise (module notes); default :class:`SlipNoise()`.
    scales : ScaleErrors, optional
        Prior and drift of the scale-error states; default :class:`ScaleErrors()`.
    encoder_std : tuple of 2 float
        Standard deviations of the encoder speed reading about the speed
        state, ``(v [m/s], w [rad/s])``: a floor that keeps the update well
        posed; the model's ``R`` already holds the quantisation.
    m_per_tick : float, optional
        Encoder scale of both wheels [m/tick], with the model's wheel base;
        default the model's :attr:`~lti_motion.model.MotionModel.encoder_intrinsics`
        (each wheel's scale and the wheel base, else both wheels at
        ``model.m_per_tick``). Needed only for :func:`encoder_speeds`.
    gyro : GyroNoise, optional
        A yaw-rate gyro to fuse (:mod:`fusion.ekf.gyro`): two states more, its
        bias and the heading at the start of its window, at :data:`GYRO_BIAS`,
        :data:`HEADING_CLONE` (the model state then starts at 8); default none
        (``n = nz + 8``).

    Attributes
    ----------
    n, nz : int
        State size ``nz + 8`` (``nz + 10`` with a gyro) and model-state size.
    z0 : int
        Where the model state starts (6, or 8 with a gyro).
    intrinsics : OdometryIntrinsics or None
        The counts-to-speeds mapping in use (None without an encoder scale);
        the scale errors are relative to it.
    m_per_tick : float or None
        Its mean scale [m/tick].
    scale_prior_std, scale_walk : tuple of 3 float
        Prior standard deviations and walk rates of ``(k_v, k_w, kappa)``
        (:meth:`ScaleErrors.prior_stds` at the intrinsics' wheel base, else
        the model's).
    dt_s : float
        Sensor period [s].
    encoder_cov : ndarray, shape (2, 2)
        ``diag(encoder_std)^2``.
    H_encoders : ndarray, shape (2, n)
        ``[0 0 0 I]``.
    ticks_to_speeds : ndarray, shape (2, 2) or None
        Tick increments (left, right) of one period -> ``(v, w)``: the
        intrinsics' Jacobian over ``dt_s``.
    F_template, G_template, W_template, Q_const : ndarray
        Constant parts of ``F`` (n, n), ``G2`` (n, 4), ``blkdiag(R, 0)`` (4, 4)
        and ``Q_c`` (n, n) (module notes).
    kernel_constants : tuple
        What the compiled step (:mod:`fusion.ekf.kernel`) reads, read-only: the
        scalars ``(dt_s, the slip parameters, R)``, ``[[A, B, 0], [C, D, offset]]``,
        ``G_template`` and ``Q_const``.

    Raises
    ------
    FilterOptionError
        For non-positive encoder noise or scale, or a ``slip`` whose class overrides
        :meth:`SlipNoise.stds` (the compiled step evaluates ``SlipNoise``'s own law).
    NotAModelError
        If ``model`` is not a :class:`~lti_motion.model.MotionModel` (a file's path:
        load it with ``MotionModel.load``).
    """

    model: MotionModel
    slip: SlipNoise = field(default_factory=SlipNoise)
    scales: ScaleErrors = field(default_factory=ScaleErrors)
    encoder_std: tuple[float, float] = (1e-5, 1e-4)
    m_per_tick: float | None = None
    gyro: GyroNoise | None = None
    n: int = field(init=False)
    z0: int = field(init=False)
    intrinsics: OdometryIntrinsics | None = field(init=False)
    scale_prior_std: tuple[float, float, float] = field(init=False)
    scale_walk: tuple[float, float, float] = field(init=False)
    nz: int = field(init=False)
    dt_s: float = field(init=False)
    encoder_cov: np.ndarray = field(init=False, repr=False)
    H_encoders: np.ndarray = field(init=False, repr=False)
    ticks_to_speeds: np.ndarray | None = field(init=False, repr=False)
    ACD: np.ndarray = field(init=False, repr=False)
    BD: np.ndarray = field(init=False, repr=False)
    F_template: np.ndarray = field(init=False, repr=False)
    G_template: np.ndarray = field(init=False, repr=False)
    W_template: np.ndarray = field(init=False, repr=False)
    Q_const: np.ndarray = field(init=False, repr=False)
    kernel_constants: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        setf = object.__setattr__
        m = self.model
        if not isinstance(m, MotionModel):
            hint = (f" ({m!r}): load a model file with MotionModel.load({m!r}) and give the "
                    "model" if isinstance(m, str | bytes | os.PathLike) else "")
            raise NotAModelError(f"model must be a MotionModel, got a "
                                 f"{type(m).__name__}{hint}")
        nz = m.n_states
        z0 = _Z0 + (0 if self.gyro is None else 2)
        n = nz + z0 + 2
        zs, ss = slice(z0, z0 + nz), slice(z0 + nz, n)
        std = tuple(float(s) for s in self.encoder_std)
        if len(std) != 2 or not all(math.isfinite(s) and s > 0 for s in std):
            raise FilterOptionError(f"encoder_std must be two positive numbers, got {std}")
        if type(self.slip).stds is not SlipNoise.stds:   # the compiled step reads the fields
            raise FilterOptionError(f"{type(self.slip).__name__} overrides SlipNoise.stds; the "
                                    "filter's compiled step evaluates SlipNoise's own law "
                                    "from its fields: give a SlipNoise with those fields")
        if self.m_per_tick is None:
            intrinsics = m.encoder_intrinsics
        else:
            scale = float(self.m_per_tick)
            if not (math.isfinite(scale) and scale > 0):
                raise FilterOptionError(f"m_per_tick must be positive, got {scale}")
            intrinsics = OdometryIntrinsics.symmetric(m_per_tick=scale,
                                                      wheel_base_m=m.wheel_base_m)
        base = m.wheel_base_m if intrinsics is None else intrinsics.wheel_base_m
        for name, value in (("m_per_tick", None if intrinsics is None else intrinsics.m_per_tick),
                            ("intrinsics", intrinsics), ("encoder_std", std), ("n", n),
                            ("z0", z0),
                            ("nz", nz), ("dt_s", m.dt_s),
                            ("scale_prior_std", self.scales.prior_stds(base)),
                            ("scale_walk", self.scales.walk_rates(base))):
            setf(self, name, value)
        setf(self, "encoder_cov", _readonly(np.diag(np.square(std))))
        h = np.zeros((2, n))
        h[:, ss] = np.eye(2)
        setf(self, "H_encoders", _readonly(h))
        # body speeds are linear in the tick increments (Censi et al. 2013, sec. III)
        setf(self, "ticks_to_speeds", None if intrinsics is None else _readonly(
            intrinsics.jacobian() / m.dt_s))
        setf(self, "ACD", _readonly(np.vstack([m.A, m.C])))
        setf(self, "BD", _readonly(np.vstack([m.B, m.D])))
        f = np.zeros((n, n))
        f[POSE, POSE] = np.eye(3)
        f[SCALES, SCALES] = np.eye(3)
        f[zs, zs] = m.A
        f[ss, zs] = m.C
        g2 = np.zeros((n, 4))
        g2[zs, :2] = m.K
        g2[ss, :2] = np.eye(2)
        if self.gyro is not None:               # bias: random walk; the clone: constant
            f[GYRO_BIAS, GYRO_BIAS] = f[HEADING_CLONE, HEADING_CLONE] = 1.0
        setf(self, "F_template", _readonly(f))
        setf(self, "G_template", _readonly(g2))
        w4 = np.zeros((4, 4))
        w4[:2, :2] = m.R
        setf(self, "W_template", _readonly(w4))
        extra = m.Q - m.K @ m.R @ m.K.T              # model error beyond K e
        extra = 0.5 * (extra + extra.T)
        evals, evecs = np.linalg.eigh(extra)
        if evals.size and evals.min() < -1e-9 * max(1.0, float(np.abs(evals).max())):
            _log.warning("model Q is not >= K R K^T (smallest eigenvalue of the difference "
                         "%.3g); negative part clipped", evals.min())
        extra = (evecs * np.clip(evals, 0.0, None)) @ evecs.T
        q = np.zeros((n, n))
        q[zs, zs] = 0.5 * (extra + extra.T)
        q[SCALES, SCALES] = np.diag(np.square(self.scale_walk) * m.dt_s)
        if self.gyro is not None:
            q[GYRO_BIAS, GYRO_BIAS] = self.gyro.bias_walk_rad_s_per_sqrt_s ** 2 * m.dt_s
        setf(self, "Q_const", _readonly(q))
        sl = self.slip
        abo = np.zeros((nz + 2, nz + 3))
        abo[:, :nz], abo[:, nz:nz + 2], abo[nz:, nz + 2] = self.ACD, self.BD, m.offset_speeds
        setf(self, "kernel_constants", (
            _readonly((m.dt_s, sl.v_floor_m_s, sl.v_frac, sl.w_floor_rad_s, sl.w_frac,
                       sl.w_per_v_rad_m, *np.ravel(m.R))),
            _readonly(abo), self.G_template, self.Q_const))

    @property
    def model_slice(self) -> slice:
        """Where the model state ``z`` sits."""
        return slice(self.z0, self.z0 + self.nz)

    @property
    def speed_slice(self) -> slice:
        """Where the speed state ``s = (v, w)`` sits (the last two entries)."""
        return slice(self.z0 + self.nz, self.n)


def _check_state(x: np.ndarray, fm: FilterModel) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.shape != (fm.n,):
        if x.shape == (fm.n, 1):            # filterpy's column convention
            return x[:, 0]
        raise MeasurementShapeError(f"expected a state of shape ({fm.n},) for a model with "
                                    f"{fm.nz} states, got {x.shape}")
    return x


def _check_command(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.shape != (2,):
        raise MeasurementShapeError(f"expected wheel commands u of shape (2,) (left, right) "
                                    f"[m/s], got {u.shape}")
    u0, u1 = u.tolist()
    if not (math.isfinite(u0) and math.isfinite(u1)):
        raise NonFiniteInputError(f"wheel commands must be finite, got {[u0, u1]}")
    return u


def predict_terms(x: np.ndarray, cmd_m_s: np.ndarray, fm: FilterModel, *, accumulate: bool = False,
                  out_F: np.ndarray | None = None, out_Q: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One prediction: the next state, the transition Jacobian and the process noise.

    Parameters
    ----------
    x : ndarray, shape (n,)
        State after period ``k-1`` (``(n, 1)`` is accepted).
    cmd_m_s : ndarray, shape (2,)
        Wheel commands ``(left, right)`` [m/s] of period ``k``.
    fm : FilterModel
        The model's filter layout.
    accumulate : bool
        Add this period's speeds to the speed state instead of replacing it
        (``a' = a + s`` rather than ``a' = s``): after an encoder reading was
        gated or lost, so the next counts, taken against the last fused ones,
        measure the sum over the periods since (module notes).
    out_F, out_Q : ndarray, shape (n, n), optional
        Buffers to write ``F`` and ``Q`` into, with no allocation. ``out_F``
        must hold an earlier ``F`` for the same ``fm`` (or a copy of
        ``fm.F_template``): only its first three rows, which depend on ``x``
        and ``cmd_m_s``, are written. ``out_Q`` is overwritten entirely.

    Returns
    -------
    x_next : ndarray, shape (n,)
        ``(pose_step(p, g_hat), c, A z + B u, s_hat)`` with ``s_hat = C z + D u``
        and ``g_hat = D_c s_hat`` (``s_hat + s`` with ``accumulate``).
    F : ndarray, shape (n, n)
        Transition Jacobian (module notes).
    Q : ndarray, shape (n, n)
        ``G2 blkdiag(R, R_slip) G2^T + Q_c`` (module notes).

    Raises
    ------
    MeasurementShapeError, NonFiniteInputError
        For a state or command of the wrong shape, or non-finite commands.

    Notes
    -----
    The pose step is paper eq. 11 in chord form, ``h = w dt / 2``,
    ``c = v dt sin(h)/h``: ``x' = x + c cos(theta + h)``,
    ``y' = y + c sin(theta + h)``, ``theta' = theta + 2 h``; its Jacobians are
    those of :func:`lti_motion.kinematics.pose_step_jacobians`, in scalar
    arithmetic, compiled (:func:`fusion.ekf.predict_terms_kernel`: per-step cost).
    """
    x = kernel_array(_check_state(x, fm))
    cmd_m_s = kernel_array(_check_command(cmd_m_s))
    F = np.array(fm.F_template) if out_F is None else out_F
    Q = np.empty((fm.n, fm.n)) if out_Q is None else out_Q
    x_new = predict_terms_kernel(x, cmd_m_s, bool(accumulate), *fm.kernel_constants, F, Q)
    return x_new, F, Q


def predict_step(x: np.ndarray, P: np.ndarray, cmd_m_s: np.ndarray, fm: FilterModel, *,
                 accumulate: bool = False, out_F: np.ndarray, out_Q: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`predict_terms` and :func:`propagate_covariance` in one compiled call.

    Parameters
    ----------
    x : ndarray, shape (n,)
        State after period ``k-1``.
    P : ndarray, shape (n, n)
        Its covariance.
    cmd_m_s : ndarray, shape (2,)
        Wheel commands ``(left, right)`` [m/s] of period ``k``.
    fm : FilterModel
        The model's filter layout.
    accumulate : bool
        As :func:`predict_terms`.
    out_F, out_Q : ndarray, shape (n, n)
        Buffers that receive ``F`` and ``Q``, as :func:`predict_terms`'s
        (``out_F`` holding an earlier ``F`` of ``fm`` or ``fm.F_template``).

    Returns
    -------
    x_next : ndarray, shape (n,)
        As :func:`predict_terms`.
    P_next : ndarray, shape (n, n)
        ``F P F^T + Q``, symmetrised (Bar-Shalom et al. 2001, eq. 5.2.3-5).

    Raises
    ------
    MeasurementShapeError, NonFiniteInputError
        As :func:`predict_terms`.

    Notes
    -----
    :func:`fusion.ekf.predict_kernel`: the same arithmetic as the two
    functions, skipping the zeros of ``F``; equal to them to rounding.
    """
    x = kernel_array(_check_state(x, fm))
    cmd_m_s = kernel_array(_check_command(cmd_m_s))
    P = np.asarray(P, dtype=float)
    if P.shape != (fm.n, fm.n):
        raise MeasurementShapeError(f"expected a covariance of shape ({fm.n}, {fm.n}), got "
                                    f"{P.shape}")
    return predict_kernel(x, kernel_array(P), cmd_m_s, bool(accumulate), *fm.kernel_constants,
                          out_F, out_Q)


def state_transition(x: np.ndarray, cmd_m_s: np.ndarray, fm: FilterModel) -> np.ndarray:
    """The next state ``f(x, u)``, shape (n,); see :func:`predict_terms`."""
    return predict_terms(x, cmd_m_s, fm)[0]


def transition_jacobian(x: np.ndarray, cmd_m_s: np.ndarray, fm: FilterModel) -> np.ndarray:
    """``F = df/dx``, shape (n, n); see :func:`predict_terms`."""
    return predict_terms(x, cmd_m_s, fm)[1]


def process_noise(x: np.ndarray, cmd_m_s: np.ndarray, fm: FilterModel) -> np.ndarray:
    """Process-noise covariance ``Q``, shape (n, n); see :func:`predict_terms`."""
    return predict_terms(x, cmd_m_s, fm)[2]


def propagate_covariance(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``F P F^T + Q``, symmetrised, shape (n, n) (Bar-Shalom et al. 2001, eq. 5.2.3-5).

    Plain array code (numba can compile it).
    """
    out = F @ P @ F.T
    out += Q
    sym = out + out.T
    sym *= 0.5
    return sym


def innovation_covariance(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``S = H P H^T + R``, shape (m, m) (Bar-Shalom et al. 2001, eq. 5.2.3-9)."""
    return H @ P @ H.T + R


def kalman_gain(P: np.ndarray, H: np.ndarray, SI: np.ndarray) -> np.ndarray:
    """``K = P H^T S^-1``, shape (n, m), from the inverse innovation covariance ``SI``."""
    return P @ H.T @ SI


def joseph_covariance(P: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray,
                      PHt: np.ndarray | None = None) -> np.ndarray:
    """Updated covariance in Joseph form, shape (n, n).

    ``(I - K H) P (I - K H)^T + K R K^T`` (Bar-Shalom et al. 2001, eq.
    5.2.3-18): a sum of positive semi-definite terms for any gain ``K``.
    Evaluated by associativity, ``M = P - K (H P)``, ``M - (M H^T) K^T``, so
    no ``n x n x n`` product is formed; ``PHt``, if given, is ``P H^T``
    already at hand. The result is symmetric to rounding
    (about 1e-16 relative); :func:`propagate_covariance` symmetrises exactly
    once per step. Plain array code (numba can compile it).
    """
    HP = H @ P if PHt is None else PHt.T    # P is symmetric: H P = (P H^T)^T
    M = P - K @ HP                          # (I - K H) P
    out = M - (M @ H.T) @ K.T               # (I - K H) P (I - K H)^T, O(n^2 m)
    out += (K @ R) @ K.T
    return out








# -- measurements -----------------------------------------------------------------------------
def encoder_measurement(x: np.ndarray, fm: FilterModel) -> np.ndarray:
    """Predicted encoder body speeds ``H x = s`` = ``C z + D u`` of the period, shape (2,)."""
    return np.array(_check_state(x, fm)[fm.n - 2:])


def encoder_jacobian(x: np.ndarray, fm: FilterModel) -> np.ndarray:
    """``H = [0 0 0 I]``, shape (2, n) (constant, read-only)."""
    return fm.H_encoders


def encoder_speeds(ticks: np.ndarray, fm: FilterModel) -> np.ndarray:
    """Body speeds ``(v [m/s], w [rad/s])`` over one period from raw 16-bit counts.

    Parameters
    ----------
    ticks : array_like of int, shape (2, 2)
        Raw counts ``(left, right)`` at the start (row 0) and the end (row 1)
        of the period.
    fm : FilterModel
        Layout with the encoder scale.

    Returns
    -------
    ndarray, shape (2,)
        Rollover-safe: increments by :func:`lti_motion.recordings.tick_deltas`,
        speeds through the intrinsics (each wheel's scale and the wheel base)
        as the 2 x 2 matrix ``fm.ticks_to_speeds``, ``J / dt_s``
        (:meth:`lti_motion.intrinsics.OdometryIntrinsics.jacobian`).

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale and ``fm`` was given none (``m_per_tick``).
    """
    if fm.ticks_to_speeds is None:
        raise MissingEncoderScaleError.needed_by(
            "turning encoder counts into speeds", keyword="m_per_tick=... to the filter "
            "(ModelEKF or FilterModel)")
    return fm.ticks_to_speeds @ tick_deltas(ticks, axis=0)[0]


def span_verdict(span_ticks: np.ndarray, predicted_ticks: np.ndarray, frame_jump_ticks: float,
                 span_jump_ticks: float, *, periods: int, max_jump_ticks: float) -> str:
    """Judge encoder counts that stayed outside the gate for ``periods`` periods.

    Parameters
    ----------
    span_ticks : array_like, shape (2,)
        Count increments ``(left, right)`` since the last fused counts [ticks].
    predicted_ticks : array_like, shape (2,)
        The model's predicted travel of each wheel over the same span [ticks].
    frame_jump_ticks : float
        ``max | |d_k| - |d_(k-1)| |`` over the wheels: change of this frame's
        increment from the last one [ticks].
    span_jump_ticks : float
        The largest such change over the earlier frames of the span [ticks].
    periods : int
        Periods the span covers.
    max_jump_ticks : float
        Largest plausible frame-to-frame change; a wheel's speed changes by
        about one tick per period (2 m/s^2 for 15 ms at 0.44 mm/tick), a
        spike or a frozen encoder that resumes by tens or hundreds.

    Returns
    -------
    {"jump", "broken", "consistent"}
        ``"jump"``: this frame's increment jumped (wait for a clean frame);
        ``"broken"``: a wheel counted at most one tick while predicted to turn
        at least half a tick a period (frozen), or an earlier frame of the
        span jumped: renew the reference and give up the span's motion;
        ``"consistent"``: both wheels counted steadily, so the model is what
        misses (a transient it does not follow) and the counts are fused.

    Examples
    --------
    >>> span_verdict(np.array([0, 60]), np.array([64.0, 64.0]), 0.0, 0.0, periods=16,
    ...              max_jump_ticks=10)
    'broken'
    >>> span_verdict(np.array([40, 41]), np.array([64.0, 64.0]), 0.0, 1.0, periods=16,
    ...              max_jump_ticks=10)
    'consistent'
    """
    if frame_jump_ticks > max_jump_ticks:
        return "jump"
    flat = np.abs(span_ticks) <= 1
    frozen = np.any(flat & (np.abs(predicted_ticks) >= 0.5 * periods))
    if frozen or span_jump_ticks > max_jump_ticks:
        return "broken"
    return "consistent"


def landmark_measurement(x: np.ndarray, landmark_xy: np.ndarray, *,
                         sensor: SensorPose | None = None) -> np.ndarray:
    """Predicted ``(range [m], bearing [rad])`` of a landmark from the state's pose, (2,).

    ``sensor`` is the sensor's mount on the robot (default centred);
    :func:`fusion.range_bearing.range_bearing`, eq. 1.
    """
    return range_bearing(x, landmark_xy, sensor=sensor)


def landmark_jacobian(x: np.ndarray, landmark_xy: np.ndarray, *,
                      sensor: SensorPose | None = None) -> np.ndarray:
    """Jacobian of :func:`landmark_measurement`, shape (2, n): the pose columns, zeros elsewhere.

    The pose columns are :func:`fusion.range_bearing.range_bearing_jacobian`
    (eq. 2 there) for the sensor's mount ``sensor`` (default centred).

    Raises
    ------
    LandmarkGeometryError
        If the sensor stands on the landmark.
    """
    out = np.zeros((2, len(x)))
    out[:, :3] = range_bearing_jacobian(x, landmark_xy, sensor=sensor)
    return out


def landmark_terms(x: np.ndarray, landmark_xy: np.ndarray, *,
                   sensor: SensorPose | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`landmark_measurement` and :func:`landmark_jacobian` in one evaluation.

    Returns
    -------
    z : ndarray, shape (2,)
        ``(range [m], bearing [rad])``, the range floored at
        :data:`fusion.range_bearing.MIN_RANGE_M` (the caller skips such a sighting).
    H : ndarray, shape (2, n)
        The pose columns of :func:`fusion.range_bearing.range_bearing_terms`, zeros elsewhere.
    """
    z, h_pose, _ = range_bearing_terms(x, landmark_xy, sensor=sensor)
    out = np.zeros((2, len(x)))
    out[:, :3] = h_pose
    return z, out


#: ``a - b`` of range-bearing vectors with the bearing wrapped (filterpy's ``residual``).
landmark_residual = range_bearing_residual


def pose_measurement(x: np.ndarray) -> np.ndarray:
    """The pose ``(x, y, theta)`` of the state, shape (3,): an absolute pose fix."""
    return np.array(x[:3], dtype=float).reshape(3)


def pose_jacobian(x: np.ndarray) -> np.ndarray:
    """``[I 0]``, shape (3, n)."""
    out = np.zeros((3, len(x)))
    out[:, :3] = np.eye(3)
    return out


def pose_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` for poses ``(..., 3)``, heading wrapped to ``(-pi, pi]``."""
    d = np.subtract(a, b, dtype=float)
    d[..., 2] = wrap_angle(d[..., 2])
    return d


def state_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` for full states ``(..., n)``, heading wrapped (a UKF's ``residual_x``)."""
    return pose_residual(a, b)


def state_mean(sigmas: np.ndarray, Wm: np.ndarray) -> np.ndarray:
    """Weighted mean of states, the heading as a circular mean (a UKF's ``x_mean_fn``).

    Parameters
    ----------
    sigmas : ndarray, shape (m, n)
        Sigma points.
    Wm : ndarray, shape (m,)
        Mean weights.

    Returns
    -------
    ndarray, shape (n,)
        The heading is ``atan2(sum W sin, sum W cos)`` moved to the branch
        nearest the first sigma point's heading (headings stay continuous).
    """
    out = np.asarray(Wm) @ np.asarray(sigmas)
    ref = sigmas[0, 2]
    mean = math.atan2(float(Wm @ np.sin(sigmas[:, 2])), float(Wm @ np.cos(sigmas[:, 2])))
    out[2] = ref + float(wrap_angle(mean - ref))
    return out


# -- start ------------------------------------------------------------------------------------
def initial_state(fm: FilterModel, pose: np.ndarray, *, z: np.ndarray | None = None
                  ) -> np.ndarray:
    """A start state: the pose, zero scale errors (3), the model state (zeros: at rest), ``C z``.

    With a gyro (``fm.gyro``) a zero bias and the heading clone (the start heading)
    sit between the scale errors and the model state.

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    MeasurementShapeError
        If ``pose`` is not (3,) or ``z`` not (nz,).
    NonFiniteInputError
        If either is not finite.
    """
    pose = np.asarray(pose, dtype=float)
    zz = np.zeros(fm.nz) if z is None else np.asarray(z, dtype=float)
    if pose.shape != (3,) or zz.shape != (fm.nz,):
        raise MeasurementShapeError(f"expected pose (3,) and z ({fm.nz},), got {pose.shape} "
                                    f"and {zz.shape}")
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(zz))):
        raise NonFiniteInputError("the start pose and model state must be finite")
    gyro = () if fm.gyro is None else (0.0, pose[2])
    return np.concatenate([pose, np.zeros(3), gyro, zz,
                           fm.model.C @ zz + fm.model.offset_speeds])


def initial_covariance(fm: FilterModel, *, pose_std: tuple[float, float, float] = (0.01, 0.01,
                       0.01), z_cov: np.ndarray | None = None) -> np.ndarray:
    """A start covariance: independent pose, scale errors, model state and its speed.

    Parameters
    ----------
    fm : FilterModel
        Layout (``fm.scale_prior_std`` for the three scale errors).
    pose_std : tuple of 3 float
        ``(x [m], y [m], theta [rad])`` standard deviations.
    z_cov : ndarray, shape (nz, nz), optional
        Covariance of ``z``; default the model's ``Q`` (one step of its own
        uncertainty: right for a robot at rest).

    Returns
    -------
    ndarray, shape (n, n)
        ``blkdiag(diag(pose_std^2), diag(prior^2), [[P_z, P_z C^T], [C P_z,
        C P_z C^T + R]])``.

    Raises
    ------
    FilterOptionError
        For non-positive standard deviations or a ``z_cov`` that is not SPD.
    MeasurementShapeError
        If ``z_cov`` is not (nz, nz).
    """
    std = np.asarray(pose_std, dtype=float)
    if std.shape != (3,) or not np.all(std > 0) or not np.all(np.isfinite(std)):
        raise FilterOptionError(f"pose_std must be three positive numbers, got {pose_std}")
    pz = fm.model.Q if z_cov is None else np.asarray(z_cov, dtype=float)
    if pz.shape != (fm.nz, fm.nz):
        raise MeasurementShapeError(f"expected z_cov of shape ({fm.nz}, {fm.nz}), got {pz.shape}")
    if not np.allclose(pz, pz.T) or np.linalg.eigvalsh(0.5 * (pz + pz.T)).min(initial=1.0) <= 0:
        raise FilterOptionError("z_cov must be symmetric positive definite")
    c = fm.model.C
    zs, ss = fm.model_slice, fm.speed_slice
    p = np.zeros((fm.n, fm.n))
    p[POSE, POSE] = np.diag(std ** 2)
    p[SCALES, SCALES] = np.diag(np.square(fm.scale_prior_std))
    if fm.gyro is not None:         # the bias prior; the clone is the heading itself
        p[GYRO_BIAS, GYRO_BIAS] = fm.gyro.bias_prior_std_rad_s ** 2
        p[HEADING_CLONE, HEADING_CLONE] = p[2, HEADING_CLONE] = p[HEADING_CLONE, 2] = std[2] ** 2
    p[zs, zs] = pz
    p[zs, ss] = pz @ c.T
    p[ss, zs] = c @ pz
    p[ss, ss] = c @ pz @ c.T + fm.model.R
    return 0.5 * (p + p.T)
