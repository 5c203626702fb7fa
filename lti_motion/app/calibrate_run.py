"""``lti-motion calibrate``: drive the manoeuvres, keep each log as it ends, save a healthy model.

What the command promises (docs/guide_calibrate_real_robot.md):

* the output folder is checked for writing before anything is driven;
* each manoeuvre's log is written to ``OUT/log_<stage>.npz`` as soon as the
  manoeuvre ends, so a link that dies or a Ctrl-C loses only the manoeuvre
  under way; ``--resume`` uses the logs found there instead of driving again;
* Ctrl-C stops the wheels (leaving the driver's ``with`` block does) and ends
  with one line saying what was kept, exit code 130;
* a drive whose analysis fails (the rotation shows no period, the robot did not
  apply the step command) is a failed drive, not a finished one: its log is kept
  as ``OUT/log_<stage>.failed.npz`` for inspection, and ``--resume`` drives it
  again instead of failing on it the same way;
* a model whose held-out fit is below the documented healthy range is not
  saved under its name unless ``--accept-unhealthy``: the drives and plots are
  kept, the reason is printed, exit code 2.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from lti_motion.calibration import Calibration, CalibrationPlan
from lti_motion.recordings import FrameLog

if TYPE_CHECKING:
    from drivers.sim import RobotParams

__all__ = [
    "HEALTHY_FIT_PERCENT",
    "STAGES",
    "check_writable_folder",
    "failed_log_path",
    "health_problems",
    "nominal_wheel_base_m",
    "run_calibrate",
    "stage_log_path",
]

#: The manoeuvres, in the order they are driven.
STAGES = ("rotation", "steps", "excitation")

#: Lowest held-out free-run fit of ``v`` and ``w`` [%] of a healthy model: the lower end
#: of "above 85-90% for v and w on a healthy robot on hard floor"
#: (docs/guide_calibrate_real_robot.md, section 4).
HEALTHY_FIT_PERCENT = 85.0

#: The wheel base [m] of a Create 2: the nominal one without --wheel-base or --robot.
CREATE2_WHEEL_BASE_M = 0.235

#: Exit code after Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130


def nominal_wheel_base_m(args: argparse.Namespace, described: RobotParams | None) -> float:
    """``--wheel-base`` [m], else the ``--robot`` description's, else a Create 2's."""
    if args.wheel_base is not None:
        return args.wheel_base
    return described.wheel_base_m if described is not None else CREATE2_WHEEL_BASE_M


def stage_log_path(out: Path, stage: str) -> Path:
    """Where a manoeuvre's log is kept: ``OUT/log_<stage>.npz``."""
    return Path(out) / f"log_{stage}.npz"


def failed_log_path(out: Path, stage: str) -> Path:
    """Where a manoeuvre's log is kept when its analysis failed: ``OUT/log_<stage>.failed.npz``
    (``--resume`` does not read it: the manoeuvre is driven again)."""
    return Path(out) / f"log_{stage}.failed.npz"


class _Analysed(Mapping):
    """The recorded logs, watched: which manoeuvre's log the calibration is analysing.

    :func:`~lti_motion.calibration.calibrate` analyses each manoeuvre's log (the
    rotation's period, the steps' timing) right after it has it (driven, then
    ``after_stage``; or read from here on ``--resume``) and before it looks here for
    the next manoeuvre (``stage in recorded``); the last log it had is analysed until
    then, and the excitation's until the fits are done.
    """

    def __init__(self, logs: Mapping[str, FrameLog]) -> None:
        self._logs = dict(logs)
        self.analysing: str | None = None

    def __getitem__(self, stage: str) -> FrameLog:
        log = self._logs[stage]
        self.analysing = stage
        return log

    def __bool__(self) -> bool:
        return True                   # watched even when empty (``recorded or {}`` keeps it)

    def __contains__(self, stage: object) -> bool:
        self.analysing = None                 # on to the next manoeuvre: the last one passed
        return stage in self._logs

    def __iter__(self) -> Iterator[str]:
        return iter(self._logs)

    def __len__(self) -> int:
        return len(self._logs)


def check_writable_folder(folder: Path, *, option: str = "--out") -> None:
    """Create ``folder`` if needed and write a scratch file in it, before any driving.

    Raises
    ------
    OSError
        One line naming the folder, the reason and the option to change.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OSError(f"cannot write to {folder}: {reason}; give {option} a folder you can "
                      "write to (checked before driving)") from exc


def health_problems(cal: Calibration, *,
                    healthy_fit_percent: float = HEALTHY_FIT_PERCENT) -> list[str]:
    """Why the calibrated ARX model is unhealthy; empty when it is healthy.

    The measure is the held-out free-run fit stored in the model
    (``diagnostics["validation_fit_v"]`` and ``["validation_fit_w"]``), the
    one :func:`drivers.sim.summarize` prints.
    """
    problems = []
    for name in ("v", "w"):
        fit = cal.arx.diagnostics[f"validation_fit_{name}"]
        if not fit >= healthy_fit_percent:
            problems.append(f"held-out fit of {name} {fit:.1f}% is below the healthy "
                            f"{healthy_fit_percent:g}%")
    return problems


def _recorded(out: Path, *, resume: bool) -> dict[str, FrameLog]:
    """The logs of manoeuvres driven before (``--resume``); refuse to mix runs otherwise."""
    from lti_motion.recordings import load_log

    found = [s for s in STAGES if stage_log_path(out, s).is_file()]
    if not resume:
        if found:
            raise OSError(f"{out} holds the drives of an earlier calibration "
                          f"({', '.join(stage_log_path(out, s).name for s in found)}): give "
                          "--resume to go on from them, or another --out")
        return {}
    return {s: load_log(stage_log_path(out, s)) for s in found}


def _drive(args: argparse.Namespace, plan: CalibrationPlan, recorded: _Analysed,
           after_stage: Callable[[str, FrameLog], None]) -> Calibration:
    """The manoeuvres not yet recorded, on the simulator or the robot, and the fits."""
    from drivers.sim import calibrate_simulator, floor_name, load_robot, print_progress
    from lti_motion.calibration import calibrate

    described = load_robot(args.sim) if args.sim else None
    if described is not None and not args.port:
        print(f"calibrating the simulated {described.name} robot on "
              f"{args.floor or floor_name(described.floor)} floor (seed {args.seed})")
        return calibrate_simulator(described, seed=args.seed, floor=args.floor, plan=plan,
                                   progress=print_progress, after_stage=after_stage,
                                   recorded=recorded)
    from drivers.roomba import Roomba, RoombaOptions
    from lti_motion.app.prompts import wait_until_placed

    driving: list[Roomba] = []

    def before_stage(stage: str) -> None:
        where = {"rotation": "beside a wall or furniture (within 30 cm), room to turn",
                 "steps": "on open floor, 2 m clear all round",
                 "excitation": "on open floor, 2 m clear all round"}[stage]
        print(f"next: {stage}. Put the robot {where}.")
        if not args.yes:
            wait_until_placed()
        for robot in driving:       # the frames that waited meanwhile are from before it
            robot.catch_up()

    options = {"wheel_base_m": nominal_wheel_base_m(args, described),
               "plan": plan, "floor": args.floor or "hard", "progress": print_progress,
               "before_stage": before_stage, "after_stage": after_stage, "recorded": recorded}
    if all(s in recorded for s in STAGES):            # nothing to drive: no robot needed
        return calibrate(_NoRobot(recorded["rotation"].dt_s), **options)
    print(f"calibrating the robot on {args.port} at {args.baud} baud")
    link = RoombaOptions(baud_bps=args.baud, clock_rate=args.clock_rate)
    with Roomba(args.port, options=link) as robot:
        driving.append(robot)
        return calibrate(robot, **options)


class _NoRobot:
    """The robot of a calibration whose every manoeuvre is recorded: never driven."""

    def __init__(self, dt_s: float) -> None:
        self.dt_s = dt_s

    def step(self, cmd_m_s: object) -> None:
        raise RuntimeError("every manoeuvre is recorded; nothing is driven")


def _kept_text(out: Path) -> str:
    kept = [stage_log_path(out, s).name for s in STAGES if stage_log_path(out, s).is_file()]
    if not kept:
        return "no manoeuvre was complete, nothing kept"
    return (f"kept {', '.join(kept)} in {out}: run again with --resume to go on without "
            "driving them again")


def run_calibrate(args: argparse.Namespace) -> int:
    """The ``calibrate`` sub-command (see the module docstring); the exit code."""
    import sys

    from drivers.exceptions import PassiveModeError
    from lti_motion.recordings import save_log

    out = Path(args.out)
    created = not out.exists()
    check_writable_folder(out)
    recorded = _Analysed(_recorded(out, resume=args.resume))
    if len(recorded):
        print(f"resuming: {', '.join(recorded)} recorded in {out}, not driven again")

    def after_stage(stage: str, log: FrameLog) -> None:
        print(f"  kept the {stage} drive in {save_log(stage_log_path(out, stage), log)}")
        recorded.analysing = stage

    plan = CalibrationPlan(seed=args.seed, excitation_s=args.excitation_s)
    try:
        cal = _drive(args, plan, recorded, after_stage)
        recorded.analysing = None
        return _save(_with_robot(cal, args), out, accept_unhealthy=args.accept_unhealthy)
    except KeyboardInterrupt:
        print(f"\nlti-motion calibrate: stopped by Ctrl-C; the wheels were commanded to "
              f"stop; {_kept_text(out)}", file=sys.stderr)
        _remove_if_empty(out, created=created)
        return EXIT_INTERRUPTED
    except (OSError, ValueError, PassiveModeError) as exc:
        failed = _set_aside(out, recorded.analysing)
        _remove_if_empty(out, created=created)
        raise OSError(f"{exc}; {failed}{_kept_text(out)}") from exc


def _set_aside(out: Path, stage: str | None) -> str:
    """A manoeuvre whose analysis failed: its log renamed out of ``--resume``'s way."""
    if stage is None or not stage_log_path(out, stage).is_file():
        return ""
    failed = failed_log_path(out, stage)
    stage_log_path(out, stage).replace(failed)
    return (f"the {stage} drive failed its analysis and was set aside as {failed.name} "
            "(--resume drives it again); ")


def _with_robot(cal: Calibration, args: argparse.Namespace) -> Calibration:
    """Both models with the robot they were driven on: raw 16-bit counts counted in the
    commanded direction (the Open Interface's, the simulator's), the measured encoder scale,
    the wheel base and the period (:class:`~lti_motion.robot_description.RobotDescription`)."""
    from dataclasses import replace

    from drivers.sim import load_robot
    from lti_motion.robot_description import RobotDescription

    described = load_robot(args.sim) if args.sim else None
    log = next(iter(cal.logs.values()), None)
    bits = int(log.counter_bits) if log is not None else 16
    name = described.name if described is not None else f"the robot on {args.port}"
    where = f"--robot {args.sim}" if args.sim else f"--port {args.port}"
    radius = described.wheel_diameter_m / 2 if described is not None else None
    robot = RobotDescription(
        wheel_data="counts", wheel_base_m=cal.arx.wheel_base_m, dt_s=cal.arx.dt_s,
        encoders="commanded", m_per_tick=cal.m_per_tick, wheel_radius_m=radius,
        ticks_per_rad=None if described is None else described.ticks_per_rev / (2 * math.pi),
        counter_bits=None if bits >= 63 else bits, robot=name,
        sources={"m_per_tick": "measured by the rotation in place (paper eq. 13)",
                 "wheel_base_m": ("--wheel-base" if getattr(args, "wheel_base", None)
                                  else f"the robot description ({where})"),
                 "dt_s": "the robot's sensor period"})
    return replace(cal, arx=cal.arx.updated(robot=robot), fir=cal.fir.updated(robot=robot))


def _remove_if_empty(out: Path, *, created: bool) -> None:
    """A run that failed before keeping anything leaves no empty ``--out`` it created."""
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def _save(cal: Calibration, out: Path, *, accept_unhealthy: bool) -> int:
    """Plots always; the models only when healthy or accepted. The exit code."""
    import sys

    from drivers.sim import summarize
    from lti_motion.app.plots import plot_calibration

    plots = plot_calibration(cal, out)
    for line in summarize(cal):
        print(line)
    problems = health_problems(cal)
    if problems and not accept_unhealthy:
        print(f"lti-motion calibrate: error: the model is unhealthy and was not saved: "
              f"{'; '.join(problems)} (docs/guide_calibrate_real_robot.md, section 4). The "
              f"drives and plots are in {out}: check the plots, put the robot on open floor "
              "for the steps and the excitation and calibrate again, or save this model "
              "anyway with --resume --accept-unhealthy", file=sys.stderr)
        return 2
    if problems:
        print(f"saving an unhealthy model as --accept-unhealthy asks: {'; '.join(problems)}")
    cal.arx.save(out / "model_arx.json")
    cal.fir.save(out / "model_fir.json")
    print(f"wrote {out / 'model_arx.json'}, {out / 'model_fir.json'}, "
          f"{', '.join(p.name for p in plots)} and the drives "
          f"{', '.join(stage_log_path(out, s).name for s in STAGES)}")
    return 0
