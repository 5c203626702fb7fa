"""Calibration manoeuvres as command sequences, and checks that data excites the system.

A manoeuvre is an array ``(n, 2)`` of wheel-speed commands ``(L, R)`` [m/s],
one row per sample period ``dt_s``. Three manoeuvres come from the paper:

- :func:`step_sequence`: one motor at a time, for the moving-average (FIR)
  model (paper section II.B and III.B);
- :func:`random_held_normal`: normally distributed commands held for random
  durations, for the ARX model (paper section III.C, Fig. 7);
- :func:`rotation_in_place`: the rotation that measures the encoder scale
  (paper eq. 13).

Calibration data is a list of *runs*, each a pair ``(u, y)`` of commands
``(n, 2)`` [m/s] and measured body speeds ``(n, 2)`` = ``(v [m/s], w
[rad/s])``. :func:`check_runs` validates them and :func:`check_excitation`
tests that the commands are persistently exciting (Ljung 1999, section 13.2).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from lti_motion.exceptions import NonFiniteError, NotExcitedError, ShapeError

__all__ = [
    "DEFAULT_MAX_CONDITION",
    "StepSequence",
    "check_excitation",
    "check_runs",
    "excitation_condition_number",
    "random_held_normal",
    "rotation_in_place",
    "step_sequence",
]

_log = logging.getLogger(__name__)

#: Largest condition number of the column-scaled lagged-command matrix that
#: still counts as exciting. Held random commands give 10-1000; constant,
#: one-motor or collinear commands give more than 1e12.
DEFAULT_MAX_CONDITION = 1e6

_CHANNELS = MappingProxyType({"u": ("L", "R"), "y": ("v", "w")})


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


def _samples(duration_s: float, dt_s: float, name: str) -> int:
    """Whole samples in a duration, at least one."""
    return max(1, round(_positive(duration_s, name) / dt_s))


@dataclass(frozen=True)
class StepSequence:
    """The step manoeuvre of paper section II.B / III.B and where its phases lie.

    Attributes
    ----------
    cmd_m_s : ndarray, shape (n, 2)
        Wheel-speed commands ``(L, R)`` [m/s].
    left_on, left_off, right_on, right_off : slice
        Sample ranges of the four phases: left motor on, left off (robot comes
        to rest), right motor on, right off. ``cmd_m_s[seq.left_on]``
        selects a phase.
    amplitude_m_s : float
        Step size [m/s].
    dt_s : float
        Sample period [s].
    """

    cmd_m_s: np.ndarray
    left_on: slice
    left_off: slice
    right_on: slice
    right_off: slice
    amplitude_m_s: float
    dt_s: float

    @property
    def phases(self) -> tuple[slice, slice, slice, slice]:
        """The four phases in order (left on, left off, right on, right off)."""
        return (self.left_on, self.left_off, self.right_on, self.right_off)


def step_sequence(
    *, amplitude_m_s: float, hold_s: float, rest_s: float, dt_s: float
) -> StepSequence:
    """Steps on one motor at a time: left on, stop, right on, stop.

    Parameters
    ----------
    amplitude_m_s : float
        Step size [m/s], non-zero; within the robot's limits.
    hold_s : float
        How long each motor stays on [s]; longer than the settling time.
    rest_s : float
        How long to wait after each stop [s], long enough for the robot to
        stand still (the response is recorded over ``min(hold_s, rest_s)``).
    dt_s : float
        Sample period [s].

    Returns
    -------
    StepSequence
        The commands and the sample ranges of the four phases. The robot must
        stand still when the sequence starts.

    Raises
    ------
    ValueError
        If a duration is not positive or the amplitude is zero or not finite.

    Notes
    -----
    Paper section II.B: the impulse response is the derivative of the step response,
    so a step per motor gives the four responses of the transfer matrix
    (eq. 8-10); III.B lists the four phases.

    Examples
    --------
    >>> seq = step_sequence(amplitude_m_s=0.2, hold_s=0.06, rest_s=0.03, dt_s=0.015)
    >>> seq.cmd_m_s[:, 0].tolist()
    [0.2, 0.2, 0.2, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    >>> seq.right_on
    slice(6, 10, None)
    """
    dt_s = _positive(dt_s, "dt_s")
    amp = float(amplitude_m_s)
    if not math.isfinite(amp) or amp == 0.0:
        raise ValueError(f"amplitude_m_s must be a finite non-zero speed, got {amplitude_m_s!r}")
    n_on = _samples(hold_s, dt_s, "hold_s")
    n_off = _samples(rest_s, dt_s, "rest_s")
    commands = np.zeros((2 * (n_on + n_off), 2))
    commands[:n_on, 0] = amp
    commands[n_on + n_off : 2 * n_on + n_off, 1] = amp
    return StepSequence(
        cmd_m_s=commands,
        left_on=slice(0, n_on),
        left_off=slice(n_on, n_on + n_off),
        right_on=slice(n_on + n_off, 2 * n_on + n_off),
        right_off=slice(2 * n_on + n_off, 2 * (n_on + n_off)),
        amplitude_m_s=amp,
        dt_s=dt_s,
    )


def random_held_normal(
    *,
    n: int,
    dt_s: float,
    rng: np.random.Generator,
    std_m_s: float,
    mean_m_s: float = 0.0,
    hold_s: tuple[float, float] = (0.1, 0.8),
    max_m_s: float = 0.5,
    correlation: float = 0.0,
) -> np.ndarray:
    """Normally distributed wheel commands held for random durations (paper section III.C).

    Parameters
    ----------
    n : int
        Number of samples.
    dt_s : float
        Sample period [s].
    rng : numpy.random.Generator
        Source of randomness (seed it for reproducible manoeuvres).
    std_m_s : float
        Standard deviation of the commands [m/s].
    mean_m_s : float
        Mean command [m/s]; 0 drives forwards and backwards equally.
    hold_s : (float, float)
        Each value is held for a duration drawn uniformly from
        ``[hold_s[0], hold_s[1]]`` [s], rounded to whole samples (at least one).
    max_m_s : float
        Commands are clipped to ``[-max_m_s, max_m_s]`` (0.5 m/s on a Create 2).
    correlation : float
        Correlation ``rho`` in ``[0, 1)`` between successive held values of a
        wheel: ``x[i] = mean + rho (x[i-1] - mean) + sqrt(1 - rho^2) std n[i]``,
        a stationary AR(1) whose values are still normal with the given mean
        and standard deviation. With ``rho`` near 0.85 the level wanders over
        the whole range while each step stays moderate, so less of the record
        is spent in the traction- and current-limited transients no linear
        model follows (docs/calibration.md).

    Returns
    -------
    ndarray, shape (n, 2)
        Commands ``(L, R)`` [m/s]; the wheels are drawn independently.

    Raises
    ------
    ValueError
        If ``n < 1``, a duration or ``std_m_s`` is not positive,
        ``hold_s`` is not increasing, or ``correlation`` is outside ``[0, 1)``.

    Notes
    -----
    Holding values for random durations spreads the input spectrum over the
    band of the wheel dynamics, and independent wheels keep ``L`` and ``R``
    uncorrelated, so both the linear and the angular speed are excited
    (persistence of excitation, Ljung 1999, section 13.2).

    Examples
    --------
    >>> u = random_held_normal(n=500, dt_s=0.015, rng=np.random.default_rng(1), std_m_s=0.2)
    >>> u.shape, bool(np.abs(u).max() <= 0.5)
    ((500, 2), True)
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer number of samples, got {n!r}")
    dt_s = _positive(dt_s, "dt_s")
    std = _positive(std_m_s, "std_m_s")
    limit = _positive(max_m_s, "max_m_s")
    lo, hi = (float(h) for h in hold_s)
    if not (0 < lo <= hi and math.isfinite(hi)):
        raise ValueError(f"hold_s must be (min, max) with 0 < min <= max, got {hold_s!r}")
    if not 0.0 <= correlation < 1.0:
        raise ValueError(f"correlation must be in [0, 1), got {correlation!r}")
    lo_n, hi_n = _samples(lo, dt_s, "hold_s"), _samples(hi, dt_s, "hold_s")
    n_holds = n // lo_n + 1  # enough holds to cover n samples
    out = np.empty((n, 2))
    for wheel in range(2):
        lengths = rng.integers(lo_n, hi_n + 1, size=n_holds)
        values = rng.normal(0.0, std, size=n_holds)
        if correlation > 0.0:
            # imported here: scipy.signal costs 0.7 s to import, and only this filter needs it
            from scipy.signal import lfilter

            # stationary AR(1) over the held values (started in its stationary law)
            values[1:] *= math.sqrt(1.0 - correlation**2)
            values = lfilter([1.0], [1.0, -correlation], values)
        out[:, wheel] = np.repeat(values + float(mean_m_s), lengths)[:n]
    return np.clip(out, -limit, limit, out=out)


def rotation_in_place(
    *,
    turns: float,
    wheel_speed_m_s: float,
    wheel_base_m: float,
    dt_s: float,
    margin: float = 0.1,
) -> np.ndarray:
    """Commands that turn the robot in place, counter-clockwise, for the encoder scale.

    Parameters
    ----------
    turns : float
        Number of full turns wanted (positive).
    wheel_speed_m_s : float
        Speed of each wheel [m/s] (left backwards, right forwards).
    wheel_base_m : float
        Distance between the wheels [m].
    dt_s : float
        Sample period [s].
    margin : float
        Extra duration as a fraction (0.1 = 10 % more), for the spin-up and
        any slip.

    Returns
    -------
    ndarray, shape (n, 2)
        Rows ``(-s, +s)`` with ``n = ceil(turns * pi * b / s * (1 + margin) / dt)``.

    Raises
    ------
    ValueError
        If a parameter is not positive (``margin`` may be zero).

    Notes
    -----
    Turning in place at ``w = 2 s / b``, one turn takes ``pi b / s``: each
    wheel travels ``pi b`` per turn, the basis of paper eq. 13.

    Examples
    --------
    >>> u = rotation_in_place(turns=1, wheel_speed_m_s=0.1, wheel_base_m=0.235, dt_s=0.015,
    ...                       margin=0.0)
    >>> u.shape, u[0].tolist()
    ((493, 2), [-0.1, 0.1])
    """
    turns = _positive(turns, "turns")
    speed = _positive(wheel_speed_m_s, "wheel_speed_m_s")
    base = _positive(wheel_base_m, "wheel_base_m")
    dt_s = _positive(dt_s, "dt_s")
    margin = float(margin)
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a finite fraction >= 0, got {margin!r}")
    n = math.ceil(turns * math.pi * base / speed * (1.0 + margin) / dt_s)
    return np.tile([-speed, speed], (n, 1))


def _first_non_finite(arr: np.ndarray) -> tuple[int, int]:
    idx = np.argwhere(~np.isfinite(arr))[0]
    return int(idx[0]), int(idx[1])


def check_runs(
    runs: Sequence[tuple[np.ndarray, np.ndarray]], *, min_samples: int = 1
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Validate calibration runs and return them as float arrays.

    Parameters
    ----------
    runs : sequence of (u, y)
        Commands ``u`` (n_i, 2) [m/s] and measured body speeds ``y`` (n_i, 2)
        [m/s, rad/s] of each run. A single ``(u, y)`` pair of arrays is not a
        sequence of runs: wrap it in a list.
    min_samples : int
        Fewest samples a run may have.

    Returns
    -------
    list of (ndarray, ndarray)
        The runs as C-contiguous float64 arrays.

    Raises
    ------
    ShapeError
        If a run is not a pair, an array is not ``(n, 2)``, or ``u`` and ``y``
        differ in length (both shapes are given).
    NonFiniteError
        If a sample is NaN or infinite (the run, array, sample and channel
        are named).
    CalibrationError
        Never here; see the estimators for too-short data.

    Examples
    --------
    >>> check_runs([(np.zeros((3, 2)), np.zeros((2, 2)))])
    Traceback (most recent call last):
    ...
    lti_motion.exceptions.ShapeError: run 0: u has shape (3, 2) but y has shape (2, 2); ...
    """
    if isinstance(runs, tuple) and len(runs) == 2 and isinstance(runs[0], np.ndarray):
        raise ShapeError("runs must be a list of (u, y) pairs; wrap a single run as [(u, y)]")
    out = []
    for i, run in enumerate(runs):
        if not isinstance(run, (tuple, list)) or len(run) != 2:
            raise ShapeError(f"run {i}: expected a (u, y) pair, got {type(run).__name__}")
        u = np.ascontiguousarray(run[0], dtype=float)
        y = np.ascontiguousarray(run[1], dtype=float)
        for name, arr in (("u", u), ("y", y)):
            if arr.ndim != 2 or arr.shape[1] != 2:
                raise ShapeError(f"run {i}: expected {name} of shape (n, 2), got {arr.shape}")
        if u.shape != y.shape:
            raise ShapeError(
                f"run {i}: u has shape {u.shape} but y has shape {y.shape}; they must have "
                "the same length (one command per measured sample)"
            )
        if len(u) < min_samples:
            raise ShapeError(f"run {i}: needs at least {min_samples} samples, got {len(u)}")
        for name, arr in (("u", u), ("y", y)):
            if not np.all(np.isfinite(arr)):
                k, c = _first_non_finite(arr)
                raise NonFiniteError(
                    f"run {i}: {name}[{k}, {c}] ({_CHANNELS[name][c]}) is {arr[k, c]}; "
                    "remove or interpolate non-finite samples before calibrating"
                )
        out.append((u, y))
    if not out:
        raise ShapeError("runs is empty: give at least one (u, y) run")
    return out


def excitation_condition_number(u_runs: Sequence[np.ndarray], *, n_lags: int) -> float:
    """Condition number of the lagged-command matrix, columns scaled per channel.

    Parameters
    ----------
    u_runs : sequence of ndarray, shape (n_i, 2)
        Commands of each run [m/s].
    n_lags : int
        Number of consecutive lags (the input order ``nb`` of the model).

    Returns
    -------
    float
        ``sigma_max / sigma_min`` of the matrix whose rows are
        ``(u[n], u[n-1], ..., u[n-n_lags+1])``; ``inf`` when it is singular.

    Notes
    -----
    The commands are persistently exciting of order ``n_lags`` when the
    ``2 n_lags x 2 n_lags`` matrix of lagged products is non-singular (Ljung
    1999, section 13.2). The singular values come from the eigenvalues of
    that product matrix, so values above about 1e7 are only lower bounds.

    Examples
    --------
    >>> u = np.random.default_rng(0).normal(size=(400, 2))
    >>> bool(excitation_condition_number([u], n_lags=4) < 10)
    True
    >>> excitation_condition_number([np.ones((400, 2))], n_lags=2)
    inf
    """
    n_lags = int(n_lags)
    gram = np.zeros((2 * n_lags, 2 * n_lags))
    scale = np.sqrt(sum(np.sum(u * u, axis=0) for u in u_runs) / sum(len(u) for u in u_runs))
    if np.any(scale == 0):
        return math.inf
    for u in u_runs:
        if len(u) < n_lags:
            continue
        # rows (u[n], ..., u[n-n_lags+1]) as a strided view, then one copy
        win = sliding_window_view(u / scale, n_lags, axis=0)[:, :, ::-1]
        lagged = win.transpose(0, 2, 1).reshape(len(win), 2 * n_lags)
        gram += lagged.T @ lagged
    eig = np.linalg.eigvalsh(gram)
    if eig[0] <= eig[-1] * 1e-15 or eig[-1] <= 0:
        return math.inf
    return float(np.sqrt(eig[-1] / eig[0]))


def check_excitation(
    u_runs: Sequence[np.ndarray],
    *,
    n_lags: int,
    max_condition: float = DEFAULT_MAX_CONDITION,
    condition_number: float | None = None,
) -> float:
    """Raise :class:`NotExcitedError` unless the commands excite both wheels.

    Parameters
    ----------
    u_runs : sequence of ndarray, shape (n_i, 2)
        Commands of each run [m/s].
    n_lags : int
        Input order the model will use.
    max_condition : float
        Largest acceptable :func:`excitation_condition_number`.
    condition_number : float, optional
        The condition number when the caller already has it (the estimators
        read it off the triangular factor of their regression); computed
        otherwise.

    Returns
    -------
    float
        The condition number (for the fit diagnostics).

    Raises
    ------
    NotExcitedError
        With the condition number and the reason (a wheel constant, the two
        wheels collinear, or too slowly varying commands) and what to do.

    Examples
    --------
    >>> u = np.column_stack([np.linspace(0, 1, 300), np.zeros(300)])
    >>> check_excitation([u], n_lags=3)
    Traceback (most recent call last):
    ...
    lti_motion.exceptions.NotExcitedError: the calibration commands do not excite the system: ...
    """
    cond = (excitation_condition_number(u_runs, n_lags=n_lags) if condition_number is None
            else float(condition_number))
    if cond <= max_condition:
        return cond
    u = np.concatenate(list(u_runs))
    std = u.std(axis=0)
    spread = np.abs(u).max(axis=0)
    constant = std <= 1e-9 * np.maximum(spread, 1.0)
    if np.all(constant):
        reason = "the commands of both wheels are constant"
    elif np.any(constant):
        reason = (f"the command of wheel {'LR'[int(np.flatnonzero(constant)[0])]} is constant "
                  "(only one motor moving?)")
    else:
        corr = np.corrcoef(u.T)[0, 1]
        if abs(corr) > 0.999:
            reason = (f"the L and R commands are collinear (correlation {corr:.6f}): the robot "
                      "only drove straight or only turned in place")
        else:
            reason = f"the commands vary too little over {n_lags} consecutive samples"
    msg = (
        f"the calibration commands do not excite the system: {reason}; the condition number "
        f"of the lagged-command matrix is {cond:.3g} (limit {max_condition:.3g}). Drive both "
        "wheels independently with the random excitation "
        "(lti_motion.model.excitation.random_held_normal) and calibrate again."
    )
    _log.warning(msg)
    raise NotExcitedError(msg)
