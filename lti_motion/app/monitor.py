"""``lti-motion monitor``: drive (or listen), run the EKF and the residual monitor, print alarms.

Each frame goes through :class:`~fusion.monitoring.MonitoredFilter`, which owns
the order of the steps (predict, the stuck-encoder check, the encoder update and
its gate, the dynamics tests with a Phase-I fit, the scale test with landmarks).
Alarms are printed as they are raised; a summary follows at the end.

Phase I (:func:`~fusion.monitoring.fit_nominal`): the
dynamics null and the encoder gate come from nominal drives of the same
route. ``--sim`` drives them first (``nominal_drives`` simulated drives of the
same length, other seeds, no fault); ``--port`` reads them from logs the
command recorded on nominal drives (``--record``). Without them the dynamics
tests are off and the windowed NIS and CUSUM on the encoder innovations run
instead (they cry wolf, ``docs/guide_alarms.md``). The scale test runs on
``--sim`` only, with a simulated landmark sensor
(:data:`~lti_motion.app.monitor_setup.MONITOR_LANDMARKS`, 2 Hz).

The drive (:func:`monitor_route`) is open loop: 1 s at rest, then a rounded
rectangle (straights at changing speeds, 90 degree arcs of 0.4 m radius) with
both wheel commands positive, so the encoders never count a reversal.
On the simulator, scheduled faults (:data:`FAULTS`) can be injected. The
filter and the monitor read only what a robot reports. A robot with a yaw-rate
gyro (a robot file's ``[gyro]``; a bag's ``sensor_msgs/Imu``) has its readings
fused by the EKF (:class:`~fusion.noise.GyroNoise` defaults, the bias estimated).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from fusion.ekf import EKFOptions
from fusion.landmark_map import LandmarkMap
from fusion.monitoring import (
    AlarmEvent,
    DynamicsAlarm,
    FrameResult,
    MonitoredFilter,
    MonitorOptions,
    NominalFit,
    ResidualMonitor,
    WheelVerdict,
)
from fusion.noise import GyroNoise, gate_threshold
from fusion.range_bearing import RangeBearing
from lti_motion.app.monitor_setup import (
    MONITOR_LANDMARKS,
    monitor_route,
    nominal_from_logs,
    nominal_on_simulator,
    sightings,
)
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.kinematics import wrap_angle
from lti_motion.model import MotionModel
from lti_motion.recordings import SensorFrame

if TYPE_CHECKING:
    from drivers.sim import FloorMap, RobotParams

__all__ = [
    "FAULTS",
    "MEANINGFUL_LAG_STD_PERIODS",
    "MonitorRun",
    "dynamics_detail",
    "fault_for",
    "format_alarm",
    "heading_deg",
    "monitor_frames",
    "monitor_route",
    "nominal_from_logs",
    "nominal_on_simulator",
    "run_on_port",
    "run_on_simulator",
    "wheel_detail",
]

#: ``--fault`` choices -> (simulator fault kind, its parameters, the alarm expected).
FAULTS: Mapping[str, tuple[str, Mapping[str, object], str | None]] = MappingProxyType({
    "stuck-encoder": ("stuck_encoder", MappingProxyType({"wheel": "left"}), "stuck_encoder"),
    "stall": ("stall", MappingProxyType({"wheel": "left", "duration_s": 2.0}), "stalled_wheel"),
    "spikes": ("encoder_spikes", MappingProxyType({"rate_hz": 20.0, "duration_s": 1.0}),
               "glitch_burst"),
    "payload": ("payload", MappingProxyType({"payload_kg": 1.8}), "dynamics_changed"),
    "motor": ("motor", MappingProxyType({"weakening": 0.2}), "dynamics_changed"),
    "delay": ("delay", MappingProxyType({"extra_periods": 3.0}), "dynamics_changed"),
    "carpet": ("floor", MappingProxyType({"floor": "carpet"}), "scale_changed"),
    "wheel-drift": ("wheel_diameter", MappingProxyType({"wheel": "left",
                                                       "diameter_change": 0.005}),
                    "wheel_drift"),
})

_WHEEL = MappingProxyType({0: "left wheel", 1: "right wheel"})

#: A dynamics alarm's lag is printed when its standard deviation is at most this [periods]:
#: ``a ~ N(theta b, b)`` per window (:mod:`fusion.monitoring.dynamics`), so a lag summed
#: over windows without transients (``b ~ 0``) is noise, however large.
MEANINGFUL_LAG_STD_PERIODS = 1.0


def dynamics_detail(alarm: DynamicsAlarm) -> str:
    """The sub-test of a dynamics alarm and, from the lag test, its lag when meaningful.

    ``"(lag test, lag 2.4 +- 0.3 periods)"``, ``"(covariance test)"``; the lag only
    for the lag test and when its standard deviation is at most
    :data:`MEANINGFUL_LAG_STD_PERIODS` [periods].
    """
    lag, std = alarm.lag_periods, alarm.lag_std_periods
    if (alarm.test == "lag" and math.isfinite(lag) and math.isfinite(std)
            and std <= MEANINGFUL_LAG_STD_PERIODS):
        return f"({alarm.test} test, lag {lag:.1f} +- {std:.1f} periods)"
    return f"({alarm.test} test)"


def wheel_detail(verdict: WheelVerdict) -> str:
    """Why a flat count is a stalled wheel or a stuck encoder, in a person's words."""
    if verdict.evidence == "no currents":
        return "(no motor currents reported: a blocked wheel would look the same)"
    if verdict.evidence == "overcurrent":
        return "(the robot reports a wheel overcurrent: the wheel is blocked)"
    low, ref = verdict.min_current_a * 1000.0, verdict.reference_current_a * 1000.0
    running = f" against {ref:.0f} mA while driving" if math.isfinite(ref) else ""
    if verdict.kind == "stalled_wheel":
        return f"(motor current {low:.0f} mA{running}: the wheel is blocked)"
    return f"(motor current {low:.0f} mA{running}: the wheel turns, its encoder does not count)"


def _nis(value: float) -> str:
    """A NIS gate as printed: one decimal below 1000 (55.3), none above (2667)."""
    return f"{value:.1f}" if value < 1000 else f"{value:.0f}"


def heading_deg(theta_rad: float) -> float:
    """A heading [rad], unwrapped or not, in degrees in ``(-180, 180]``."""
    return math.degrees(float(wrap_angle(theta_rad)))


def fault_for(choice: str, t_s: float) -> tuple[object, str | None]:
    """The simulator :class:`~drivers.sim.Fault` of a ``--fault`` choice at ``t_s`` [s],
    and the alarm kind it should raise."""
    from drivers.sim import Fault

    kind, params, expected = FAULTS[choice]
    return Fault(kind, t_s=t_s, **params), expected


def format_alarm(event: AlarmEvent, *, detail: str = "") -> str:
    """One line a person reads: time, kind, test, statistic / threshold, onset, channel.

    A dynamics alarm's onset is its posterior change time with the interval it
    states (:mod:`fusion.monitoring.change_time`).

    A scale alarm adds its new scale (ground travel and turn per encoder travel
    and turn, with standard deviations), a wheel-drift alarm its curvature and the
    new left-over-right wheel scale ratio; ``detail`` is appended (the dynamics
    sub-test and lag).
    """
    where = ""
    if event.channel is not None:
        where = (_WHEEL.get(event.channel, f"channel {event.channel}")
                 if event.test == "stuck" else f"channel {event.channel}")
    if event.wheel is not None:
        where = " ".join(part for part in (where, wheel_detail(event.wheel)) if part)
    if event.scale is not None:
        a = event.scale
        where = (f"travel x{a.scale_ratio:.4f} +- {a.scale_ratio_std:.4f}, turn "
                 f"x{a.yaw_ratio:.4f} +- {a.yaw_ratio_std:.4f}")
        if a.change == "curvature" and a.intrinsics is not None:
            where = (f"curvature {a.curvature_rad_per_m:+.4f} +- "
                     f"{a.curvature_std_rad_per_m:.4f} rad/m, wheels left/right "
                     f"x{a.intrinsics.diameter_ratio:.4f}")
    tail = " ".join(part for part in (where, detail) if part)
    onset = f"onset {event.onset_s:.3f} s"
    d = event.dynamics
    if d is not None and math.isfinite(d.onset_lo_s) and math.isfinite(d.onset_hi_s):
        onset += f" (between {d.onset_lo_s:.2f} and {d.onset_hi_s:.2f} s)"
    return (f"ALARM t={event.t_s:8.3f} s  {event.kind:16s} test {event.test:10s} "
            f"statistic {event.statistic:9.3g} (threshold {event.threshold:.3g})  "
            f"{onset}  {tail}").rstrip()


@dataclass
class MonitorRun:
    """What a monitored drive gave.

    Attributes
    ----------
    frames : int
        Frames processed.
    duration_s : float
        Filter time covered [s].
    events : list of AlarmEvent
        The alarms, in time order.
    counts : dict
        The monitor's counts (samples, glitches, missing, skipped, startup).
    glitch_gate_nis : float
        The monitor's per-sample glitch gate on the encoder innovations (NIS):
        a reading above it is a glitch, counted towards a burst.
    encoders_gated : int
        Encoder readings the EKF's own fusion gate kept out of the estimate.
    fusion_gate_nis : float
        That gate (NIS; chi-square, ``gate_probability`` of the EKF): a reading
        above it is not fused, and is no alarm on its own.
    final_pose : ndarray, shape (3,)
        The EKF's last pose (x [m], y [m], theta [rad]) from the origin.
    tests : list of str
        What ran, one line each (gate, dynamics, scale).
    gyro_windows : tuple of 2 int or None
        With a gyro: its windows fused and gated by the EKF; ``None`` without.
    interrupted : bool
        The drive was ended by Ctrl-C (``KeyboardInterrupt``) before its last
        frame; what came before it is summarised (and recorded) as usual.
    """

    frames: int = 0
    duration_s: float = 0.0
    events: list[AlarmEvent] = field(default_factory=list)
    counts: dict = field(default_factory=dict)
    glitch_gate_nis: float = math.nan
    encoders_gated: int = 0
    fusion_gate_nis: float = math.nan
    final_pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tests: list[str] = field(default_factory=list)
    gyro_windows: tuple[int, int] | None = None
    interrupted: bool = False

    def summary(self) -> list[str]:
        """Lines for the end of the command's output."""
        by_kind = Counter(e.kind for e in self.events)
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(by_kind.items())) or "none"
        x, y, th = self.final_pose
        startup = self.counts.get("startup", 0)
        return [
            *self.tests,
            f"monitored {self.frames} frames ({self.duration_s:.1f} s): "
            f"{self.counts.get('samples', 0)} encoder innovations tested, "
            f"{self.counts.get('missing', 0)} missing"
            + (f", {startup} left untested after starts from rest" if startup else ""),
            f"two gates: {self.counts.get('glitches', 0)} glitches above the monitor's glitch "
            f"gate (NIS {_nis(self.glitch_gate_nis)}; 3 within 20 readings make a burst); "
            f"{self.encoders_gated} readings not fused by the EKF (its own fusion gate, "
            f"NIS {self.fusion_gate_nis:.3g}; no alarm)",
            *([] if self.gyro_windows is None else [
                f"gyro: {self.gyro_windows[0]} windows fused, {self.gyro_windows[1]} gated by "
                "the EKF"]),
            f"alarms: {len(self.events)} ({kinds})",
            f"EKF pose at the end: x {x:.3f} m, y {y:.3f} m, heading {heading_deg(th):.1f} deg "
            "(from the start, in (-180, 180])",
        ]


def monitor_frames(model: MotionModel,
                   frames: Iterator[SensorFrame | tuple[SensorFrame, RangeBearing]], *,
                   options: MonitorOptions | None = None, nominal: NominalFit | None = None,
                   landmarks: LandmarkMap | None = None,
                   on_alarm: Callable[[AlarmEvent], None] | None = None,
                   on_alarm_line: Callable[[str], object] | None = None,
                   on_frame: Callable[[SensorFrame], None] | None = None,
                   on_step: Callable[[FrameResult, np.ndarray], None] | None = None,
                   counter_bits: int = 16, gyro: GyroNoise | None = None) -> MonitorRun:
    """Run a :class:`~fusion.monitoring.MonitoredFilter` over frames.

    Parameters
    ----------
    model : MotionModel
        The calibrated model; needs ``m_per_tick``.
    frames : iterator of SensorFrame or (SensorFrame, sightings)
        One robot's frames in order (a driver's, a simulator's); each frame's
        ``cmd_m_s`` is the command of the period it closes. Frames whose
        ``valid`` is false only advance the filter. With ``landmarks``, each
        item is a pair: the frame and its sightings (a
        :class:`~fusion.range_bearing.RangeBearing`).
    options : MonitorOptions, optional
        Monitor settings (default: the model's period and, with ``nominal``,
        its encoder gate; everything else default).
    nominal : NominalFit, optional
        Phase I (:func:`~fusion.monitoring.fit_nominal`): runs the
        dynamics tests with its null and the gate it set. Without it the
        encoder innovations' windowed NIS and CUSUM run instead.
    landmarks : LandmarkMap, optional
        Runs the scale test (the robot starts at the origin, heading 0). The
        sightings are not fused: the pose printed at the end is the model's
        and the encoders' alone.
    on_alarm : callable, optional
        Called with each alarm as it is raised.
    on_alarm_line : callable, optional
        Called with each alarm's line (:func:`format_alarm`, with the
        dynamics sub-test and lag).
    on_frame : callable, optional
        Called with each frame (to record it, to show progress).
    on_step : callable, optional
        Called after each frame with what it gave (a
        :class:`~fusion.monitoring.FrameResult`) and the EKF's
        pose covariance, shape (3, 3) [m^2, m rad, rad^2] (to write the estimates).
    counter_bits : int
        Width of the frames' encoder counters [bits] (16: the Open Interface's).
    gyro : GyroNoise, optional
        The EKF fuses each frame's ``yaw_rate_rad_s`` (a frame without one: no
        reading); without it the frames' readings are not used.

    Returns
    -------
    MonitorRun
        ``interrupted`` set if Ctrl-C (``KeyboardInterrupt``) ended the frames early:
        the frames before it are summarised, nothing is raised.

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale.
    """

    def relay(event: AlarmEvent) -> None:
        if on_alarm_line is not None:
            detail = "" if event.dynamics is None else dynamics_detail(event.dynamics)
            on_alarm_line(format_alarm(event, detail=detail))
        if on_alarm is not None:
            on_alarm(event)

    mf = MonitoredFilter(model, nominal=nominal, options=options,
                         ekf_options=EKFOptions(history=0, counter_bits=counter_bits, gyro=gyro),
                         landmarks=landmarks, fuse_landmarks=False,
                         pose_std=(0.005, 0.005, 0.005), on_alarm=relay)
    run = MonitorRun(tests=_test_lines(mf.monitor, nominal, landmarks),
                     glitch_gate_nis=mf.monitor.thresholds().gate)
    try:
        for item in frames:
            frame, seen = item if isinstance(item, tuple) else (item, None)
            if on_frame is not None:
                on_frame(frame)
            run.frames += 1
            if gyro is None and frame.yaw_rate_rad_s is not None:
                frame = replace(frame, yaw_rate_rad_s=None)     # the filter has no gyro
            result = mf.step(frame, sightings=seen)
            if on_step is not None and mf.ekf is not None:
                on_step(result, mf.ekf.P[:3, :3].copy())
    except KeyboardInterrupt:           # Ctrl-C ends the drive; what came before is kept
        run.interrupted = True
    if mf.ekf is not None:
        run.duration_s = mf.ekf.t_s
        run.encoders_gated = mf.ekf.stats.count("encoders", "gated")
        if mf.ekf.gate_probability is not None:
            run.fusion_gate_nis = gate_threshold(mf.ekf.gate_probability, 2)
        run.final_pose = mf.ekf.pose
        if gyro is not None:
            run.gyro_windows = (mf.ekf.stats.count("gyro", "fused"),
                                mf.ekf.stats.count("gyro", "gated"))
    run.events = list(mf.events)
    run.counts = dict(mf.monitor.counts)
    return run


def _test_lines(mon: ResidualMonitor, nominal: NominalFit | None,
                landmarks: LandmarkMap | None) -> list[str]:
    """What runs, for the summary."""
    gate = mon.thresholds().gate
    lines = []
    if nominal is None:
        lines.append(f"tests: glitch gate NIS {_nis(gate)} (chi-square) with glitch bursts, "
                     "stuck encoder, windowed NIS and CUSUM on the encoder innovations "
                     "(no nominal drives: dynamics tests off)")
    else:
        dyn = mon.dynamics
        ratio = gate / nominal.max_nominal_nis if nominal.max_nominal_nis > 0 else math.inf
        # an infinite threshold is a test the nominal drives could not set up: say it is off
        lag = (f"lag {dyn.lag_threshold:.2f} (from the nominal drives)"
               if math.isfinite(dyn.lag_threshold)
               else "lag off (no window of the nominal drives carried lag information)")
        start = (f"start {dyn.start_threshold:.2f}" if math.isfinite(dyn.start_threshold)
                 else "start off (the nominal drives gave no start-from-rest null)")
        lines.append(f"tests: glitch gate NIS {_nis(gate)} ({ratio:.3g} x the nominal maximum "
                     f"{nominal.max_nominal_nis:.0f}) with glitch bursts, stuck encoder; "
                     f"dynamics CUSUM thresholds: {lag}, covariance "
                     f"{dyn.covariance_threshold:.1f}, {start} (null from {nominal.n_drives} "
                     f"nominal drives, {nominal.duration_s / 60.0:.1f} min)")
    if landmarks is not None:
        lines.append(f"       scale test on {len(landmarks.ids)} landmarks at 2 Hz (threshold "
                     f"{mon.scale.threshold:.1f})")
    return lines


def _report(run: MonitorRun, print_fn: Callable[[str], object], *, fault: str | None,
            fault_at_s: float | None, expected: str | None) -> None:
    for line in run.summary():
        print_fn(line)
    if fault is None:
        return
    after = [e for e in run.events if e.t_s >= fault_at_s]
    right = [e for e in after if e.kind == expected]
    if right:
        print_fn(f"injected {fault} at {fault_at_s:.2f} s: first {expected} alarm at "
                 f"{right[0].t_s:.3f} s ({right[0].t_s - fault_at_s:.3f} s after the onset)")
    else:
        print_fn(f"injected {fault} at {fault_at_s:.2f} s: no {expected} alarm followed")


def run_on_simulator(model: MotionModel, *, robot: RobotParams | str = "create2",
                     duration_s: float = 30.0, seed: int = 0,
                     floor: str | FloorMap | None = None, fault: str | None = None,
                     fault_at_s: float | None = None, record: str | None = None,
                     nominal_drives: int = 20, landmarks: bool = True, gyro: bool = False,
                     print_fn: Callable[[str], object] = print,
                     progress: Callable[[str, int, int], None] | None = None) -> MonitorRun:
    """Drive :func:`monitor_route` on the simulator, monitor it, print alarms and a summary.

    Parameters
    ----------
    model : MotionModel
        Calibrated model of the robot.
    robot : RobotParams or str
        The robot, or a preset name or robot file (:func:`~drivers.sim.load_robot`);
        its own faults happen in the drive (not in Phase I).
    floor, seed
        Simulator settings (an empty room); ``floor`` defaults to the robot's.
    duration_s : float
        Simulated drive [s].
    fault : str, optional
        A key of :data:`FAULTS`, scheduled at ``fault_at_s`` (default half the drive).
    record : str, optional
        Write the frames (with the simulator's truth) as an ``lti-motion-log`` file.
    nominal_drives : int
        Phase I: nominal drives of the same length first (:func:`nominal_on_simulator`);
        0 leaves the dynamics tests off.
    landmarks : bool
        Simulate the landmark sensor and run the scale test.
    gyro : bool
        Fuse the robot's gyro (its ``[gyro]``) in the EKF (``--gyro``; opt-in: on a
        hard floor with the default scale priors it can cost accuracy, ``docs/ekf.md``).
    print_fn : callable
        Where the lines go.
    progress : callable, optional
        Phase I's steps (:func:`~fusion.monitoring.fit_nominal`'s ``progress``).

    Returns
    -------
    MonitorRun
        Ctrl-C during the drive ends it: ``interrupted`` is set, the frames before
        it are summarised and, with ``record``, written (as :func:`run_on_port`).

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale (before any drive).
    ValueError
        ``gyro`` for a robot without a ``[gyro]``.
    """
    from drivers.logs import Recorder
    from drivers.sim import Room, Simulator, floor_name, load_robot

    _require_scale(model)
    params = load_robot(robot) if isinstance(robot, str) else robot
    if gyro and params.gyro_noise_density_rad_s_sqrt_hz is None:
        raise ValueError(f"--gyro: the robot {params.name} has no gyro (a robot file's [gyro], "
                         "docs/robot_file.md)")
    floor = params.floor if floor is None else floor
    preset = params.name

    faults, expected = [], None
    if fault is not None:
        fault_at_s = 0.5 * duration_s if fault_at_s is None else fault_at_s
        sim_fault, expected = fault_for(fault, fault_at_s)
        faults.append(sim_fault)
    nominal = None
    if nominal_drives > 0:
        print_fn(f"phase I: fitting the dynamics null and the encoder gate on {nominal_drives} "
                 f"nominal drives of {duration_s:g} s (seeds {seed + 1000}-"
                 f"{seed + 999 + nominal_drives}, no fault) ...")
        nominal = nominal_on_simulator(model, robot=params, n_drives=nominal_drives,
                                       duration_s=duration_s, seed=seed, floor=floor,
                                       progress=progress)
    sim = Simulator(params, seed=seed, floor=floor, room=Room.empty(),
                    initial_pose=(0.0, 0.0, 0.0), faults=faults)
    commands = monitor_route(duration_s, dt_s=sim.dt_s, wheel_base_m=model.wheel_base_m,
                             rng=np.random.default_rng(seed))
    rec = Recorder(dt_s=sim.dt_s, meta={"source": "lti-motion monitor --sim", "preset": preset,
                                        "seed": seed, "floor": floor_name(floor),
                                        "fault": fault,
                                        "fault_at_s": fault_at_s,
                                        "counter_bits": params.counter_bits})
    print_fn(f"driving the simulated {preset} robot for {duration_s:g} s (seed {seed}, "
             f"{floor_name(floor)} floor)"
             + (f"; {fault} fault at {fault_at_s:g} s" if fault else ""))
    own = [f for f in params.faults if f.t_s < duration_s]
    if own:
        print_fn(f"the robot {preset} has faults of its own in this drive (its file's "
                 f"[[faults]], left out of Phase I): "
                 + ", ".join(f"{f.kind} at {f.t_s:g} s" for f in own))
    sensor_rng = np.random.default_rng([seed, 0x5E45])

    def frames() -> Iterator[tuple[SensorFrame, RangeBearing | None]]:
        block = max(1, round(1.0 / sim.dt_s))
        n = 0
        for k0 in range(0, len(commands), block):
            log = sim.run(commands[k0:k0 + block])
            for k in range(len(log)):
                full = log.frame(k)
                if record:
                    rec.add(full)
                # the landmark sensor sees the world (the true pose); the monitor sees its output
                seen = (sightings(full.true_pose, n, sensor_rng, dt_s=sim.dt_s)
                        if landmarks else None)
                n += 1
                # the filter and the monitor get what a robot reports: no truth
                yield replace(full, true_pose=None, true_body_m_s=None), seen

    density = params.gyro_noise_density_rad_s_sqrt_hz
    noise = GyroNoise(noise_density_rad_s_sqrt_hz=density) if density else GyroNoise()
    if density is not None:
        print_fn(f"the robot has a gyro: the EKF fuses its yaw rate (bias estimated; noise "
                 f"density {noise.noise_density_rad_s_sqrt_hz:.3g} rad/s/sqrt(Hz), "
                 f"{'the robot file' if density else 'the default'}'s)" if gyro
                 else "the robot has a gyro; --gyro fuses its yaw rate")
    run = monitor_frames(model, frames(), nominal=nominal,
                         landmarks=MONITOR_LANDMARKS if landmarks else None,
                         on_alarm_line=print_fn, counter_bits=params.counter_bits,
                         gyro=noise if gyro and density is not None else None)
    if run.interrupted:
        print_fn(f"stopped by Ctrl-C after {run.frames} frames")
    _report(run, print_fn, fault=fault, fault_at_s=fault_at_s, expected=expected)
    if record and len(rec):
        print_fn(f"wrote the drive to {rec.save(record)} (lti-motion replay reads it)")
    return run


def run_on_port(model: MotionModel, port: str, *, duration_s: float = 30.0, baud: int = 115200,
                clock_rate: float = 1.0, listen: bool = False, seed: int = 0,
                record: str | None = None, nominal_logs: Sequence[str] = (),
                print_fn: Callable[[str], object] = print,
                progress: Callable[[str, int, int], None] | None = None) -> MonitorRun:
    """Drive :func:`monitor_route` on a Roomba / Create 2 (or only listen), monitor it.

    Parameters
    ----------
    model : MotionModel
        Calibrated model of this robot.
    port : str
        Serial device.
    duration_s : float
        Robot time to drive or listen [s].
    baud, clock_rate
        As for :class:`drivers.roomba.Roomba`.
    listen : bool
        Send no wheel command: read the stream only (the robot stays where it is
        unless something else moves it).
    record : str, optional
        Write the frames as an ``lti-motion-log`` file.
    nominal_logs : sequence of str
        Logs of nominal drives of this robot on this route (``--record``):
        Phase I (:func:`nominal_from_logs`); none leaves the dynamics tests off.
    print_fn : callable
        Where the lines go.
    progress : callable, optional
        Phase I's steps (:func:`~fusion.monitoring.fit_nominal`'s ``progress``).

    Returns
    -------
    MonitorRun
        Ctrl-C during the drive ends it (closing the port stops the wheels):
        ``interrupted`` is set, the frames before it are summarised and, with
        ``record``, written.

    Raises
    ------
    PortError, StreamStalledError, PassiveModeError
        From the driver; the wheels are stopped first.
    MissingEncoderScaleError
        If the model has no encoder scale (before the port is opened).
    """
    from drivers.logs import Recorder
    from drivers.roomba import Roomba, RoombaOptions

    _require_scale(model)

    nominal = None
    if nominal_logs:
        print_fn(f"phase I: fitting the dynamics null and the encoder gate on "
                 f"{len(nominal_logs)} nominal drive log(s) ...")
        nominal = nominal_from_logs(model, nominal_logs, progress=progress)
    commands = monitor_route(duration_s, dt_s=model.dt_s, wheel_base_m=model.wheel_base_m,
                             rng=np.random.default_rng(seed))
    rec = Recorder(meta={"source": "lti-motion monitor --port", "port": port, "listen": listen})
    what = "listening to" if listen else "driving"
    print_fn(f"{what} the robot on {port} for {duration_s:g} s"
             + ("" if listen else " (needs 2 m x 2 m of clear floor; Ctrl-C stops it)"))
    options = RoombaOptions(baud_bps=baud, clock_rate=clock_rate, open_timeout_s=3.0,
                            stall_periods=max(5, math.ceil(0.3 * clock_rate / model.dt_s)))
    with Roomba(port, options=options) as robot:

        def frames() -> Iterator[SensorFrame]:
            for cmd in commands:
                frame = robot.read_frame() if listen else robot.step(cmd)
                if record:
                    rec.add(frame)
                yield frame

        # Ctrl-C ends the drive (monitor_frames keeps what came before); closing the
        # robot stops the wheels
        run = monitor_frames(model, frames(), nominal=nominal, on_alarm_line=print_fn)
    if run.interrupted:
        print_fn(f"stopped by Ctrl-C after {run.frames} frames")
    _report(run, print_fn, fault=None, fault_at_s=None, expected=None)
    if record and len(rec):
        print_fn(f"wrote the drive to {rec.save(record)} (lti-motion replay reads it)")
    return run


def _require_scale(model: MotionModel) -> None:
    """Fail before a drive starts (nothing driven, nothing lost) if counts cannot be scaled."""
    if model.m_per_tick is None:
        raise MissingEncoderScaleError.needed_by("the monitor")
