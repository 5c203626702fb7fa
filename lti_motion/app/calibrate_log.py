"""``lti-motion calibrate --log FILE``: the ARX model from any recorded drive.

Reads a log of either version (Roomba / simulator frames, or a recording of
any differential drive, ``docs/log_format.md``), prints the excitation report
(:func:`lti_motion.calibration.excitation_report`), refuses data that cannot
identify a model with the reason, and writes ``model_arx.json`` and
``excitation.txt``. The encoder scale is not measured (that needs the rotation
in place of ``calibrate --sim/--port``): it comes from the robot description
given on the command line, and the output says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from lti_motion.app.recorded_health import HeldOut
from lti_motion.calibration import OfflineCalibration, calibrate_recording, rotation_scale
from lti_motion.persistence import atomic_write
from lti_motion.recordings import Recording, load_recording, median_period_s
from lti_motion.robot_description import ANGLE_COUNTS_PER_RAD, RobotDescription

__all__ = ["LogRobot", "run_calibrate_log", "run_calibrate_recording"]


@dataclass(frozen=True)
class LogRobot:
    """What the command line says about the robot [m, m/tick] (kept in the model as its
    :class:`~lti_motion.robot_description.RobotDescription`).

    Attributes
    ----------
    wheel_base_m : float
        ``--wheel-base``.
    m_per_tick : float or None
        ``--m-per-tick``, else the ``--robot`` description's nominal scale.
    wheel_radius_m : float or None
        ``--wheel-radius``, else the ``--robot`` description's nominal radius.
    source : str
        Where the scale came from, for the output.
    name : str or None
        The robot's name (``--robot``'s).
    """

    wheel_base_m: float
    m_per_tick: float | None
    wheel_radius_m: float | None
    source: str
    name: str | None = None

    def __post_init__(self) -> None:
        for flag, value in (("--wheel-base", self.wheel_base_m),
                            ("--m-per-tick", self.m_per_tick),
                            ("--wheel-radius", self.wheel_radius_m)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{flag} must be a positive number of metres"
                                 f"{' per tick' if flag == '--m-per-tick' else ''}, "
                                 f"got {value}")


def _scale_for(rec: Recording, robot: LogRobot) -> dict:
    """The scale keyword the recording's wheel kind needs, or a command-line error."""
    if rec.wheel_kind == "counts":
        if robot.m_per_tick is None:
            found = rotation_scale(rec, wheel_base_m=robot.wheel_base_m)
            if isinstance(found, str):
                raise ValueError(f"this log holds encoder counts and {found}: give "
                                 "--m-per-tick (metres per tick, from the robot description) "
                                 "or --robot NAME_OR_FILE")
        return {"m_per_tick": robot.m_per_tick}
    if rec.wheel_kind in ("wheel_angles_rad", "wheel_speeds_rad_s"):
        if robot.wheel_radius_m is None:
            raise ValueError(f"this log holds {rec.wheel_kind.replace('_', ' ')}: give "
                             "--wheel-radius (metres, from the robot description) or "
                             "--robot NAME_OR_FILE")
        if rec.wheel_kind == "wheel_angles_rad":   # counted as calibrate --bag counts them
            return {"wheel_radius_m": robot.wheel_radius_m,
                    "m_per_tick": robot.wheel_radius_m / ANGLE_COUNTS_PER_RAD}
        return {"wheel_radius_m": robot.wheel_radius_m}
    return {}


def run_calibrate_log(path: str, robot: LogRobot, *, out: Path,
                      floor: str | None = None, held_out: HeldOut | None = None,
                      accept_unhealthy: bool = False, max_wheel_speed_m_s: float | None = None,
                      dt_s: float | None = None) -> tuple[OfflineCalibration, list[str]]:
    """Calibrate from a log file; write the model and report only when all went well.

    The model is measured on a held-out time span (``held_out``, default the last 20%
    of the drive; :mod:`lti_motion.app.recorded_health`) and written only when healthy
    or ``accept_unhealthy``; the report is written either way.

    Returns
    -------
    OfflineCalibration
        The model, report and fit.
    list of str
        The lines to print.

    Raises
    ------
    FileNotFoundError, ValueError
        One line each, at the command-line user's level (the CLI exits 2);
        nothing is written.
    """
    return run_calibrate_recording(load_recording(path), robot, out=out, floor=floor,
                                   held_out=held_out, accept_unhealthy=accept_unhealthy,
                                   max_wheel_speed_m_s=max_wheel_speed_m_s, dt_s=dt_s)


def run_calibrate_recording(rec: Recording, robot: LogRobot, *, out: Path,
                            floor: str | None = None, held_out: HeldOut | None = None,
                            accept_unhealthy: bool = False,
                            max_wheel_speed_m_s: float | None = None,
                            dt_s: float | None = None
                            ) -> tuple[OfflineCalibration, list[str]]:
    """:func:`run_calibrate_log` on a recording already read (a log file's, or a bag's
    odometry twist, :func:`drivers.bags.read_bag`); ``max_wheel_speed_m_s``
    (``--max-wheel-speed``) bounds the wheels' speed [m/s] (default: the core's); ``dt_s``
    (``--dt``) is the model's period [s], refused more than 10 % from the recording's own
    (:func:`lti_motion.app.recorded_health.check_period`).

    Raises
    ------
    ValueError
        Also an unhealthy model (held-out fit below the healthy one, an order or delay at
        its range's edge) without ``accept_unhealthy``: the report is written, the model
        not.
    """
    from lti_motion.app.recorded_health import (
        check_period,
        held_out_line,
        held_out_span,
        recorded_problems,
        refuse_unhealthy,
    )

    scale = _scale_for(rec, robot)
    frames_v1 = rec.wheel_kind == "counts" and rec.counter_bits == 16 and rec.cmd_per_frame
    t = rec.wheel.t_s
    check_period(dt_s, median_period_s(t), "the median interval of its wheel stamps")
    span = held_out_span(held_out or HeldOut(), float(t[-1] - t[0]))
    encoders = "commanded" if frames_v1 else "quadrature"
    cal = calibrate_recording(rec, wheel_base_m=robot.wheel_base_m, scale_from=robot.source,
                              encoders=encoders, floor=floor, held_out_s=span, dt_s=dt_s,
                              **scale,
                              **({} if max_wheel_speed_m_s is None
                                 else {"max_wheel_speed_m_s": max_wheel_speed_m_s}))
    described = RobotDescription(
        wheel_data=rec.wheel_kind, wheel_base_m=robot.wheel_base_m, dt_s=cal.model.dt_s,
        encoders=encoders, m_per_tick=scale.get("m_per_tick", cal.m_per_tick),
        ticks_per_rad=ANGLE_COUNTS_PER_RAD if rec.wheel_kind == "wheel_angles_rad" else None,
        wheel_radius_m=scale.get("wheel_radius_m"), counter_bits=rec.counter_bits,
        robot=robot.name or (Path(rec.source.path).name if rec.source is not None else None),
        sources={"m_per_tick" if rec.wheel_kind == "counts" else "wheel_radius_m":
                 cal.scale_from, "wheel_base_m": robot.source})
    cal = replace(cal, model=cal.model.updated(robot=described))
    lines = cal.report.lines()
    if cal.scale_measured:
        lines.append(f"encoder scale: m_per_tick = {cal.m_per_tick:.6g}, measured by "
                     f"{cal.scale_from}")
    else:
        what = (", ".join(f"{k} = {v:.6g}" for k, v in scale.items() if v is not None)
                or "none needed (body speeds)")
        lines.append(f"encoder scale: {what}, from {cal.scale_from}; NOT measured (no "
                     "rotation in place beside a wall in this recording: run 'lti-motion "
                     "calibrate --robot/--port' to measure it)")
    m = cal.model
    if cal.widened:
        lines.append(f"search widened: {cal.widened}")
    lines.append(f"ARX model: period {m.dt_s * 1e3:.4f} ms; {held_out_line(cal)}")
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "excitation.txt", text=True) as fh:
        fh.write("\n".join(lines) + "\n")
    problems = recorded_problems(cal)
    if problems and not accept_unhealthy:
        for line in lines:
            print(line)
        lines.clear()
    refuse_unhealthy(problems, accept_unhealthy=accept_unhealthy, print_fn=lines.append)
    model_path = m.save(out / "model_arx.json")
    lines.append(f"wrote {model_path} and {out / 'excitation.txt'}")
    return cal, lines
