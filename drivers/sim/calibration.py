"""Calibrating the simulator as a user calibrates a robot: one function for the CLI, the
demo and the examples (application layer)."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from drivers.sim.config import FloorMap, RobotParams, Room, floor_name, load_robot
from drivers.sim.simulator import Simulator
from lti_motion.calibration.manoeuvres import Calibration, CalibrationPlan, calibrate
from lti_motion.recordings.frames import FrameLog

__all__ = ["calibrate_simulator", "print_progress", "summarize", "wall_run_simulator"]


def print_progress(stage: str, done: int, total: int) -> None:
    """A one-line progress display for :func:`lti_motion.calibration.calibrate`."""
    end = "\n" if done >= total else ""
    print(f"\r  {stage:10s} {100 * done / total:5.1f}% ({done}/{total} frames)", end=end,
          flush=True)


def calibrate_simulator(robot: str | RobotParams = "create2", *, seed: int = 0,
                        floor: str | FloorMap | None = None,
                        plan: CalibrationPlan | None = None,
                        progress: Callable[[str, int, int], None] | None = None,
                        after_stage: Callable[[str, FrameLog], None] | None = None,
                        recorded: Mapping[str, FrameLog] | None = None) -> Calibration:
    """Calibrate a simulated robot: rotate beside the furniture of the cluttered room, then
    carry it to open floor for the steps and the random excitation.

    Parameters
    ----------
    robot : str or RobotParams
        Preset name, robot file (:func:`~drivers.sim.load_robot`) or parameters.
        The calibration is of the healthy robot: its own faults
        (:attr:`~drivers.sim.RobotParams.faults`) are left out.
    seed : int
        Simulator seed; also the excitation's unless ``plan`` says otherwise.
    floor : str or FloorMap, optional
        Floor to simulate (default the robot's); its name (a map's default surface) is
        recorded in the models.
    plan : CalibrationPlan, optional
        Manoeuvre sizes (default: :class:`CalibrationPlan` with ``seed``).
    progress : callable, optional
        ``progress(stage, done, total)``.
    after_stage, recorded
        As for :func:`lti_motion.calibration.calibrate`: save each manoeuvre's
        log as it ends; use logs saved before instead of driving again.
    """
    params = load_robot(robot) if isinstance(robot, str) else robot
    floor = params.floor if floor is None else floor
    sim = Simulator(params.replace(faults=()), seed=seed, floor=floor, room=Room.cluttered(),
                    initial_pose=Room.CALIBRATION_SPOT)

    def to_open_floor(stage: str) -> None:
        if stage != "rotation":
            sim.place(Room.OPEN_FLOOR)

    return calibrate(sim, wheel_base_m=params.wheel_base_m,
                     plan=plan or CalibrationPlan(seed=seed), floor=floor_name(floor),
                     progress=progress, before_stage=to_open_floor, after_stage=after_stage,
                     recorded=recorded)


def wall_run_simulator(robot: str | RobotParams = "create2", *, seed: int = 0,
                       floor: str | FloorMap | None = None) -> Simulator:
    """A simulated robot set up for the wall run (:mod:`lti_motion.calibration.wall_run_drive`) as a
    user sets up a real one: healthy (its own faults left out), 0.5 m in front of a straight
    white wall 10 m long (:meth:`~drivers.sim.Room.single_wall`), facing it within
    +-3 degrees (drawn from ``seed``, as in ``benchmarks/bench_wall_run.py``).

    Parameters
    ----------
    robot : str or RobotParams
        Preset name, robot file or parameters.
    seed : int
        Simulator seed; also draws the start heading.
    floor : str or FloorMap, optional
        Floor to simulate (default the robot's).
    """
    params = load_robot(robot) if isinstance(robot, str) else robot
    heading = -np.pi / 2 + np.random.default_rng([seed, 0x3A11]).uniform(-1, 1) * np.deg2rad(3)
    return Simulator(params.replace(faults=()), seed=seed,
                     floor=params.floor if floor is None else floor, room=Room.single_wall(),
                     initial_pose=(0.0, 0.5, heading))


def summarize(cal: Calibration) -> list[str]:
    """Lines a person reads: encoder scale, ARX order, delay, fit and DC gain, FIR length.

    The fit is the held-out free-run fit stored in the model
    (``diagnostics["validation_fit_v"]``, ``["validation_fit_w"]``: the model
    as saved, its DC gain restricted to the wheel servos' when the plan says
    so), not the selection grid's unrestricted candidate.
    """
    d = cal.arx.diagnostics
    gain = f", DC gain scale {d['dc_gain_scale']:.3f}" if "dc_gain_scale" in d else ""
    return [
        f"encoder scale   {cal.m_per_tick * 1e3:.5f} mm/tick (rotation period "
        f"{cal.rotation.period_ticks:.1f} ticks, confidence {cal.rotation.confidence:.3f})",
        f"ARX             order {cal.arx.orders['na']}, input delay {cal.arx.orders['delay']} "
        f"samples; held-out free-run fit v {d['validation_fit_v']:.1f}%, "
        f"w {d['validation_fit_w']:.1f}%{gain}",
        f"FIR             {cal.fir.orders['n_taps']} taps",
    ]
