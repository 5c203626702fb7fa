"""The serial Roomba driver's options as one frozen object.

:class:`RoombaOptions` holds how a :class:`~drivers.roomba.Roomba` talks to the
robot: the link (baud rate, timeouts, the stream's packets), its failure
handling (stall window, reconnect, mode re-assertion), its clocks and the
nominal geometry behind :attr:`Roomba.m_per_tick <drivers.roomba.Roomba.m_per_tick>`.
Section numbers ("spec §4.1", "G17") refer to ``../shared/spec/roomba_oi.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from drivers.roomba.oi import DEFAULT_BAUD_BPS, DEFAULT_STREAM_IDS

__all__ = ["SERIAL_LATENCY_TOLERANCE_S", "RoombaOptions"]

#: The stream clock's latency tolerance on a serial device [s]: an FTDI adapter delivers
#: every 16 ms (its latency timer, G17), and a few milliseconds of host jitter on top.
SERIAL_LATENCY_TOLERANCE_S = 0.02


@dataclass(frozen=True, kw_only=True)
class RoombaOptions:
    """How a :class:`~drivers.roomba.Roomba` drives its serial link (defaults:
    ``RoombaOptions()``, a Create 2 on the official cable).

    Attributes
    ----------
    baud_bps : int
        Bits per second (115200 for the Create 2 and Roomba 500/600; spec §1.3, G15).
    mode : {"safe", "full"}
        OI mode to drive in (spec §2). Safe keeps the cliff, wheel-drop and
        charger safeties, which fall back to Passive (see ``reassert_mode``).
    stream_ids : tuple of int
        Packets to stream; must contain the encoders 43 and 44. Bumps 7,
        light bumps 46-51, mode 35 and requested velocities 41/42 are used
        when present (zeros / ``None`` / the sent command otherwise). Never
        distance/angle 19/20 (spec §6.1). Checked against the packet table and
        the baud rate when the driver is made.
    read_timeout_s : float, optional
        pyserial read timeout [s]: how often a waiting read re-checks its
        deadline. Default: a quarter of the stall window, at most 0.05 s.
    write_timeout_s : float
        pyserial write timeout [s].
    open_timeout_s : float
        Wall time [s] allowed for the first valid frame after opening.
    stall_periods : int
        A read that sees no valid frame for this many stream periods (robot
        time, i.e. ``stall_periods * 0.015 / clock_rate`` wall seconds), and
        for at least ``stall_floor_s`` of wall time, raises
        :class:`~drivers.exceptions.StreamStalledError`.
    stall_floor_s : float
        Shortest stall window in wall time [s], >= 0 (default 0.3 s). A loaded
        host, or a virtual Roomba sharing its cores, leaves gaps of tens of
        milliseconds between frames; at a high ``clock_rate`` the window of
        ``stall_periods`` alone shrinks to a few milliseconds (7.5 ms at 10x)
        and such a gap would stop the drive. On a robot (``clock_rate=1``) the
        window is ``max(0.075, 0.3)`` s by default.
    reconnect : bool
        On a stall, re-send the stream request once and wait up to
        ``reconnect_timeout_s`` (robot time) before raising.
    reconnect_timeout_s : float
        See ``reconnect`` (robot time [s], and at least ``stall_floor_s`` of wall time).
    reassert_mode : bool
        On a fall to Passive, re-send Safe/Full once (logged as a warning and
        counted) instead of raising; raises if the mode is still wrong
        ``stall_periods`` frames later. Off by default: never silent.
    clock : {"stream", "host"}
        Frame timestamps: ``"stream"`` gives ``k * 0.015`` s with ``k`` the
        stream period counted by :class:`~drivers.roomba.StreamClock` (frame 0 is
        the one that confirmed the stream); ``"host"`` gives the host arrival
        time ``(time.monotonic() - t0) * clock_rate``. Both start at 0 at frame
        0, whose host time is :attr:`Roomba.t0_monotonic_s
        <drivers.roomba.Roomba.t0_monotonic_s>`.
    clock_rate : float
        Robot seconds per wall second: 1.0 for a robot, the ``speed`` of a
        faster-than-real-time virtual Roomba. Scales every robot-time window.
    latency_tolerance_s : float or None
        Largest arrival latency [robot s] the stream clock does not take for a
        lost frame (covers FTDI bursts, G17); ``math.inf``: frames are counted,
        lateness is never taken for loss. ``None`` (the default) chooses by the
        link: :data:`SERIAL_LATENCY_TOLERANCE_S` (0.02 s) on a serial device;
        ``math.inf`` on a pseudo-terminal (:class:`~drivers.roomba.VirtualRoomba`):
        the emulator never skips a frame for lateness, so there lateness is what a
        busy host delays, in wall time and without bound (at ``clock_rate`` 10,
        0.02 robot s was 2 ms of wall time; 0.02 s of wall time was still exceeded
        hundreds of times a drive with the machine loaded), and frames that arrive
        late are late, not lost. The emulator's own stalls and lost frames (its
        faults) then leave no gap in the timestamps: give a tolerance to find them.
    mode_report_offset : int
        Subtracted from packet 35 before use: 1 for Roombas that report the
        mode off by one (G8). Values still outside 0..3 are counted and ignored.
    cmd_source : {"requested", "sent"}
        Where a frame's ``cmd_m_s`` comes from: packets 42/41 (the command the
        robot applied in that period) when streamed, or the last command the
        driver sent.
    wake : bool
        Pulse RTS (wired to BRC on the official cable) on open; best effort,
        a pseudo-terminal refuses it (spec §1.4, §8.3, G3).
    settle_s : float
        Pause after Start and after the mode command [robot s].
    wheel_diameter_m, ticks_per_rev, wheel_base_m : float
        Nominal geometry (spec §7.1), for :attr:`Roomba.m_per_tick
        <drivers.roomba.Roomba.m_per_tick>`; the driver itself reports raw ticks.

    Raises
    ------
    ValueError
        For an option out of its range (the message names it and its value).

    Examples
    --------
    >>> RoombaOptions(clock_rate=5.0).stream_ids == tuple(DEFAULT_STREAM_IDS)
    True
    >>> RoombaOptions(stall_periods=0)
    Traceback (most recent call last):
    ...
    ValueError: stall_periods must be an int >= 1, got 0
    """

    baud_bps: int = DEFAULT_BAUD_BPS
    mode: Literal["safe", "full"] = "safe"
    stream_ids: Sequence[int] = tuple(DEFAULT_STREAM_IDS)
    read_timeout_s: float | None = None
    write_timeout_s: float = 0.5
    open_timeout_s: float = 1.0
    stall_periods: int = 5
    stall_floor_s: float = 0.3
    reconnect: bool = False
    reconnect_timeout_s: float = 1.0
    reassert_mode: bool = False
    clock: Literal["stream", "host"] = "stream"
    clock_rate: float = 1.0
    latency_tolerance_s: float | None = None
    mode_report_offset: int = 0
    cmd_source: Literal["requested", "sent"] = "requested"
    wake: bool = True
    settle_s: float = 0.05
    wheel_diameter_m: float = 0.072
    ticks_per_rev: float = 508.8
    wheel_base_m: float = 0.235

    def __post_init__(self) -> None:
        object.__setattr__(self, "stream_ids", tuple(self.stream_ids))
        if self.mode not in ("safe", "full"):
            raise ValueError(f"mode must be 'safe' or 'full', got {self.mode!r}")
        if self.clock not in ("stream", "host"):
            raise ValueError(f"clock must be 'stream' or 'host', got {self.clock!r}")
        if self.cmd_source not in ("requested", "sent"):
            raise ValueError(f"cmd_source must be 'requested' or 'sent', got "
                             f"{self.cmd_source!r}")
        stall = self.stall_periods
        if isinstance(stall, bool) or not (isinstance(stall, int) and stall >= 1):
            raise ValueError(f"stall_periods must be an int >= 1, got {stall!r}")
        for name in ("clock_rate", "write_timeout_s", "open_timeout_s", "reconnect_timeout_s",
                     "wheel_diameter_m", "ticks_per_rev", "wheel_base_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite positive number, got {v!r}")
        for name in ("settle_s", "stall_floor_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        v = self.read_timeout_s
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"read_timeout_s must be a finite positive number, got {v!r}")
        v = self.latency_tolerance_s
        if v is not None and not v >= 0:
            raise ValueError(f"latency_tolerance_s must be >= 0 s (math.inf: never), got {v!r}")
