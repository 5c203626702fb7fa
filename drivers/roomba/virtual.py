"""A virtual Roomba: the physics simulator behind the Open Interface bytes, on a pseudo-terminal.

:class:`VirtualRoomba` opens a pseudo-terminal, puts both ends in raw mode and
runs a background thread that behaves like a Create 2 on the other end of a
serial cable: it parses Open Interface commands (spec §2, §3), tracks the OI
mode, drives a seeded :class:`~drivers.sim.Simulator` one stream period at a
time, and answers with stream frames, Sensors and Query List replies encoded
by :mod:`drivers.roomba.oi`. The pyserial driver :class:`drivers.roomba.Roomba`
opens :attr:`VirtualRoomba.device_path` exactly as it would open
``/dev/ttyUSB0``.

Section numbers ("spec §8.1") are those listed in :mod:`drivers.roomba.oi`.

Timing and command alignment
----------------------------
The emulator's clock ticks once per stream period, ``0.015 / speed`` seconds
of wall time, paced against :func:`time.monotonic` (tick ``k`` is due at
``t_start + k * period / speed``, so sleep errors never accumulate). At each
tick it first reads and executes every byte that has arrived, then steps the
simulator once with the wheel command in effect, then sends that period's
frame. A Drive Direct received in the wall interval ``(tick k-1, tick k]``
therefore acts in simulator period ``k``, and the frame sent at tick ``k``
carries it in packets 41/42. A host that answers frame ``k-1`` within one
period gets its command into frame ``k``; a slower host's command lands one
(or more) periods later, and two commands arriving in the same interval leave
only the second in effect. :attr:`VirtualRoomba.applied_commands_m_s` records
the command used in every simulator period and :attr:`frame_periods` the
period of every frame sent, so ``Simulator(...).run(applied_commands_m_s)``
reproduces every streamed value bit for bit whatever the timing was.

The simulator runs from :meth:`start` on, streaming or not (the robot keeps
moving while the stream is paused); in Off and Passive mode its wheels are
commanded to zero. A thread that falls behind its schedule (a loaded host)
catches up by running the missed periods back to back, so the frames arrive
in a burst, as from a USB adapter's buffer (G17); beyond
``max_catch_up_periods`` it re-anchors the schedule instead, simulator time
then runs slower than wall time, and ``overruns`` counts the event. Frames
are never skipped for lateness, and outgoing bytes are queued, never dropped,
while the host does not read (up to 1 MiB).

Examples
--------
>>> with VirtualRoomba(seed=1, options=VirtualRoombaOptions(speed=10.0)) as robot:
...     robot.device_path.startswith("/dev/")
True
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import select
import struct
import sys
import threading
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drivers.exceptions import ProtocolError
from drivers.roomba.oi import (
    COMMAND_DATA_BYTES,
    MAX_WHEEL_SPEED_MM_S,
    PACKETS,
    OIMode,
    Opcode,
    PacketLayout,
)
from drivers.roomba.virtual_options import (
    DEFAULT_BANNER,
    DEFAULT_CHARGER_TEXT,
    VirtualRoombaOptions,
)
from drivers.sim.config import Fault, FloorMap, RobotParams, Room, floor_name, load_robot
from drivers.sim.simulator import Simulator

__all__ = [
    "DEFAULT_BANNER",
    "DEFAULT_CHARGER_TEXT",
    "EmulatorStats",
    "ReceivedCommand",
    "VirtualRoomba",
    "VirtualRoombaOptions",
    "serve",
]

_log = logging.getLogger(__name__)

_WHEEL_BASE_MM = 235.0          # Drive (137) kinematics, spec §3.1
_MAX_OUT_QUEUE = 1 << 20        # bytes held for a host that does not read
_READ_CHUNK = 4096


class ReceivedCommand(NamedTuple):
    """One complete command the virtual Roomba parsed.

    Attributes
    ----------
    t_s : float
        Robot time [s] at receipt: the start of the simulator period the
        command acts in.
    opcode : int
        The opcode byte.
    data : bytes
        Its data bytes.
    mode : int
        OI mode (packet 35 value) when it arrived.
    accepted : bool
        ``False`` if the mode made the robot ignore it (spec §2, §3).
    """

    t_s: float
    opcode: int
    data: bytes
    mode: int
    accepted: bool


@dataclass(frozen=True)
class EmulatorStats:
    """Counters of a :class:`VirtualRoomba` (a snapshot).

    Attributes
    ----------
    periods : int
        Simulator periods run.
    frames_sent : int
        Stream frames queued for sending (after suppression by a stall).
    frames_suppressed : int
        Frames not sent because of a stall or a simulator lost-frame fault.
    bytes_sent : int
        Bytes written to the pseudo-terminal.
    bytes_corrupted, bytes_dropped : int
        Outgoing bytes with a flipped bit, and outgoing bytes dropped, by the line faults.
    bytes_ignored : int
        Received bytes ignored: unknown opcodes and anything but Start/Reset in Off.
    overruns : int
        Times the thread fell behind and re-anchored its schedule.
    """

    periods: int
    frames_sent: int
    frames_suppressed: int
    bytes_sent: int
    bytes_corrupted: int
    bytes_dropped: int
    bytes_ignored: int
    overruns: int


class VirtualRoomba:
    """The simulator behind the Roomba Open Interface on a pseudo-terminal.

    Parameters
    ----------
    robot : str or RobotParams
        Simulator preset or parameters (``"create2"``, ``"paper"``, ...); its own
        faults (:attr:`~drivers.sim.RobotParams.faults`) happen as scheduled.
    seed : int
        Seed of the simulator and (through a separate generator) of the line faults.
    floor, room, initial_pose, faults
        Passed to :class:`~drivers.sim.Simulator` (``floor`` defaults to the robot's;
        ``faults`` are the
        simulator's own: floor changes, payload, lost frames, ...).
    options : VirtualRoombaOptions, optional
        Its pace against the wall clock and its line's faults and quirks
        (:class:`~drivers.roomba.VirtualRoombaOptions`: ``speed``, corrupted and
        dropped bytes, a silent stream, a fall to Passive, banner and charger
        text, the off-by-one mode report); default ``VirtualRoombaOptions()``.

    Attributes
    ----------
    options : VirtualRoombaOptions
        Its options.
    speed : float
        ``options.speed``: robot seconds per wall second.

    Raises
    ------
    ValueError
        For options that are not a :class:`VirtualRoombaOptions`.
    SimulatorError
        For a bad preset, floor, pose or fault.

    Notes
    -----
    The pseudo-terminal's slave end is put in raw mode right after
    ``openpty()``, because a fresh slave has IXON set and would swallow byte
    19, the stream header, as XOFF (spec §8.1). The emulator keeps its own
    slave descriptor open so the device survives a driver closing it.
    Everything is paced against :func:`time.monotonic`; :meth:`stop` joins the
    thread with a timeout.
    """

    def __init__(
        self,
        robot: str | RobotParams = "create2",
        *,
        seed: int = 0,
        floor: str | FloorMap | None = None,
        room: Room | None = None,
        initial_pose: Sequence[float] | None = None,
        faults: Sequence[Fault] = (),
        options: VirtualRoombaOptions | None = None,
    ) -> None:
        opts = VirtualRoombaOptions() if options is None else options
        if not isinstance(opts, VirtualRoombaOptions):
            raise ValueError(f"options must be a VirtualRoombaOptions, got "
                             f"{type(opts).__name__}")
        self.options = opts
        self.sim = Simulator(robot, seed=seed, floor=floor, room=room,
                             initial_pose=initial_pose, faults=faults)
        self.dt_s = float(self.sim.dt_s)
        self.seed = int(seed)
        self._rng = np.random.default_rng([int(seed), 0x4C494E45])  # "LINE": own stream
        # OI state: touched only by the thread once started
        self.mode = OIMode.OFF
        self._wheels_mm_s = (0, 0)          # (left, right) from Drive Direct / Drive
        self._drive = (0, 0)                # packets 39/40 (last Drive)
        self._layout: PacketLayout | None = None
        self._streaming = False
        self._inbuf = bytearray()
        self._out = bytearray()
        self._charger_sent = False
        self._passive_fired = False
        self._values = _base_values()
        # records, shared with readers under the lock
        self._lock = threading.Lock()
        self._received: list[ReceivedCommand] = []
        self._texts: list[str] = []
        self._place: np.ndarray | None = None
        self._applied: list[tuple[float, float]] = []
        self._frame_periods: list[int] = []
        self._counts = dict.fromkeys(
            ("frames_sent", "frames_suppressed", "bytes_sent", "bytes_corrupted",
             "bytes_dropped", "bytes_ignored", "overruns"), 0)
        # pseudo-terminal
        self._master: int | None = None
        self._slave: int | None = None
        self.device_path = ""
        self._thread: threading.Thread | None = None
        self._stop_event = threading.Event()
        self._error: BaseException | None = None

    @property
    def speed(self) -> float:
        """Robot seconds per wall second (``options.speed``)."""
        return float(self.options.speed)

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> VirtualRoomba:
        """Open the pseudo-terminal and start the robot's thread (idempotent).

        Returns
        -------
        VirtualRoomba
            ``self``, with :attr:`device_path` set.
        """
        if self._thread is not None:
            return self
        master, slave = os.openpty()
        tty.setraw(slave)       # at once: byte 19 is XOFF in cooked mode (spec §8.1)
        with contextlib.suppress(OSError):
            tty.setraw(master)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.device_path = os.ttyname(slave)
        self._stop_event.clear()
        self._thread = threading.Thread(target=self._run, name=f"VirtualRoomba {self.device_path}",
                                        daemon=True)
        self._thread.start()
        _log.info("virtual Roomba on %s (speed %g, seed %d)", self.device_path, self.speed,
                  self.seed)
        return self

    def stop(self, *, timeout_s: float = 2.0) -> None:
        """Stop the thread (joined with a timeout), handle last input, close the pty.

        Bytes the driver wrote before closing are still read and recorded, so
        a test can check the driver's shutdown commands after ``stop()``.
        Idempotent; never raises for a pty that went away.
        """
        thread = self._thread
        if thread is None:
            return
        self._stop_event.set()
        thread.join(timeout_s)
        if thread.is_alive():
            _log.error("virtual Roomba thread did not stop within %.1f s", timeout_s)
        else:
            self._drain_input()     # whatever arrived after the last tick
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        self._thread = None

    def __enter__(self) -> VirtualRoomba:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """Whether the thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def error(self) -> BaseException | None:
        """The exception that ended the thread, if any."""
        return self._error

    # ------------------------------------------------------------------ records

    @property
    def received(self) -> list[ReceivedCommand]:
        """Copy of every complete command parsed so far, oldest first."""
        with self._lock:
            return list(self._received)

    @property
    def applied_commands_m_s(self) -> np.ndarray:
        """Wheel command (left, right) [m/s] used in each simulator period, shape (n, 2)."""
        with self._lock:
            return np.array(self._applied, dtype=float).reshape(-1, 2)

    @property
    def frame_periods(self) -> np.ndarray:
        """Simulator period index of each stream frame queued for sending, shape (m,)."""
        with self._lock:
            return np.array(self._frame_periods, dtype=np.int64)

    @property
    def stats(self) -> EmulatorStats:
        """A snapshot of the counters."""
        with self._lock:
            return EmulatorStats(periods=len(self._applied), **self._counts)

    def send_text(self, text: str) -> None:
        """Send ASCII text (a banner, charger status) before the next period's frame (G21).

        Thread-safe; the text goes through the line faults like every other byte.
        """
        with self._lock:
            self._texts.append(text)

    def place(self, pose: np.ndarray | tuple[float, float, float]) -> None:
        """Put the simulated robot down at ``pose`` (x m, y m, heading rad) before the next period.

        As a person carrying the robot would: it lands at rest, the encoders and
        the stream go on (:meth:`drivers.sim.Simulator.place`). Thread-safe.
        """
        pose = np.asarray(pose, dtype=float).reshape(3)
        with self._lock:
            self._place = pose

    def wait_until(self, predicate: Callable[[VirtualRoomba], bool], *,
                   timeout_s: float = 2.0) -> bool:
        """Poll ``predicate(self)`` every millisecond until it holds or ``timeout_s`` passes.

        Returns
        -------
        bool
            Whether the predicate held.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            if predicate(self):
                return True
            if time.monotonic() >= deadline or not self.running:
                return bool(predicate(self))
            time.sleep(0.001)

    # ------------------------------------------------------------------ thread

    def _run(self) -> None:
        period = self.dt_s / self.speed
        next_tick = time.monotonic() + period
        master = self._master
        try:
            while not self._stop_event.is_set():
                now = time.monotonic()
                wait = next_tick - now
                if wait > 0:
                    wlist = [master] if self._out else []
                    readable, writable, _ = select.select([master], wlist, [], min(wait, 0.05))
                    if readable:
                        self._read_input()
                    if writable:
                        self._flush_output()
                    continue
                if -wait > self.options.max_catch_up_periods * period:
                    with self._lock:
                        self._counts["overruns"] += 1
                    next_tick = now
                self._read_input()
                self._tick()
                self._flush_output()
                next_tick += period
        except BaseException as exc:   # report, never kill the interpreter from a thread
            self._error = exc
            _log.exception("virtual Roomba thread failed")

    def _drain_input(self, *, quiet_s: float = 0.01, max_s: float = 0.2) -> None:
        """Read until the line has been quiet for ``quiet_s`` (pty data moves asynchronously)."""
        deadline = time.monotonic() + max_s
        while self._master is not None and time.monotonic() < deadline:
            readable, _, _ = select.select([self._master], [], [], quiet_s)
            if not readable:
                break
            self._read_input()

    def _read_input(self) -> None:
        if self._master is None:
            return
        while True:
            try:
                chunk = os.read(self._master, _READ_CHUNK)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno in (errno.EIO, errno.EBADF):
                    break
                raise
            if not chunk:
                break
            self._inbuf += chunk
        if self._inbuf:
            self._execute_input()

    def _flush_output(self) -> None:
        if not self._out or self._master is None:
            return
        try:
            n = os.write(self._master, self._out)
        except BlockingIOError:
            return
        except OSError as exc:
            if exc.errno in (errno.EIO, errno.EBADF):
                return
            raise
        del self._out[:n]
        with self._lock:
            self._counts["bytes_sent"] += n

    def _send(self, data: bytes) -> None:
        """Queue outgoing bytes through the line faults."""
        if self.options.corrupt_probability > 0 or self.options.drop_probability > 0:
            arr = np.frombuffer(data, dtype=np.uint8).copy()
            if self.options.corrupt_probability > 0:
                hit = self._rng.random(arr.size) < self.options.corrupt_probability
                bits = self._rng.integers(0, 8, arr.size)
                arr[hit] ^= (1 << bits[hit]).astype(np.uint8)
                corrupted = int(hit.sum())
            else:
                corrupted = 0
            if self.options.drop_probability > 0:
                keep = self._rng.random(arr.size) >= self.options.drop_probability
                dropped = int(arr.size - keep.sum())
                arr = arr[keep]
            else:
                dropped = 0
            data = arr.tobytes()
            with self._lock:
                self._counts["bytes_corrupted"] += corrupted
                self._counts["bytes_dropped"] += dropped
        self._out += data
        if len(self._out) > _MAX_OUT_QUEUE:     # a host that never reads: forget the oldest
            del self._out[:len(self._out) - _MAX_OUT_QUEUE]

    # ------------------------------------------------------------------ commands (spec §2, §3)

    def _execute_input(self) -> None:
        buf = self._inbuf
        while buf:
            op = buf[0]
            if self.mode == OIMode.OFF and op not in (Opcode.START, Opcode.RESET):
                self._ignore(1)         # Off listens only for Start (spec §2)
                continue
            try:
                opcode = Opcode(op)
            except ValueError:
                _log.debug("ignoring unknown opcode %d", op)
                self._ignore(1)
                continue
            need = _data_bytes(opcode, buf)
            if need is None or len(buf) < 1 + need:
                break               # a partial command waits for its data bytes (spec §2)
            data = bytes(buf[1:1 + need])
            del buf[:1 + need]
            mode_before = int(self.mode)
            accepted = self._execute(opcode, data)
            with self._lock:
                self._received.append(ReceivedCommand(self.sim.t_s, int(opcode), data,
                                                      mode_before, accepted))

    def _ignore(self, n: int) -> None:
        del self._inbuf[:n]
        with self._lock:
            self._counts["bytes_ignored"] += n

    def _execute(self, opcode: Opcode, data: bytes) -> bool:
        active = self.mode in (OIMode.SAFE, OIMode.FULL)
        if opcode == Opcode.RESET:
            self._enter_off()
            self._layout = None
            self._send(self.options.banner_text.encode("ascii", "replace"))
        elif opcode == Opcode.START:
            self.mode = OIMode.PASSIVE
            self._wheels_mm_s = (0, 0)
        elif opcode in (Opcode.SAFE, Opcode.CONTROL):
            self.mode = OIMode.SAFE
        elif opcode == Opcode.FULL:
            self.mode = OIMode.FULL
        elif opcode == Opcode.STOP:
            self._enter_off()
        elif opcode == Opcode.DRIVE_DIRECT:
            if not active:
                return False
            right, left = struct.unpack(">hh", data)
            self._wheels_mm_s = (_clip_speed(left), _clip_speed(right))
        elif opcode == Opcode.DRIVE:
            if not active:
                return False
            velocity, radius = struct.unpack(">hh", data)
            self._drive = (velocity, radius)
            self._wheels_mm_s = _drive_to_wheels(velocity, radius)
        elif opcode == Opcode.STREAM:
            layout = self._layout_of(data[1:])
            if layout is None or layout.n > 255:
                return False
            self._layout, self._streaming = layout, True
        elif opcode == Opcode.PAUSE_RESUME_STREAM:
            self._streaming = bool(data[0]) and self._layout is not None
        elif opcode in (Opcode.SENSORS, Opcode.QUERY_LIST):
            layout = self._layout_of(data if opcode == Opcode.SENSORS else data[1:])
            if layout is None:
                return False
            self._refresh_state_values()
            self._send(layout.encode_reply(self._values))
        elif opcode in (Opcode.BAUD, Opcode.POWER, Opcode.SPOT, Opcode.CLEAN, Opcode.MAX,
                        Opcode.SEEK_DOCK):
            if opcode != Opcode.BAUD:
                self.mode = OIMode.PASSIVE
                self._wheels_mm_s = (0, 0)
        return True                 # LEDs, songs, ...: accepted, no effect here

    def _enter_off(self) -> None:
        self.mode = OIMode.OFF
        self._streaming = False
        self._wheels_mm_s = (0, 0)

    @staticmethod
    def _layout_of(ids: bytes) -> PacketLayout | None:
        try:
            return PacketLayout.from_ids(list(ids))
        except (ProtocolError, TypeError) as exc:
            _log.debug("ignoring packet request %s: %s", list(ids), exc)
            return None

    # ------------------------------------------------------------------ one period

    def _refresh_state_values(self) -> tuple[int, int]:
        """Update the mode and command packets; return the (left, right) mm/s in effect."""
        active = self.mode in (OIMode.SAFE, OIMode.FULL)
        left, right = self._wheels_mm_s if active else (0, 0)
        v = self._values
        v[35] = min(max(int(self.mode) + self.options.mode_report_offset, 0), 255)
        v[41], v[42] = right, left
        v[39], v[40] = self._drive
        return left, right

    def _tick(self) -> None:
        t = self.sim.t_s
        at, duration = self.options.passive_at_s, self.options.passive_duration_s
        drop_on = at is not None and at - 1e-9 <= t < at + duration
        first = drop_on and not self._passive_fired
        if first or (drop_on and self.mode == OIMode.SAFE):
            if first:
                self._passive_fired = True
                _log.info("virtual Roomba: wheel drop at %.3f s, OI falls to Passive", t)
            if self.mode != OIMode.OFF:
                self.mode = OIMode.PASSIVE  # wheel drop: Safe reverts, motors stop (spec §2)
            self._wheels_mm_s = (0, 0)
        if (self.options.charger_text_at_s is not None and not self._charger_sent
                and t >= self.options.charger_text_at_s - 1e-9):
            self._charger_sent = True
            self._send(self.options.charger_text.encode("ascii", "replace"))
        if self._texts:
            with self._lock:
                texts, self._texts = self._texts, []
            for text in texts:
                self._send(text.encode("ascii", "replace"))
        with self._lock:
            place, self._place = self._place, None
        if place is not None:
            self.sim.place(place)
        left, right = self._refresh_state_values()
        cmd = (left / 1000.0, right / 1000.0)
        frame = self.sim.step(np.array(cmd))
        k = self.sim.period_index - 1
        v = self._values
        v[7] = (int(frame.bumps[1]) | int(frame.bumps[0]) << 1 | (0b1100 if drop_on else 0))
        v[43], v[44] = int(frame.ticks[0]), int(frame.ticks[1])
        light = [int(x) for x in frame.light_bump]
        for i, signal in enumerate(light):
            v[46 + i] = signal
        v[45] = sum(1 << i for i, s in enumerate(light) if s > self.options.light_bumper_threshold)
        v[8] = (v[45] >> 5) & 1
        v[27] = min(light[5], 1023)
        # the simulated motors' currents [mA, int16] and overcurrent flags (packet 14)
        v[54], v[55] = (max(-32768, min(32767, round(1000.0 * float(a))))
                        for a in frame.motor_current_a)
        v[14] = (0x10 if frame.wheel_overcurrent[0] else 0) | (
            0x08 if frame.wheel_overcurrent[1] else 0)
        v[23] = -(300 + abs(v[54]) + abs(v[55]))
        moving = frame.true_body_m_s is not None and abs(float(frame.true_body_m_s[0])) > 0.01
        v[58] = (k & 1) if moving else 0
        at, duration = self.options.stall_at_s, self.options.stall_duration_s
        stalled = at is not None and at - 1e-9 <= t < at + duration
        sent = False
        if self._streaming and self._layout is not None:
            v[38] = min(len(self._layout.ids), 255)
            if stalled or not bool(frame.valid):
                with self._lock:
                    self._counts["frames_suppressed"] += 1
            else:
                self._send(self._layout.encode_frame(v))
                sent = True
        with self._lock:
            self._applied.append(cmd)
            if sent:
                self._frame_periods.append(k)
                self._counts["frames_sent"] += 1


# ---------------------------------------------------------------------- helpers


def _data_bytes(opcode: Opcode, buf: bytearray) -> int | None:
    """Data bytes of the command at the start of ``buf``; None until its count byte arrived."""
    need = COMMAND_DATA_BYTES[opcode]
    if need is not None:
        return need
    if opcode == Opcode.SONG:                       # [140][song#][N] + 2N (spec §3.4)
        return None if len(buf) < 3 else 2 + 2 * buf[2]
    return None if len(buf) < 2 else 1 + buf[1]     # Stream / Query List: N + N ids


def _clip_speed(mm_s: int) -> int:
    return max(-MAX_WHEEL_SPEED_MM_S, min(MAX_WHEEL_SPEED_MM_S, mm_s))


def _drive_to_wheels(velocity: int, radius: int) -> tuple[int, int]:
    """(left, right) mm/s of Drive (137) (spec §3.1 kinematics, wheel base 235 mm)."""
    v = _clip_speed(velocity)
    if radius in (32767, -32768):
        return v, v
    if radius == -1:
        return v, -v                # spin clockwise
    if radius == 1:
        return -v, v                # spin counter-clockwise
    r = float(max(-2000, min(2000, radius)))
    half = _WHEEL_BASE_MM / 2
    return (_clip_speed(round(v * (r - half) / r)), _clip_speed(round(v * (r + half) / r)))


def _base_values() -> dict[int, int]:
    """Plausible constant values of every single packet (spec §5)."""
    v = dict.fromkeys(PACKETS, 0)
    v.update({22: 15600, 23: -300, 24: 26, 25: 2400, 26: 2696, 28: 2650, 29: 2710,
              30: 2690, 31: 2630, 40: 0})
    return v


def serve(
    *,
    preset: str | RobotParams = "create2",
    seed: int = 0,
    speed: float = 1.0,
    floor: str | None = None,
    print_fn: Callable[[str], object] = print,
    duration_s: float | None = None,
) -> EmulatorStats:
    """Run a virtual Roomba until Ctrl-C, for the command line.

    Prints the device path and how to connect, then waits; on
    :class:`KeyboardInterrupt` (or after ``duration_s`` of wall time, for
    tests) it stops the emulator cleanly.

    Parameters
    ----------
    preset : str or RobotParams
        The robot: parameters, a preset name or a robot file
        (:func:`~drivers.sim.load_robot`).
    seed, speed, floor
        As for :class:`VirtualRoomba` (``floor`` defaults to the robot's).
    print_fn : callable
        Where the messages go (``print`` by default).
    duration_s : float, optional
        Stop after this many wall seconds instead of waiting for Ctrl-C.

    Returns
    -------
    EmulatorStats
        The counters at the end.
    """
    params = load_robot(preset) if isinstance(preset, str) else preset
    floor = params.floor if floor is None else floor
    robot = VirtualRoomba(params, seed=seed, floor=floor, room=Room.cluttered(),
                          initial_pose=Room.CALIBRATION_SPOT,
                          options=VirtualRoombaOptions(speed=speed))
    spots = [Room.OPEN_FLOOR, Room.CALIBRATION_SPOT]

    def carry() -> None:
        # each Enter carries the robot: to open floor, back beside the furniture, ...
        try:
            for i, _ in enumerate(iter(sys.stdin.readline, "")):
                robot.place(spots[i % 2])
                print_fn("carried the robot to " + ("open floor" if i % 2 == 0
                                                     else "beside the furniture"))
        except (OSError, ValueError):       # no readable standard input: nobody to carry it
            return

    robot.start()
    threading.Thread(target=carry, daemon=True, name="virtual-roomba-carry").start()
    try:
        print_fn(f"virtual Roomba ({params.name}, floor {floor_name(floor)}, seed {seed}, "
                 f"speed x{speed:g}) "
                 f"listening on {robot.device_path}")
        print_fn(f"connect with: lti-motion calibrate --port {robot.device_path} --clock-rate "
                 f"{speed:g}, or Roomba({robot.device_path!r}, "
                 f"options=RoombaOptions(clock_rate={speed:g}))")
        print_fn("it stands beside furniture (to rotate); press Enter here to carry it to "
                 "open floor and back; Ctrl-C stops it")
        deadline = None if duration_s is None else time.monotonic() + duration_s
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.05 if deadline is None else max(0.0, min(0.05,
                                                                   deadline - time.monotonic())))
            if not robot.running:
                break
    except KeyboardInterrupt:
        print_fn("stopping the virtual Roomba")
    finally:
        robot.stop()
    stats = robot.stats
    print_fn(f"virtual Roomba stopped: {stats.periods} periods, {stats.frames_sent} frames sent, "
             f"{len(robot.received)} commands received")
    return stats
