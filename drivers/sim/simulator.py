"""A physics simulator of a Roomba-class differential-drive robot, many robots in lock step.

The simulator is the project's embedded default: every model is calibrated and
tested against it, so it is deliberately *not* linear. Per wheel, a command
passes through a jittered transport delay, a PID speed loop with saturation
and anti-windup, a current-limited DC motor, wheel and body inertia, and a
floor contact with a traction limit, rolling resistance, tyre compression and
slip (see :mod:`drivers.sim.kernel` for the equations). The mechanics runs at
a quarter of a 1 ms controller step; frames come out once per sensor period.

A frame carries what a real Create 2 streams (raw encoder counts, 16-bit as the
Open Interface's unless ``RobotParams.counter_bits`` says otherwise, that
count wheel rotation in the commanded direction, six light-bump IR signals of
the walls and boxes of a :class:`~drivers.sim.Room`, bump flags, the
commands in effect, the wheel motors' currents and overcurrent flags) plus the
simulator's ground truth. Estimators must never
read the truth; tests and experiments compare against it.

Determinism: all randomness comes from per-robot seeds, drawn in fixed blocks
of periods, so the same seed gives the same frames bit for bit whether the
robot is stepped one period at a time or run over a whole sequence.

Examples
--------
>>> sim = Simulator("create2", seed=1)
>>> log = sim.run(np.full((200, 2), 0.2))        # 3 s straight at 0.2 m/s
>>> round(float(log.true_body_m_s[-1, 0]), 2)
0.2
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence

import numpy as np

from drivers.exceptions import SimulatorError
from drivers.sim import kernel as K
from drivers.sim.config import FLOORS, Fault, FloorMap, RobotParams, Room, get_floor, get_preset
from lti_motion.recordings.frames import FrameLog, SensorFrame

__all__ = ["Simulator", "ground_m_per_tick"]

_log = logging.getLogger(__name__)

_FLOOR_NAMES = tuple(FLOORS)
_BLOCK = 1024           # periods per block of pre-drawn noise
_N_EVENT = 6            # per-period event draws: spike L/R, spike size L/R, lost, latency


def ground_m_per_tick(params: RobotParams, floor: str) -> float:
    """True ground travel per encoder tick without slip on a floor [m/tick], mean of the wheels.

    The wheels' true diameters differ from the nominal one, and the tyre's
    compression on soft floors shrinks the rolling radius, so this is
    ``pi D (1 + mean diameter error) (1 - compression) / ticks_per_rev``.
    """
    diameter = 1.0 + float(np.mean(params.wheel_diameter_errors))
    return params.m_per_tick * diameter * (1.0 - get_floor(floor).compression)


def _params_row(p: RobotParams, floor_default: int) -> np.ndarray:
    row = np.zeros(K.N_PARAMS)
    nsub = max(1, round(p.period_s / p.internal_step_s))
    row[[K.P_B, K.P_DIAM, K.P_TPR, K.P_MASS, K.P_I0, K.P_RPAY, K.P_FRAC, K.P_MW, K.P_K,
         K.P_R, K.P_ILIM, K.P_VSUP, K.P_BG, K.P_FC, K.P_BAL, K.P_KP, K.P_KI, K.P_KD,
         K.P_KFF, K.P_TAU, K.P_DELAY, K.P_JITTER, K.P_T, K.P_NSUB, K.P_RADIUS, K.P_IRR,
         K.P_IRREF, K.P_IRNOISE, K.P_FLOOR0]] = [
        p.true_wheel_base_m, p.wheel_diameter_m, p.ticks_per_rev, p.mass_kg, p.yaw_inertia_kg_m2,
        p.payload_radius_m, p.drive_weight_fraction, p.wheel_mass_kg, p.motor_k,
        p.motor_resistance_ohm, p.current_limit_a, p.supply_v, p.gear_viscous_n_s_m,
        p.gear_coulomb_n, p.motor_balance, p.pid_kp, p.pid_ki, p.pid_kd, p.pid_kff,
        p.speed_filter_s, p.delay_periods, p.delay_jitter_periods, p.period_s, nsub,
        p.robot_radius_m, p.ir_radius_m, p.ir_reference_m, p.ir_noise, floor_default,
    ]
    row[K.P_IRANG:K.P_IRANG + 6] = p.ir_angles_rad
    row[K.P_DERR0:K.P_DERR0 + 2] = p.wheel_diameter_errors
    row[K.P_CASTER] = p.caster_offset_m
    return row


def _wrap(ticks: np.ndarray, modulus: np.ndarray, ring: np.ndarray | None) -> np.ndarray:
    """Counts of shape (N, n, 2) on each robot's ``2**counter_bits`` ring: ``modulus``, shape
    (N, 1, 1), is ``2**min(bits, 62)``, ``ring`` where ``bits <= 62`` (None: everywhere;
    63, 64: unwrapped, a signed 64-bit count that no drive overflows)."""
    if ring is None:
        return ticks % modulus
    return np.where(ring, ticks % modulus, ticks)


def _own_faults(params: Sequence[RobotParams]) -> list[Fault]:
    """The robots' own faults (:attr:`RobotParams.faults`), each on its robot only."""
    if all(p.faults == params[0].faults for p in params):
        return list(params[0].faults)
    return [dataclasses.replace(f, robots=(i,) if f.robots is None else f.robots)
            for i, p in enumerate(params) for f in p.faults]


class _NoiseBlocks:
    """Random draws of every robot, generated in fixed blocks of periods.

    Block ``b`` of stream ``s`` for the robot with seed ``seed`` comes from
    ``default_rng([seed, s, b])``, so a draw depends only on the seed and the
    period index, never on how the periods were split into calls.
    """

    def __init__(self, seeds: Sequence[int]) -> None:
        self.seeds = tuple(seeds)
        self._cache: dict[tuple[int, int], np.ndarray] = {}

    def _one(self, seed: int, stream: int, b: int) -> np.ndarray:
        rng = np.random.default_rng([seed, stream, b])
        if stream == 0:     # physics: jitter, roughness, IR noise
            blk = rng.standard_normal((_BLOCK, K.N_NOISE))
            blk[:, K.NZ_JITTER] = rng.uniform(-0.5, 0.5, _BLOCK)
        elif stream == 2:   # the gyro's white noise, drawn only for robots with a gyro
            blk = rng.standard_normal((_BLOCK, 1))
        else:               # events: spikes, lost frames, timestamp latency
            blk = rng.uniform(0.0, 1.0, (_BLOCK, _N_EVENT))
            blk[:, 5] = rng.standard_normal(_BLOCK)
        return blk

    def _block(self, stream: int, b: int) -> np.ndarray:
        key = (stream, b)
        if key not in self._cache:
            if len(self._cache) >= 8:
                self._cache.clear()
            self._cache[key] = np.stack([self._one(s, stream, b) for s in self.seeds])
        return self._cache[key]

    def draw(self, stream: int, k0: int, n: int) -> np.ndarray:
        """Draws for periods ``k0 .. k0 + n - 1``, shape ``(N, n, columns)``."""
        b0, b1 = k0 // _BLOCK, (k0 + n - 1) // _BLOCK
        start = k0 - b0 * _BLOCK
        if b0 == b1:
            return self._block(stream, b0)[:, start:start + n]
        blocks = np.concatenate([self._block(stream, b) for b in range(b0, b1 + 1)], axis=1)
        return blocks[:, start:start + n]


class Simulator:
    """One robot, or ``N`` robots stepped in lock step.

    Parameters
    ----------
    robot : str or RobotParams or sequence of RobotParams
        A preset name (``"create2"``, ``"paper"``), one robot's parameters, or
        one set of parameters per robot (all with the same ``period_s``).
    n_robots : int, optional
        Number of robots of a batch. A batch is also made when ``robot`` or
        ``seed`` is a sequence. Without any, the simulator holds one robot
        and its outputs have no robot axis.
    seed : int or sequence of int
        Seed per robot (an int for a batch means ``seed, seed + 1, ...``).
    floor : str or FloorMap, optional
        Surface everywhere (``"hard"``, ``"tile"``, ``"carpet"``) or by region; default
        the robots' own (:attr:`RobotParams.floor`, the same for every robot).
    room : Room, optional
        Walls and boxes; default :meth:`Room.cluttered`.
    initial_pose : array_like, shape (3,) or (N, 3), optional
        Start pose(s) (x m, y m, heading rad); default the room's centre
        ``(2.5, 2.5, 0)``.
    faults : sequence of Fault
        Scheduled changes (times from the start of the simulation), besides each
        robot's own (:attr:`RobotParams.faults`, which hit only that robot).

    Raises
    ------
    SimulatorError
        Unknown preset or floor, mismatched batch sizes or periods, bad poses.
    """

    def __init__(
        self,
        robot: str | RobotParams | Sequence[RobotParams] = "create2",
        *,
        n_robots: int | None = None,
        seed: int | Sequence[int] = 0,
        floor: str | FloorMap | None = None,
        room: Room | None = None,
        initial_pose: np.ndarray | Sequence[float] | None = None,
        faults: Sequence[Fault] = (),
    ) -> None:
        batch = n_robots is not None or not isinstance(robot, (str, RobotParams)) or not (
            isinstance(seed, (int, np.integer)))
        if isinstance(robot, str):
            robot = get_preset(robot)
        if isinstance(seed, (int, np.integer)):
            n = n_robots if n_robots is not None else (
                1 if isinstance(robot, RobotParams) else len(robot))
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = [int(s) for s in seed]
        params = [robot] * len(seeds) if isinstance(robot, RobotParams) else list(robot)
        if n_robots is not None and n_robots < 1:
            raise SimulatorError(f"n_robots must be >= 1, got {n_robots}")
        if len(params) != len(seeds) or (n_robots is not None and len(seeds) != n_robots):
            raise SimulatorError(
                f"batch sizes disagree: {len(params)} parameter sets, {len(seeds)} seeds, "
                f"n_robots={n_robots}"
            )
        if len({p.period_s for p in params}) != 1:
            raise SimulatorError("robots in lock step must share one period_s; got "
                                 f"{sorted({p.period_s for p in params})}")
        self.batch = batch
        self.params: tuple[RobotParams, ...] = tuple(params)
        self.seeds = tuple(seeds)
        self.n = len(seeds)
        self.dt_s = params[0].period_s
        self.room = room if room is not None else Room.cluttered()
        if floor is None:
            floor = params[0].floor
            if any(p.floor != floor for p in params):
                raise SimulatorError("robots in lock step drive on one floor; their "
                                     "parameters name different ones: give floor=")
        self.floor_map = floor if isinstance(floor, FloorMap) else FloorMap(default=floor)
        self.faults = tuple(sorted([*_own_faults(params), *faults], key=lambda f: f.t_s))
        for f in self.faults:
            if f.robots is not None and any(not 0 <= r < self.n for r in f.robots):
                raise SimulatorError(
                    f"fault {f.kind!r} names robots {f.robots} outside 0..{self.n - 1}")
        default_idx = _FLOOR_NAMES.index(self.floor_map.default)
        self._params = np.stack([_params_row(p, default_idx) for p in params])
        self._regions = np.array(
            [[r[0], r[1], r[2], r[3], _FLOOR_NAMES.index(r[4])] for r in self.floor_map.regions],
            dtype=float,
        ).reshape(-1, 5)
        self._walls = np.ascontiguousarray(self.room.segments)
        # the kernel's floor table, one row per floor of _FLOOR_NAMES
        self._floors = np.array(
            [[f.friction, f.slip_ratio, f.rolling_resistance, f.compression, f.roughness_n,
              f.scrub] for f in FLOORS.values()])
        pose0 = np.broadcast_to(
            np.asarray((2.5, 2.5, 0.0) if initial_pose is None else initial_pose, float),
            (self.n, 3),
        )
        if not np.all(np.isfinite(pose0)):
            raise SimulatorError("initial_pose must be finite")
        self._state = np.zeros((self.n, K.N_STATE))
        self._state[:, :3] = pose0
        self._queue = np.zeros((self.n, K.QUEUE_LEN, 3))
        self._qinfo = np.zeros((self.n, 2), np.int64)
        self._noise = _NoiseBlocks(seeds)
        self._k = 0
        self._last_t = np.full(self.n, -np.inf)
        self._times: tuple[int, np.ndarray] = (-1, np.empty((self.n, 0)))  # see _period_times
        # what every call needs and only the parameters decide, built once
        self._vmax = np.array([p.max_speed_m_s for p in params])[:, None, None]
        self._vlimit = self._vmax + 1e-9
        self._lat_mean = np.array([p.latency_s for p in params])[:, None]
        self._lat_std = np.array([p.latency_jitter_s for p in params])[:, None]
        bits = np.array([p.counter_bits for p in params], np.int64)[:, None, None]
        self._modulus = np.left_shift(np.int64(1), np.minimum(bits, 62))
        self._ring = None if np.all(bits <= 62) else bits <= 62
        # one period's inputs with no fault active (the kernel only reads them)
        self._idle = np.zeros((self.n, 1, K.N_PERIOD))
        self._idle[:, :, K.PP_FLOOR] = -1.0
        self._idle[:, :, K.PP_PAYLOAD] = np.array([p.payload_kg for p in params])[:, None]
        self._idle[:, :, K.PP_GAIN0:K.PP_GAIN0 + 2] = 1.0
        self._idle[:, :, K.PP_DIAM0:K.PP_DIAM0 + 2] = 1.0
        self._fault_rows = [slice(None) if f.robots is None else np.array(f.robots)
                            for f in self.faults]
        # the gyro (RobotParams.gyro_*): None when no robot has one (no draws, no output)
        density = [p.gyro_noise_density_rad_s_sqrt_hz for p in params]
        self._gyro_std = None if all(d is None for d in density) else np.array(
            [np.nan if d is None else d / np.sqrt(self.dt_s) for d in density])[:, None]
        self._gyro_bias = np.array([p.gyro_bias_rad_s for p in params])[:, None]

    # -- public API -------------------------------------------------------------

    @property
    def period_index(self) -> int:
        """Number of sensor periods simulated so far."""
        return self._k

    @property
    def t_s(self) -> float:
        """Simulation time [s] (start of the next period)."""
        return self._k * self.dt_s

    def step(self, cmd_m_s: np.ndarray | Sequence[float]) -> SensorFrame:
        """Send one command pair per robot and simulate one sensor period.

        Parameters
        ----------
        cmd_m_s : array_like, shape (2,) or (N, 2)
            Wheel-speed commands (left, right) [m/s]; rounded to 1 mm/s as the
            Open Interface does.

        Returns
        -------
        SensorFrame
            For a batch every field has a leading robot axis and ``valid`` is
            an array; a lost frame has ``valid`` False.
        """
        cmd = np.asarray(cmd_m_s, dtype=float)
        want = (self.n, 2) if self.batch else (2,)
        if cmd.shape != want:
            raise SimulatorError(f"step() expects commands of shape {want}, got {cmd.shape}")
        t_s, ticks, light, bumps, cmd, valid, pose, body, current, over, gyro = self._simulate(
            cmd.reshape(self.n, 1, 2))
        take = (slice(None), 0) if self.batch else (0, 0)
        return SensorFrame(
            t_s=t_s[take], ticks=ticks[take], light_bump=light[take], bumps=bumps[take],
            cmd_m_s=cmd[take], valid=valid[take], true_pose=pose[take],
            true_body_m_s=body[take], motor_current_a=current[take],
            wheel_overcurrent=over[take],
            yaw_rate_rad_s=None if gyro is None else (gyro[:, 0] if self.batch
                                                      else float(gyro[0, 0])),
        )

    def run(self, cmd_m_s: np.ndarray) -> FrameLog:
        """Simulate a whole command sequence (one command pair per period).

        Parameters
        ----------
        cmd_m_s : ndarray, shape (n, 2) or (N, n, 2)
            Wheel-speed commands (left, right) [m/s] per period.

        Returns
        -------
        FrameLog
            ``n`` frames (per robot for a batch), continuing from the current
            time; identical to ``n`` calls of :meth:`step`.
        """
        cmd = np.asarray(cmd_m_s, dtype=float)
        ok = cmd.ndim == 3 and cmd.shape[0] == self.n if self.batch else cmd.ndim == 2
        if not ok or cmd.shape[-1] != 2 or cmd.shape[-2] == 0:
            want = f"({self.n}, n, 2)" if self.batch else "(n, 2)"
            raise SimulatorError(f"run() expects commands of shape {want} with n >= 1, "
                                 f"got {cmd.shape}")
        out = self._advance(cmd.reshape(self.n, -1, 2))
        return out if self.batch else out.robot(0)

    def place(self, pose: np.ndarray | Sequence[float]) -> None:
        """Put the robot(s) down at ``pose``, at rest, as a person carrying it would.

        Wheel and body speeds, the speed loop's integrators and pending
        commands are cleared; encoder counts, time and the fault schedule go on.

        Parameters
        ----------
        pose : array_like, shape (3,) or (N, 3)
            New pose(s) (x m, y m, heading rad).
        """
        pose = np.broadcast_to(np.asarray(pose, dtype=float), (self.n, 3))
        if not np.all(np.isfinite(pose)):
            raise SimulatorError("place() needs a finite pose")
        keep = self._state[:, [K.TICK0, K.TICK0 + 1, K.OFF0, K.OFF0 + 1, K.T_NOW]]
        self._state[:] = 0.0
        self._state[:, [K.TICK0, K.TICK0 + 1, K.OFF0, K.OFF0 + 1, K.T_NOW]] = keep
        self._state[:, K.LAST_EFF] = keep[:, -1]
        self._state[:, :3] = pose
        self._qinfo[:] = 0

    # -- internals --------------------------------------------------------------

    def _check_commands(self, cmd: np.ndarray) -> np.ndarray:
        if not (np.abs(cmd) <= self._vlimit).all():     # NaN fails too
            if not np.all(np.isfinite(cmd)):
                bad = np.argwhere(~np.isfinite(cmd))[0]
                raise SimulatorError(
                    f"commands must be finite; first bad value at index {tuple(bad)}")
            worst = float(np.max(np.abs(cmd)))
            raise SimulatorError(
                f"wheel-speed command {worst:.4g} m/s exceeds the robot's limit of "
                f"{float(self._vmax.min()):.4g} m/s; clip commands before sending"
            )
        return np.rint(cmd * 1000.0) / 1000.0       # the OI takes whole mm/s (= np.round)

    def _schedule(self, k0: int, n: int, events: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Per-period fault inputs, tick offsets of encoder spikes (None: none), and the
        valid mask, for periods ``k0 .. k0 + n - 1`` with their event draws."""
        per = self._idle if n == 1 else np.repeat(self._idle, n, axis=1)
        fresh = n > 1       # per may be written (self._idle never is)
        spikes = None
        valid = np.ones((self.n, n), bool)
        t = None
        # period times are increasing, so a fault is active over a run of periods
        t_first, t_last = k0 * self.dt_s, (k0 + n - 1) * self.dt_s
        for f, rows in zip(self.faults, self._fault_rows, strict=True):
            start, end = f.t_s - 1e-9, f.t_s + f.duration_s - 1e-9
            if t_last < start or t_first >= end:
                continue
            if t is None:
                t = (k0 + np.arange(n)) * self.dt_s
            active = np.flatnonzero((t >= start) & (t < end))
            if active.size == 0:
                continue
            sel = (rows, slice(active[0], active[-1] + 1))
            if not fresh:
                per, fresh = per.copy(), True
            if f.kind == "floor":
                per[..., K.PP_FLOOR][sel] = _FLOOR_NAMES.index(f.floor)
            elif f.kind == "payload":
                per[..., K.PP_PAYLOAD][sel] = f.payload_kg
            elif f.kind == "delay":
                per[..., K.PP_DELAY][sel] = f.extra_periods
            for wh in f.wheels:
                if f.kind == "motor":
                    per[..., K.PP_GAIN0 + wh][sel] = 1.0 - f.weakening
                elif f.kind == "stuck_encoder":
                    per[..., K.PP_STUCK0 + wh][sel] = 1.0
                elif f.kind == "stall":
                    per[..., K.PP_STALL0 + wh][sel] = 1.0
                elif f.kind == "wheel_diameter":
                    per[..., K.PP_DIAM0 + wh][sel] = 1.0 + f.diameter_change
                elif f.kind == "encoder_spikes":
                    if spikes is None:
                        spikes = np.zeros((self.n, n, 2))
                    hit = events[..., wh] < f.rate_hz * self.dt_s
                    draw = events[..., 2 + wh]      # sign and size in one uniform draw
                    size = f.magnitude_ticks * (0.5 + 2.0 * np.abs(draw - 0.5))
                    spikes[..., wh][sel] += (hit * size * np.where(draw < 0.5, -1.0, 1.0))[sel]
            if f.kind == "lost_frames":
                valid[sel] &= ~(events[..., 4] < f.probability)[sel]
        return per, spikes, valid

    def _simulate(self, cmd: np.ndarray) -> tuple[np.ndarray, ...]:
        """The next ``cmd.shape[1]`` periods: t_s, ticks, light, bumps, cmd, valid, pose,
        body, current, overcurrent, gyro (None without one), each with a robot and a
        period axis."""
        cmd = self._check_commands(cmd)
        k0, n = self._k, cmd.shape[1]
        # true heading at the start, for the gyro
        heading0 = self._state[:, 2].copy() if self._gyro_std is not None else None
        events = self._noise.draw(1, k0, n)
        per, spikes, valid = self._schedule(k0, n, events)
        noise = np.ascontiguousarray(self._noise.draw(0, k0, n))
        ticks, light, bumps, pose, body, current, overcurrent = K.empty_outputs(self.n, n)
        K.run_periods(self._state, self._queue, self._qinfo, self._params, self._floors,
                      self._regions, self._walls, np.ascontiguousarray(cmd), per, noise,
                      ticks, light, bumps, pose, body, current, overcurrent)
        if spikes is not None:
            ticks = ticks + np.round(spikes).astype(np.int64)
        ticks = _wrap(ticks, self._modulus, self._ring)
        # host timestamps: end of each period plus a jittered, never negative latency
        t_s = np.maximum(self._period_times(k0, n, events), self._last_t[:, None] + 1e-6)
        if n > 1:
            t_s = np.maximum.accumulate(t_s, axis=1)
        self._last_t = t_s[:, -1].copy()
        gyro = None if heading0 is None else self._gyro(k0, heading0, pose[..., 2])
        self._k += n
        return t_s, ticks, light, bumps, cmd, valid, pose, body, current, overcurrent, gyro

    def _period_times(self, k0: int, n: int, events: np.ndarray) -> np.ndarray:
        """Host times of periods ``k0 ..`` before the monotone clamp, (N, n) [s]: the end of
        each period plus its jittered, never negative latency. A single period (step()) reads
        them from a whole block of periods computed at once (the same elementwise values)."""
        if n > 1:
            latency = np.maximum(0.0, self._lat_mean + self._lat_std * events[..., 5])
            return np.arange(k0 + 1, k0 + 1 + n) * self.dt_s + latency
        b, start = divmod(k0, _BLOCK)
        if b != self._times[0]:
            k1 = b * _BLOCK
            self._times = (b, self._period_times(k1, _BLOCK, self._noise.draw(1, k1, _BLOCK)))
        return self._times[1][:, start:start + 1]

    def _gyro(self, k0: int, heading0: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """Gyro readings of periods ``k0 ..``, shape (N, n): the true heading's change over
        each period over ``dt`` (the period's mean body yaw rate), plus the bias, plus white
        noise of standard deviation ``density / sqrt(dt)``; NaN for robots without a gyro."""
        turn = np.diff(np.concatenate([heading0[:, None], heading], axis=1), axis=1)
        turn = np.arctan2(np.sin(turn), np.cos(turn))   # wrapped, in case the kernel wraps
        noise = self._noise.draw(2, k0, heading.shape[1])[..., 0]
        return turn / self.dt_s + self._gyro_bias + self._gyro_std * noise

    def _advance(self, cmd: np.ndarray) -> FrameLog:
        k0 = self._k
        t_s, ticks, light, bumps, cmd, valid, pose, body, current, over, gyro = self._simulate(
            cmd)
        return FrameLog(
            t_s=t_s, ticks=ticks, light_bump=light, bumps=bumps, cmd_m_s=cmd, valid=valid,
            dt_s=self.dt_s, true_pose=pose, true_body_m_s=body, motor_current_a=current,
            wheel_overcurrent=over, yaw_rate_rad_s=gyro,
            meta={"preset": [p.name for p in self.params], "seeds": list(self.seeds),
                  "counter_bits": [p.counter_bits for p in self.params],
                  "floor": self.floor_map.default, "k0": k0},
        )
