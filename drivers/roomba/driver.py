"""The iRobot Roomba / Create 2 over its Open Interface, with pyserial.

:class:`Roomba` opens the serial port, wakes the robot, enters Safe or Full
mode, requests a sensor stream and turns every valid stream frame into a
:class:`~lti_motion.recordings.SensorFrame`. Its :meth:`Roomba.step` has the
signature of :meth:`drivers.sim.Simulator.step`, so calibration manoeuvres run
unchanged on the simulator or the robot, e.g. through :func:`lti_motion.calibration.drive`.

Protocol bytes come from :mod:`drivers.roomba.oi`; this module owns only the port,
the clocks and the failure handling. Section numbers ("spec §4.1") and gotchas ("G17")
are those listed in :mod:`drivers.roomba.oi`.

Failure handling, in short:

* a port that does not exist or is busy raises :class:`PortError` naming it;
* corrupt bytes, ASCII banners and charger text are skipped by the stream
  parser and counted (G10, G21), never fatal;
* no valid frame for ``stall_periods`` periods raises
  :class:`StreamStalledError` after commanding the wheels to stop
  (``RoombaOptions(reconnect=True)`` first re-requests the stream once);
* packet 35 reporting Off or Passive while Safe/Full is expected (wheel drop,
  cliff, charger; spec §2, G7) raises :class:`PassiveModeError` after
  commanding the wheels to stop (``RoombaOptions(reassert_mode=True)`` re-sends
  Safe/Full once per episode, with a warning, instead);
* :meth:`Roomba.close` always stops the wheels, pauses the stream and sends
  Start then Stop (G18), also when the ``with`` body raises, and never raises
  for a dead port.

Examples
--------
Drive a virtual Roomba on a pseudo-terminal through the real driver:

>>> from drivers.roomba.virtual import VirtualRoomba
>>> from lti_motion.calibration.manoeuvres import drive
>>> from drivers.roomba.virtual import VirtualRoombaOptions
>>> options = RoombaOptions(clock_rate=5.0, stall_periods=100)
>>> vr = VirtualRoomba(seed=3, options=VirtualRoombaOptions(speed=5.0))
>>> with vr, Roomba(vr.device_path, options=options) as robot:
...     log = drive(robot, np.full((20, 2), 0.1))
>>> len(log), log.dt_s
(20, 0.015)
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import os
import stat
import struct
import sys
import time
from collections import deque
from collections.abc import Iterator, Sequence

import numpy as np
import serial

from drivers.exceptions import PassiveModeError, PortError, ProtocolError, StreamStalledError
from drivers.roomba.oi import (
    STREAM_PERIOD_S,
    OIMode,
    PacketLayout,
    StreamFrame,
    StreamParser,
    check_stream_bandwidth,
    drive_direct,
    full,
    pause_resume_stream,
    safe,
    start,
    stop,
    stream,
)
from drivers.roomba.roomba_options import SERIAL_LATENCY_TOLERANCE_S, RoombaOptions
from drivers.roomba.stream_clock import StreamClock
from lti_motion.recordings.frames import N_LIGHT_BUMPS, SensorFrame

__all__ = ["LinkCounters", "Roomba", "RoombaOptions", "StreamClock", "is_pseudo_terminal"]

_log = logging.getLogger(__name__)

_LIGHT_IDS = (46, 47, 48, 49, 50, 51)
# ---------------------------------------------------------------------- counters


@dataclasses.dataclass(frozen=True)
class LinkCounters:
    """Health of the serial link of a :class:`Roomba` (a snapshot).

    Attributes
    ----------
    frames : int
        Valid stream frames decoded (the one that confirmed the stream
        included, and any still queued for :meth:`Roomba.read_frame`).
    checksum_failures : int
        Candidate frames with a bad checksum (G10).
    bytes_dropped : int
        Bytes skipped by the parser: ASCII banners, charger text, noise, and
        the header byte of each rejected candidate (spec §4.1).
    bad_length, bad_id : int
        Candidates rejected for a wrong ``n`` byte or an id out of place.
    stalls : int
        Times no valid frame arrived within ``stall_periods`` periods.
    periods_skipped : int
        Stream periods the stream clock inferred as lost (see :class:`StreamClock`).
    invalid_mode_reports : int
        Frames whose packet 35 was outside 0..3 after the offset (G8).
    mode_reasserts : int
        Times Safe/Full was re-sent after a fall to Passive (``reassert_mode``).
    """

    frames: int = 0
    checksum_failures: int = 0
    bytes_dropped: int = 0
    bad_length: int = 0
    bad_id: int = 0
    stalls: int = 0
    periods_skipped: int = 0
    invalid_mode_reports: int = 0
    mode_reasserts: int = 0


# ---------------------------------------------------------------------- the driver


#: Linux's device majors of pseudo-terminal slaves (Unix98 ptys, ``/dev/pts/N``: 136-143).
_PTY_MAJORS = range(136, 144)


def is_pseudo_terminal(port: str) -> bool:
    """Whether ``port`` is a pseudo-terminal (a :class:`~drivers.roomba.VirtualRoomba`'s
    ``/dev/pts/N``), not a serial device: by its device major on Linux, else by its path.

    >>> is_pseudo_terminal("/dev/ttyUSB0")
    False
    """
    try:
        st = os.stat(port)
    except OSError:
        return False
    if stat.S_ISCHR(st.st_mode) and sys.platform.startswith("linux"):
        return os.major(st.st_rdev) in _PTY_MAJORS
    return os.path.realpath(port).startswith(("/dev/pts/", "/dev/ttys"))


class Roomba:
    """A Roomba 600 / Create 2 on a serial port, streaming sensor frames.

    Parameters
    ----------
    port : str
        Serial device, e.g. ``"/dev/ttyUSB0"`` or a virtual Roomba's ``device_path``.
    options : RoombaOptions, optional
        How the driver talks to the robot (:class:`~drivers.roomba.RoombaOptions`:
        baud rate, OI mode, streamed packets, timeouts, the stall window,
        reconnect and mode re-assertion, the clocks, the nominal geometry);
        default ``RoombaOptions()``.

    Attributes
    ----------
    port : str
        The serial device.
    options : RoombaOptions
        The driver's options.
    dt_s : float
        The stream period, 0.015 s.
    read_timeout_s : float
        The pyserial read timeout in use [s] (``options.read_timeout_s`` or
        derived from the stall window).
    latency_tolerance_s : float
        The stream clock's latency tolerance in use [robot s]:
        ``options.latency_tolerance_s``, or by the link:
        :data:`~drivers.roomba.SERIAL_LATENCY_TOLERANCE_S` on a serial device,
        ``math.inf`` (frames counted) on a pseudo-terminal (:func:`is_pseudo_terminal`).

    Raises
    ------
    UnknownPacketError
        If ``options.stream_ids`` holds an unknown packet id (before any port is opened).
    StreamBandwidthError
        If the frame does not fit one period at ``baud`` (spec §4.1, G9).
    ValueError
        For options that are not a :class:`RoombaOptions`, or lack the encoder packets.

    Notes
    -----
    :meth:`step` sends a Drive Direct and returns the next frame in arrival
    order. Frames are never skipped to catch up: a host that falls behind gets
    the buffered frames in order, and its commands act later than the frame it
    answers; with ``cmd_source="requested"`` each frame says which command the
    robot actually applied.
    """

    def __init__(self, port: str, *, options: RoombaOptions | None = None) -> None:
        opts = RoombaOptions() if options is None else options
        if not isinstance(opts, RoombaOptions):
            raise ValueError(f"options must be a RoombaOptions, got {type(opts).__name__}")
        self.port = str(port)
        self.options = opts
        # on a pseudo-terminal lateness is what a busy host delays, in wall time and
        # without bound: the frames are counted (late, not lost)
        self.latency_tolerance_s = (
            opts.latency_tolerance_s if opts.latency_tolerance_s is not None
            else math.inf if is_pseudo_terminal(self.port) else SERIAL_LATENCY_TOLERANCE_S)
        self._index_fields(opts.stream_ids, cmd_source=opts.cmd_source)
        self.dt_s = STREAM_PERIOD_S
        self._set_timeouts(opts.read_timeout_s)
        self._init_link_state()

    def _index_fields(self, stream_ids: Sequence[int], *, cmd_source: str) -> None:
        """The stream layout, and where the packets the driver reads sit in a frame."""
        self.layout = PacketLayout.from_ids(stream_ids, what="Stream (148)")
        self.layout.require_streamable()
        check_stream_bandwidth(self.layout.ids, baud_bps=self.options.baud_bps)
        fields = self.layout.field_ids
        for pid in (43, 44):
            if pid not in fields:
                raise ProtocolError(f"stream_ids {list(self.layout.ids)} lack encoder packet "
                                    f"{pid}; the driver needs 43 and 44 (spec §7)")
        self._i_ticks = (fields.index(43), fields.index(44))
        self._i_light = (tuple(fields.index(p) for p in _LIGHT_IDS)
                         if all(p in fields for p in _LIGHT_IDS) else None)
        self._i_bumps = fields.index(7) if 7 in fields else None
        self._i_mode = fields.index(35) if 35 in fields else None
        self._i_req = ((fields.index(42), fields.index(41))
                       if 41 in fields and 42 in fields and cmd_source == "requested" else None)

    def _set_timeouts(self, read_timeout_s: float | None) -> None:
        """The stall window [wall s] and the pyserial read timeout derived from it."""
        opts = self.options
        self._stall_window_s = max(opts.stall_periods * STREAM_PERIOD_S / opts.clock_rate,
                                   float(opts.stall_floor_s))
        self.read_timeout_s = (min(0.05, max(5e-4, self._stall_window_s / 4))
                               if read_timeout_s is None else float(read_timeout_s))

    def _init_link_state(self) -> None:
        """A closed port, an empty parser, queue and stream clock, zero counters."""
        self._ser: serial.Serial | None = None
        self._parser = StreamParser(self.layout.ids)
        self._clock = StreamClock(clock_rate=self.options.clock_rate,
                                  latency_tolerance_s=self.latency_tolerance_s)
        self._pending: deque[tuple[StreamFrame, int, float]] = deque()
        self._sent_m_s = (0.0, 0.0)
        self._stalls = 0
        self._invalid_modes = 0
        self._reasserts = 0
        self._reassert_left: int | None = None
        self.t0_monotonic_s = 0.0
        self.first_frame: SensorFrame | None = None

    # ------------------------------------------------------------------ properties

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._ser is not None

    def log_meta(self) -> dict:
        """What :func:`lti_motion.calibration.drive` records about this link in a log's meta."""
        opts = self.options
        return {"port": self.port, "baud": opts.baud_bps, "mode": opts.mode, "clock": opts.clock,
                "latency_tolerance_s": (None if math.isinf(self.latency_tolerance_s)
                                        else self.latency_tolerance_s),    # robot s
                "counters": dataclasses.asdict(self.counters)}

    @property
    def m_per_tick(self) -> float:
        """Nominal wheel travel per encoder tick, ``pi D / ticks_per_rev`` [m] (spec §7.1)."""
        return math.pi * self.options.wheel_diameter_m / self.options.ticks_per_rev

    @property
    def counters(self) -> LinkCounters:
        """A snapshot of the link counters."""
        p = self._parser
        return LinkCounters(frames=p.frames_ok, checksum_failures=p.checksum_failures,
                            bytes_dropped=p.bytes_dropped, bad_length=p.bad_length,
                            bad_id=p.bad_id, stalls=self._stalls,
                            periods_skipped=self._clock.periods_skipped,
                            invalid_mode_reports=self._invalid_modes,
                            mode_reasserts=self._reasserts)

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return (f"Roomba({self.port!r}, baud_bps={self.options.baud_bps}, "
                f"mode={self.options.mode!r}, {state})")

    # ------------------------------------------------------------------ open / close

    def __enter__(self) -> Roomba:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> Roomba:
        """Open the port, wake the robot, enter the mode and start the stream (idempotent).

        Sends Start (128), then Safe (131) or Full (132), then Stream (148)
        with ``stream_ids``, and waits for the first valid frame in the
        expected mode (frame 0 of the stream clock, kept in :attr:`first_frame`).

        Returns
        -------
        Roomba
            ``self``.

        Raises
        ------
        PortError
            If the port does not exist, is busy (opened with ``exclusive=True``)
            or fails.
        StreamStalledError
            If no valid frame arrives within ``open_timeout_s``.
        PassiveModeError
            If frames arrive but report Off/Passive (robot on its charger or
            with a wheel dropped in Safe mode).
        """
        if self._ser is not None:
            return self
        try:
            ser = serial.Serial(self.port, baudrate=self.options.baud_bps,
                                timeout=self.read_timeout_s,
                                write_timeout=self.options.write_timeout_s, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise PortError(f"cannot open serial port {self.port!r}: {exc}. Check that the "
                            "device exists and that no other program (or another Roomba "
                            "object) holds it") from exc
        self._ser = ser
        try:
            if self.options.wake:
                self.wake()
            self._reset_input(ser)
            self._write(start())
            self._settle()
            self._write(safe() if self.options.mode == "safe" else full())
            self._settle()
            self._reset_input(ser)
            self._pending.clear()
            self._write(stream(self.layout.ids))
            self._await_first_frame(ser)
        except BaseException:
            self.close()
            raise
        _log.info("Roomba on %s: %s mode, streaming %s", self.port, self.options.mode,
                  list(self.layout.ids))
        return self

    def close(self) -> None:
        """Stop the wheels, pause the stream, send Start then Stop, close the port.

        Idempotent, and never raises because the port went away: failures are
        logged. Start then Stop leaves the robot in Off mode, where it can
        charge (spec §1.4, G18).
        """
        ser, self._ser = self._ser, None
        if ser is None:
            return
        self._sent_m_s = (0.0, 0.0)
        for what, payload in (("stop the wheels", drive_direct(0, 0)),
                              ("pause the stream", pause_resume_stream(resume=False)),
                              ("send Start", start()), ("send Stop", stop())):
            try:
                ser.write(payload)
            except Exception as exc:    # a dead port must not hide the caller's error
                _log.warning("Roomba on %s: could not %s while closing: %s", self.port, what, exc)
                break
        try:
            ser.close()
        except Exception as exc:
            _log.warning("Roomba on %s: error closing the port: %s", self.port, exc)
        self._pending.clear()

    def wake(self) -> bool:
        """Pulse RTS low-high, which drives BRC on the official cable (spec §1.4).

        Best effort: a pseudo-terminal or adapter without RTS refuses the
        ioctl (spec §8.3), which is logged at debug level.

        Returns
        -------
        bool
            Whether the pulse was sent.
        """
        ser = self._require_open()
        try:
            ser.rts = True
            time.sleep(0.1)
            ser.rts = False
        except (OSError, ValueError, serial.SerialException) as exc:
            _log.debug("Roomba on %s: no RTS wake pulse (%s)", self.port, exc)
            return False
        return True

    # ------------------------------------------------------------------ commands and frames

    def send_wheels(self, left_m_s: float, right_m_s: float) -> None:
        """Send Drive Direct (145) with the wheel speeds in m/s (spec §3.2).

        Parameters
        ----------
        left_m_s, right_m_s : float
            Wheel speeds [m/s], each in [-0.5, 0.5]; rounded to whole mm/s.

        Raises
        ------
        ProtocolError
            If a speed is NaN, infinite or out of range; nothing is sent.
        PortError
            If the port is closed or the write fails.
        """
        payload = drive_direct(float(left_m_s) * 1000.0, float(right_m_s) * 1000.0)
        self._write(payload)
        right, left = struct.unpack(">hh", payload[1:])
        self._sent_m_s = (left / 1000.0, right / 1000.0)

    def step(self, cmd_m_s: np.ndarray | Sequence[float]) -> SensorFrame:
        """Send one wheel command and return the next frame, like ``Simulator.step``.

        Parameters
        ----------
        cmd_m_s : array_like, shape (2,)
            Wheel speeds (left, right) [m/s], each in [-0.5, 0.5].

        Returns
        -------
        SensorFrame
            The next frame in arrival order (see :meth:`read_frame`).

        Raises
        ------
        ValueError
            If ``cmd_m_s`` does not have shape (2,) (nothing is sent).
        ProtocolError
            If a speed is out of range (nothing is sent).
        StreamStalledError, PassiveModeError, PortError
            As for :meth:`read_frame`.
        """
        cmd = np.asarray(cmd_m_s, dtype=float)
        if cmd.shape != (2,):
            raise ValueError(f"step() expects a (left, right) command of shape (2,), "
                             f"got shape {cmd.shape}")
        self.send_wheels(cmd[0], cmd[1])
        return self.read_frame()

    def catch_up(self) -> int:
        """Drop the frames that wait to be read; how many were dropped.

        For a host that fell behind while the robot stood still (before a manoeuvre:
        loading a library, a person at a prompt): :meth:`step` returns frames oldest
        first, so its commands would answer frames seconds old, and a manoeuvre would be
        logged from before it began. The stream clock still counts the dropped frames'
        periods. Never called by the driver itself: during a drive no frame is dropped.
        """
        ser = self._require_open()
        dropped = len(self._pending)
        self._pending.clear()
        # read until a frame comes while the host waits for it: what arrives then is new
        # (a virtual Roomba queues what the pseudo-terminal cannot hold and refills it as
        # it is read, so an empty buffer alone does not mean the backlog is gone)
        deadline = time.monotonic() + max(2.0, self._stall_window_s)
        while time.monotonic() < deadline:
            chunk, host_s, fresh = self._receive(ser)
            n = self._take(chunk, host_s, False)     # counted: a backlog carries no timing
            dropped += len(self._pending)
            self._pending.clear()
            if fresh and n <= 2:
                break
        if dropped:
            _log.info("Roomba on %s: dropped %d waiting frames to catch up", self.port, dropped)
        return dropped

    def read_frame(self) -> SensorFrame:
        """The next valid stream frame, oldest first.

        Returns
        -------
        SensorFrame
            Ticks from packets 43/44, light bumps 46-51, bumps from packet 7
            (bit 1 left, bit 0 right), ``oi_mode`` from 35, ``cmd_m_s`` per
            ``cmd_source``, ``t_s`` per ``clock``.

        Raises
        ------
        StreamStalledError
            If no valid frame arrives within ``stall_periods`` periods (after
            one stream re-request with ``reconnect=True``); the wheels are
            commanded to stop first.
        PassiveModeError
            If the frame reports Off/Passive while Safe/Full is expected (spec
            §2, G7); the wheels are commanded to stop first.
        PortError
            If the port is closed or fails.
        """
        ser = self._require_open()
        deadline = time.monotonic() + self._stall_window_s
        reconnected = False
        while not self._pending:
            if time.monotonic() >= deadline and not self._take_waiting(ser):
                self._stalls += 1
                if self.options.reconnect and not reconnected:
                    reconnected = True
                    _log.warning("Roomba on %s: no frame for %d periods; re-requesting the "
                                 "stream", self.port, self.options.stall_periods)
                    self._write(stream(self.layout.ids))
                    opts = self.options
                    deadline = time.monotonic() + max(opts.reconnect_timeout_s / opts.clock_rate,
                                                      opts.stall_floor_s)
                    continue
                self._stop_wheels_quietly()
                raise self._stall_error(reconnected=reconnected)
            self._take(*self._receive(ser))
        sf, k, host_s = self._pending.popleft()
        frame = self._to_frame(sf, k, host_s)
        self._check_mode(frame)
        return frame

    def discard_buffered(self) -> int:
        """Drop the frames that waited while nobody read; the next frame is a fresh one.

        The stream flows while the host waits at a prompt or computes; those
        frames queue in the OS (and in a virtual Roomba's output) and
        :meth:`read_frame` would return them first, so the next commands would
        answer stale frames and act that many periods late. Reads until a read
        has to wait for data (at most one stall window); the dropped frames
        still advance the stream clock, so the next timestamps show the gap.

        Returns
        -------
        int
            Frames dropped.

        Raises
        ------
        PortError
            If the port is closed or fails.
        """
        ser = self._require_open()
        dropped = len(self._pending)
        self._pending.clear()
        deadline = time.monotonic() + self._stall_window_s
        while time.monotonic() < deadline:
            chunk, host_s, fresh = self._receive(ser)
            if fresh:                               # the backlog is read: keep what is new
                self._take(chunk, host_s, fresh)
                break
            dropped += self._take(chunk, host_s, False)
            self._pending.clear()
        if dropped:
            _log.info("Roomba on %s: dropped %d frames that waited unread", self.port, dropped)
        return dropped

    def frames(self) -> Iterator[SensorFrame]:
        """Yield :meth:`read_frame` until an exception (or the caller) stops it."""
        while True:
            yield self.read_frame()

    # ------------------------------------------------------------------ internals

    def _require_open(self) -> serial.Serial:
        if self._ser is None:
            raise PortError(f"Roomba on {self.port} is not open; use open() or a with block")
        return self._ser

    def _write(self, data: bytes) -> None:
        ser = self._require_open()
        try:
            ser.write(data)
        except (serial.SerialException, OSError) as exc:
            raise PortError(f"write to {self.port} failed: {exc}") from exc

    def _reset_input(self, ser: serial.Serial) -> None:
        try:
            ser.reset_input_buffer()
        except (serial.SerialException, OSError) as exc:
            raise PortError(f"cannot flush {self.port}: {exc}") from exc

    def _settle(self) -> None:
        if self.options.settle_s > 0:
            time.sleep(self.options.settle_s / self.options.clock_rate)

    def _receive(self, ser: serial.Serial) -> tuple[bytes, float, bool]:
        """One read: (bytes, host time, whether the host was waiting for them)."""
        try:
            waiting = ser.in_waiting
            if waiting:
                chunk, fresh = ser.read(waiting), False
            else:
                chunk, fresh = ser.read(1), True        # waits up to read_timeout_s
                more = ser.in_waiting if chunk else 0
                if more:
                    chunk += ser.read(more)
        except (serial.SerialException, OSError) as exc:
            raise PortError(f"read from {self.port} failed: {exc}") from exc
        return chunk, time.monotonic(), fresh

    def _take(self, chunk: bytes, host_s: float, fresh: bool) -> int:
        """Parse a chunk and queue its frames with their stream periods; how many."""
        frames = self._parser.feed(chunk) if chunk else []
        if frames:
            ks = self._clock.assign(len(frames), host_s, fresh=fresh)
            self._pending.extend((f, k, host_s) for f, k in zip(frames, ks, strict=True))
        return len(frames)

    def _take_waiting(self, ser: serial.Serial) -> bool:
        """At a deadline: queue what already waits in the OS buffer, without waiting.

        A host descheduled past the deadline finds the frames that arrived
        meanwhile here instead of calling it a stall.
        """
        try:
            waiting = ser.in_waiting
            chunk = ser.read(waiting) if waiting else b""
        except (serial.SerialException, OSError) as exc:
            raise PortError(f"read from {self.port} failed: {exc}") from exc
        return self._take(chunk, time.monotonic(), False) > 0

    def _stall_error(self, *, reconnected: bool) -> StreamStalledError:
        c = self.counters
        return StreamStalledError(
            f"no valid stream frame from {self.port} ({self.options.baud_bps} baud) for "
            f"{self._stall_window_s:.3g} s of wall time (at least {self.options.stall_periods} "
            f"periods{', after one re-request' if reconnected else ''}); "
            f"{c.frames} frames so far, {c.checksum_failures} checksum failures. The "
            "wheels were commanded to stop. Check the cable, that the robot is on and "
            "awake, and the baud rate (spec §1.3, G3, G15)")

    def _await_first_frame(self, ser: serial.Serial) -> None:
        deadline = time.monotonic() + self.options.open_timeout_s
        wrong_modes: list[int] = []
        while time.monotonic() < deadline:
            chunk, host_s, _ = self._receive(ser)
            frames = self._parser.feed(chunk) if chunk else []
            for i, sf in enumerate(frames):
                mode = self._mode_of(sf)
                if mode is not None and mode < OIMode.SAFE:
                    wrong_modes.append(mode)
                    continue
                self._clock.start(host_s)
                self.t0_monotonic_s = host_s
                self.first_frame = self._to_frame(sf, 0, host_s)
                rest = frames[i + 1:]
                ks = self._clock.assign(len(rest), host_s, fresh=False)
                self._pending.extend((f, k, host_s) for f, k in zip(rest, ks, strict=True))
                return
        if wrong_modes:
            raise PassiveModeError(
                f"Roomba on {self.port} stays in OI mode {wrong_modes[-1]} "
                f"({OIMode(wrong_modes[-1]).name}) after the "
                f"{self.options.mode.capitalize()} command "
                f"({len(wrong_modes)} frames): is it on the charger or lifted (wheel drop)? "
                "(spec §2, G7)")
        c = self.counters
        raise StreamStalledError(
            f"no valid stream frame from {self.port} at {self.options.baud_bps} baud within "
            f"{self.options.open_timeout_s:g} s of requesting the stream ({c.bytes_dropped} bytes "
            "skipped). Check that the robot is switched on and awake (press Clean), the cable "
            "(TX/RX, ground), and the baud rate: 115200 for a Create 2 / Roomba 500-600, "
            "57600 for a Create 1 (spec §1.3, G3, G15)")

    def _mode_of(self, sf: StreamFrame) -> int | None:
        if self._i_mode is None:
            return None
        mode = sf.values[self._i_mode] - self.options.mode_report_offset
        if not 0 <= mode <= 3:
            self._invalid_modes += 1
            _log.debug("Roomba on %s: invalid OI mode report %d (G8)", self.port,
                       sf.values[self._i_mode])
            return None
        return mode

    def _to_frame(self, sf: StreamFrame, k: int, host_s: float) -> SensorFrame:
        v = sf.values
        if self._i_light is None:
            light = np.zeros(N_LIGHT_BUMPS, dtype=np.int64)
        else:
            light = np.array([v[i] for i in self._i_light], dtype=np.int64)
        b = 0 if self._i_bumps is None else v[self._i_bumps]
        if self._i_req is None:
            cmd = self._sent_m_s
        else:
            cmd = (v[self._i_req[0]] / 1000.0, v[self._i_req[1]] / 1000.0)
        t_s = (k * STREAM_PERIOD_S if self.options.clock == "stream"
               else (host_s - self.t0_monotonic_s) * self.options.clock_rate)
        fields = self.layout.field_ids
        current = (np.array((v[fields.index(54)], v[fields.index(55)]), dtype=float) / 1000.0
                   if 54 in fields and 55 in fields else None)
        over = v[fields.index(14)] if 14 in fields else None      # bit4 left, bit3 right
        return SensorFrame(
            t_s=t_s,
            ticks=np.array((v[self._i_ticks[0]], v[self._i_ticks[1]]), dtype=np.int64),
            light_bump=light,
            bumps=np.array((b & 2, b & 1), dtype=bool),
            cmd_m_s=np.array(cmd, dtype=float),
            oi_mode=self._mode_of(sf),
            motor_current_a=current,
            wheel_overcurrent=(None if over is None
                               else np.array((over & 0x10, over & 0x08), dtype=bool)),
        )

    def _check_mode(self, frame: SensorFrame) -> None:
        mode = frame.oi_mode
        if mode is None or mode >= OIMode.SAFE:
            self._reassert_left = None
            return
        self._stop_wheels_quietly()
        if self.options.reassert_mode:
            if self._reassert_left is None:
                self._reassert_left = self.options.stall_periods
                self._reasserts += 1
                _log.warning("Roomba on %s: OI fell to mode %d (%s); re-sending %s as "
                             "RoombaOptions(reassert_mode=True) asks", self.port, mode,
                             OIMode(mode).name, self.options.mode.capitalize())
                self._write(safe() if self.options.mode == "safe" else full())
                return
            if self._reassert_left > 0:
                self._reassert_left -= 1
                return
        raise PassiveModeError(
            f"Roomba on {self.port} reports OI mode {mode} ({OIMode(mode).name}) while the "
            f"driver expects {self.options.mode.upper()}"
            f"{' even after re-sending it' if self.options.reassert_mode else ''}: the robot "
            "fell back (wheel drop, cliff, charger; spec §2, G7). The wheels were commanded to "
            "stop. Lift the cause, then reopen, or pass RoombaOptions(reassert_mode=True)")

    def _stop_wheels_quietly(self) -> None:
        with contextlib.suppress(PortError):
            self._write(drive_direct(0, 0))
        self._sent_m_s = (0.0, 0.0)


# ---------------------------------------------------------------------- manoeuvres
