"""Calibration by driving: the paper's three manoeuvres run through any robot, then fitted.

1. Rotation in place: the encoder scale from the period of the light-bump
   signals in ticks (paper eq. 13, :mod:`lti_motion.calibration.encoder_scale`).
2. Steps on one motor at a time: the moving-average (FIR) model (paper section II.B).
3. Random held normal commands: the ARX model with order and delay selection
   (paper section II.C, III.C).

A *robot* is anything with a sensor period ``dt_s`` [s] and a method
``step(cmd_m_s) -> SensorFrame`` that sends one pair of wheel commands and
returns the next frame (and, optionally, ``discard_buffered()``, called before
each manoeuvre, that drops frames which waited unread): the simulator
(:class:`drivers.sim.Simulator`) and the serial driver
(:class:`drivers.roomba.Roomba`) both are. This module only
duck-types them, so the core imports neither.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Literal, Protocol

import numpy as np

from lti_motion.calibration.encoder_scale import (
    RotationPeriod,
    encoder_scale_m_per_tick,
    rotation_period_ticks,
)
from lti_motion.exceptions import CalibrationError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.model.excitation import (
    StepSequence,
    random_held_normal,
    rotation_in_place,
    step_sequence,
)
from lti_motion.model.motion_model import MotionModel, fit_arx, fit_fir_from_steps
from lti_motion.model.output_error import OutputErrorOptions, refine_model
from lti_motion.recordings.frames import FrameLog, SensorFrame
from lti_motion.recordings.recording import Recording
from lti_motion.recordings.resample import on_grid
from lti_motion.recordings.ticks import unwrap_ticks

__all__ = [
    "Calibration",
    "CalibrationPlan",
    "Robot",
    "calibrate",
    "drive",
    "phases_as_applied",
    "speeds_from_log",
]

_log = logging.getLogger(__name__)

#: Horizons [s] of the output-error criterion of ``arx_criterion="output_scales"``
#: (those of :class:`~lti_motion.model.OutputErrorOptions`).
OUTPUT_SCALE_HORIZONS_S = (1.0, 3.0, 10.0, 30.0)


class Robot(Protocol):
    """What calibration needs of a robot or a simulator."""

    dt_s: float

    def step(self, cmd_m_s: np.ndarray) -> SensorFrame:
        """Send wheel commands (left, right) [m/s]; return the next frame."""


@dataclass(frozen=True)
class CalibrationPlan:
    """The manoeuvres and their sizes.

    Attributes
    ----------
    rotation_turns, rotation_speed_m_s : float
        Turns in place for the encoder scale, and the wheel speed of the turn.
    step_amplitude_m_s, step_hold_s, step_rest_s : float
        Step manoeuvre: size, time on, time at rest.
    excitation_s, excitation_std_m_s, excitation_mean_m_s : float
        Random excitation: duration [s], standard deviation and mean of the
        wheel commands [m/s]. A zero mean keeps the robot near where it starts.
    excitation_correlation : float
        Correlation of successive held values (see
        :func:`~lti_motion.model.random_held_normal`).
    hold_s : tuple of float
        Range of the random hold durations [s]. Longer holds and correlated
        levels keep most of the record out of the traction- and
        current-limited transients that no linear model follows
        (docs/calibration.md has the measurements).
    validation_fraction : float
        Tail of the excitation held out to choose the ARX order and delay.
    dc_gain : {"wheel_servo", "free"}
        Steady-state gain of the ARX fit (:func:`~lti_motion.model.fit_arx`).
        ``"wheel_servo"`` (default): the robot servoes each wheel on the
        encoders that measure ``y``, so the gain is one scale times the
        wheel-to-body matrix; this removes the straight-line yaw scatter of
        a free fit (docs/route.md).
    fir_dc_gain : {"wheel_servo", "settled", "free"}
        Steady-state gain of the FIR from steps
        (:func:`~lti_motion.model.fir_from_steps`). ``"free"`` is the
        paper's (the step response at the last tap, one sample);
        ``"settled"`` the mean of the settled part of each response;
        ``"wheel_servo"`` (default) the wheel-servo gain ``c M`` nearest it
        (docs/route.md has the measurements).
    arx_criterion : {"equation", "output_scales", "output_error"}
        The ARX fit: least squares on the equation error (default); that fit
        with ``v`` and ``w`` scaled to minimise the output-error criterion
        over 1, 3, 10 and 30 s (``"output_scales"``: the wheel-servo
        structure and the least-squares dynamics kept,
        :func:`lti_motion.model.output_scales`); or all its
        coefficients refined on the output-error criterion without offset
        (:func:`lti_motion.model.refine_model`), which frees the
        wheel-servo gain and closes the simulator's route worse
        (docs/calibration.md has the measurements).
    seed : int
        Seed of the random excitation.
    """

    rotation_turns: float = 3.0
    rotation_speed_m_s: float = 0.15
    step_amplitude_m_s: float = 0.3
    step_hold_s: float = 2.0
    step_rest_s: float = 2.0
    excitation_s: float = 180.0
    excitation_std_m_s: float = 0.2
    excitation_mean_m_s: float = 0.0
    excitation_correlation: float = 0.85
    hold_s: tuple[float, float] = (0.5, 2.0)
    validation_fraction: float = 0.3
    dc_gain: Literal["wheel_servo", "free"] = "wheel_servo"
    fir_dc_gain: Literal["wheel_servo", "settled", "free"] = "wheel_servo"
    arx_criterion: Literal["equation", "output_scales", "output_error"] = "equation"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.arx_criterion not in ("equation", "output_scales", "output_error"):
            raise ValueError("arx_criterion must be 'equation', 'output_scales' or "
                             f"'output_error', got {self.arx_criterion!r}")


@dataclass(frozen=True)
class Calibration:
    """What calibration found, and the data it used.

    Attributes
    ----------
    m_per_tick : float
        Encoder scale [m/tick] (paper eq. 13).
    rotation : RotationPeriod
        The period estimate behind it (with its confidence).
    fir, arx : MotionModel
        The two calibrated models.
    logs : dict of str to FrameLog
        ``"rotation"``, ``"steps"`` and ``"excitation"`` frames.
    """

    m_per_tick: float
    rotation: RotationPeriod
    fir: MotionModel
    arx: MotionModel
    logs: dict[str, FrameLog] = field(repr=False)


def drive(robot: Robot, cmd_m_s: np.ndarray, *,
          progress: Callable[[int, int], None] | None = None) -> FrameLog:
    """Send one command pair per sensor period and collect the frames.

    Parameters
    ----------
    robot : Robot
        Simulator or serial driver. A single simulator's whole-sequence
        ``run`` is used when it has one (the same frames, faster). A robot
        with a ``log_meta()`` method adds what it returns to the log's meta
        (the serial driver: port, baud, link counters).
    cmd_m_s : array_like, shape (n, 2)
        Wheel commands (left, right) [m/s], ``n >= 1``.
    progress : callable, optional
        Called as ``progress(done, total)`` every 100 periods and at the end.

    Returns
    -------
    FrameLog
        The ``n`` frames, lost ones marked invalid.

    Raises
    ------
    ValueError
        If the commands are not a finite array of shape (n, 2) with n >= 1.

    Examples
    --------
    >>> from drivers.sim.simulator import Simulator
    >>> log = drive(Simulator("create2", seed=0), np.full((10, 2), 0.2))
    >>> len(log), bool(log.ticks[-1, 0] > 0)
    (10, True)
    """
    cmd_m_s = np.asarray(cmd_m_s, dtype=float)
    if cmd_m_s.ndim != 2 or cmd_m_s.shape[1] != 2 or len(cmd_m_s) == 0:
        raise ValueError(
            f"commands must have shape (n, 2) with n >= 1, got {cmd_m_s.shape}")
    if not np.all(np.isfinite(cmd_m_s)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(cmd_m_s))[0])
        raise ValueError(f"commands must be finite; first bad value at index {bad}")
    n = len(cmd_m_s)
    meta = {"source": type(robot).__name__, "n_commands": n}
    if hasattr(robot, "log_meta"):
        meta.update(robot.log_meta())
    if hasattr(robot, "run") and not getattr(robot, "batch", False):
        out = robot.run(cmd_m_s)
        if progress is not None:
            progress(n, n)
        return replace(out, meta={**out.meta, **meta})
    frames = []
    for k, cmd in enumerate(cmd_m_s):
        frames.append(robot.step(cmd))
        if progress is not None and (k % 100 == 99 or k == n - 1):
            progress(k + 1, n)
    if hasattr(robot, "log_meta"):
        meta.update(robot.log_meta())        # the link counters after the drive
    return FrameLog.from_frames(frames, dt_s=robot.dt_s, meta=meta)


def speeds_from_log(log: FrameLog, *, m_per_tick: float | None = None,
                    wheel_base_m: float | None = None,
                    intrinsics: OdometryIntrinsics | None = None,
                    encoders: Literal["quadrature", "commanded"] = "commanded",
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Commands and encoder body speeds, aligned for identification.

    Frame ``k`` closes period ``k``, whose command ``u[k]`` went out at its
    start; the body speeds ``y[k]`` are the encoder speeds over that period,
    timed on the robot's sensor clock fitted to the frame times
    (:func:`lti_motion.recordings.assign_periods`: jitter, drift, late and
    duplicated frames never raise). Frames marked invalid (lost) are skipped:
    the next valid frame's counts span the gap (:func:`lti_motion.recordings.on_grid`).
    ``encoders="commanded"`` (the default, for the Roomba / Create 2 and the
    simulator) restores the wheels' direction around reversals. The encoder scale is
    ``m_per_tick`` and ``wheel_base_m``, or each wheel's in ``intrinsics``.

    Returns
    -------
    cmd_m_s : ndarray, shape (P, 2)
        Wheel commands (left, right) [m/s] of periods ``1 .. P`` (``P = n - 1``
        when no period was lost after the last frame).
    speeds : ndarray, shape (P, 2)
        Body speeds (v [m/s], w [rad/s]) over the same periods.
    """
    if intrinsics is not None:                      # each wheel's own scale
        m_per_tick = np.array([intrinsics.m_per_tick_left, intrinsics.m_per_tick_right])
        wheel_base_m = intrinsics.wheel_base_m
    grid = on_grid(Recording.from_frame_log(log), wheel_base_m=wheel_base_m,
                   m_per_tick=m_per_tick, encoders=encoders)
    return grid.cmd_m_s, grid.speeds


def phases_as_applied(steps: StepSequence, cmd_m_s: np.ndarray, *,
                      max_lag: int) -> tuple[slice, slice, slice, slice]:
    """The step phases where the recorded commands put them.

    A robot applies a command one or more periods after the host planned it
    when the host answers late (frames waiting in a buffer, G17); its frames
    record the command it applied (packets 41/42). Each phase starts at the
    first sample, from its planned start on, whose recorded command is the
    phase's; it ends where the next one starts (the last one where the
    planned length or the data ends). A simulator applies every command on
    time, and the phases are the planned ones.

    Parameters
    ----------
    steps : StepSequence
        The planned manoeuvre; ``steps.cmd_m_s[k]`` was sent for sample ``k``.
    cmd_m_s : ndarray, shape (n, 2)
        Recorded (applied) wheel commands [m/s], sample 0 aligned with the plan's.
    max_lag : int
        Most periods a command may land late.

    Returns
    -------
    tuple of four slices
        Left on, left off, right on, right off, in samples of ``cmd_m_s``.

    Raises
    ------
    CalibrationError
        If a phase's command does not appear within ``max_lag`` periods of its plan.

    Examples
    --------
    >>> seq = step_sequence(amplitude_m_s=0.2, hold_s=0.06, rest_s=0.03, dt_s=0.015)
    >>> late = np.concatenate([np.zeros((1, 2)), seq.cmd_m_s[:-1]])   # one period late
    >>> phases_as_applied(seq, late, max_lag=3)
    (slice(1, 5, None), slice(5, 7, None), slice(7, 11, None), slice(11, 12, None))
    """
    starts = []
    for phase in steps.phases:
        level = steps.cmd_m_s[phase.start]
        window = cmd_m_s[phase.start:phase.start + max_lag + 1]
        hit = np.flatnonzero(np.all(np.abs(window - level) < 5e-4, axis=1))   # mm/s rounding
        if hit.size == 0:
            raise CalibrationError(
                f"the robot did not apply the step command {level.tolist()} m/s within "
                f"{max_lag} periods of sample {phase.start}; its link is too slow or the "
                "commands were lost")
        starts.append(phase.start + int(hit[0]))
    last = steps.phases[-1]
    ends = [*starts[1:], min(starts[-1] + last.stop - last.start, len(cmd_m_s))]
    return tuple(slice(a, b) for a, b in zip(starts, ends, strict=True))


def _stage_commands(plan: CalibrationPlan, *, wheel_base_m: float, dt_s: float,
                    ) -> tuple[dict[str, np.ndarray], StepSequence, int]:
    """The wheel commands of the three manoeuvres, the step plan, and the rest length."""
    rest = np.zeros((round(1.0 / dt_s), 2))
    rot_cmd = np.concatenate([rest, rotation_in_place(
        turns=plan.rotation_turns, wheel_speed_m_s=plan.rotation_speed_m_s,
        wheel_base_m=wheel_base_m, dt_s=dt_s), rest])
    steps = step_sequence(amplitude_m_s=plan.step_amplitude_m_s, hold_s=plan.step_hold_s,
                          rest_s=plan.step_rest_s, dt_s=dt_s)
    rng = np.random.default_rng(plan.seed)
    exc_cmd = random_held_normal(n=round(plan.excitation_s / dt_s), dt_s=dt_s, rng=rng,
                                 std_m_s=plan.excitation_std_m_s,
                                 mean_m_s=plan.excitation_mean_m_s, hold_s=plan.hold_s,
                                 correlation=plan.excitation_correlation)
    commands = {"rotation": rot_cmd, "steps": np.concatenate([rest, steps.cmd_m_s]),
                "excitation": np.concatenate([rest, exc_cmd, rest])}
    return commands, steps, len(rest)


def _recorded_or_driven(robot: Robot, name: str, cmd_m_s: np.ndarray, *,
                        recorded: Mapping[str, FrameLog],
                        progress: Callable[[str, int, int], None] | None,
                        before_stage: Callable[[str], None] | None,
                        after_stage: Callable[[str, FrameLog], None] | None) -> FrameLog:
    """One manoeuvre: its recorded log if there is one (checked against the plan), else driven."""
    if name in recorded:
        log = recorded[name]
        if len(log) != len(cmd_m_s) or abs(log.dt_s - robot.dt_s) > 1e-12:
            raise CalibrationError(
                f"the recorded {name} has {len(log)} frames of {log.dt_s:g} s; this plan drives "
                f"{len(cmd_m_s)} of {robot.dt_s:g} s. Drive it again, or calibrate with the "
                "options it was recorded with")
        _log.info("%s: the recorded log of %d frames, not driven again", name, len(log))
        return log
    if before_stage is not None:
        before_stage(name)
    if hasattr(robot, "discard_buffered"):      # a serial robot: frames that waited unread
        robot.discard_buffered()                # (a prompt, computing) would delay every command
    log = drive(robot, cmd_m_s, progress=None if progress is None
                else (lambda d, t: progress(name, d, t)))
    if after_stage is not None:
        after_stage(name, log)
    return log


def calibrate(robot: Robot, *, wheel_base_m: float, plan: CalibrationPlan | None = None,
              floor: str | None = None,
              progress: Callable[[str, int, int], None] | None = None,
              before_stage: Callable[[str], None] | None = None,
              after_stage: Callable[[str, FrameLog], None] | None = None,
              recorded: Mapping[str, FrameLog] | None = None) -> Calibration:
    """Run the three manoeuvres on ``robot`` and fit the encoder scale, FIR and ARX models.

    Parameters
    ----------
    robot : Robot
        Simulator or serial driver, standing where it can turn in place near
        walls or furniture (the light-bump sensors must see something).
    wheel_base_m : float
        Nominal wheel base [m], the one constant the paper assumes known.
    plan : CalibrationPlan, optional
        Manoeuvre sizes; defaults as in :class:`CalibrationPlan`.
    floor : str, optional
        Name of the floor, recorded in the models.
    progress : callable, optional
        ``progress(stage, done, total)`` while driving.
    before_stage : callable, optional
        ``before_stage(stage)`` before each manoeuvre (``"rotation"``,
        ``"steps"``, ``"excitation"``): the place to move the robot, e.g. from
        beside the furniture it turns next to out to open floor where the
        random excitation cannot hit anything. Wall contact corrupts the fit.
    after_stage : callable, optional
        ``after_stage(stage, log)`` as soon as a manoeuvre has been driven:
        the place to save its log, so that a later failure loses nothing.
    recorded : mapping of str to FrameLog, optional
        Manoeuvres already driven (e.g. saved by ``after_stage`` in a run that
        was stopped): used instead of driving them again, neither
        ``before_stage`` nor ``after_stage`` is called for them.

    Returns
    -------
    Calibration

    Raises
    ------
    lti_motion.exceptions.CalibrationError
        If a manoeuvre's data cannot give a model (no periodic signal, not
        excited, unstable fit), or a recorded log does not have the plan's
        length; the message says which and what to do.
    """
    plan = plan or CalibrationPlan()
    dt = robot.dt_s
    commands, steps, n_rest = _stage_commands(plan, wheel_base_m=wheel_base_m, dt_s=dt)
    hooks = {"recorded": recorded or {}, "progress": progress, "before_stage": before_stage,
             "after_stage": after_stage}

    rot_log = _recorded_or_driven(robot, "rotation", commands["rotation"], **hooks)
    ticks = unwrap_ticks(rot_log.ticks[rot_log.valid])
    rotation = rotation_period_ticks(rot_log.light_bump[rot_log.valid],
                                     ticks[:, 1] - ticks[:, 0])
    scale = encoder_scale_m_per_tick(rotation.period_ticks, wheel_base_m=wheel_base_m)
    _log.info("encoder scale %.6g m/tick from a period of %.1f ticks (confidence %.3f)",
              scale, rotation.period_ticks, rotation.confidence)

    step_log = _recorded_or_driven(robot, "steps", commands["steps"], **hooks)
    u_s, y_s = speeds_from_log(step_log, m_per_tick=scale, wheel_base_m=wheel_base_m)
    lead = n_rest - 1        # speeds_from_log drops the first frame
    u_s, y_s = u_s[lead:], y_s[lead:]
    step_phases = phases_as_applied(steps, u_s, max_lag=n_rest)

    exc_log = _recorded_or_driven(robot, "excitation", commands["excitation"], **hooks)
    u_x, y_x = speeds_from_log(exc_log, m_per_tick=scale, wheel_base_m=wheel_base_m)

    common = {"dt_s": dt, "wheel_base_m": wheel_base_m, "m_per_tick": scale, "floor": floor}
    arx = fit_arx([(u_x, y_x)], validation=plan.validation_fraction, dc_gain=plan.dc_gain,
                  output_scale_horizons_s=(OUTPUT_SCALE_HORIZONS_S
                                           if plan.arx_criterion == "output_scales" else None),
                  **common)
    if plan.arx_criterion == "output_error":
        arx = refine_model(arx, [(u_x, y_x)], options=OutputErrorOptions(offset=False))
    fir = fit_fir_from_steps(u_s, y_s, phases=step_phases, noise_runs=[(u_x, y_x)],
                             dc_gain=plan.fir_dc_gain, **common)
    return Calibration(m_per_tick=scale, rotation=rotation, fir=fir, arx=arx,
                       logs={"rotation": rot_log, "steps": step_log, "excitation": exc_log})
