"""The virtual Roomba's options as one frozen object: its pace and its line's faults.

:class:`VirtualRoombaOptions` holds how a :class:`~drivers.roomba.VirtualRoomba`
behaves on its pseudo-terminal: how fast it runs against the wall clock, the
faults of its serial line (corrupted and dropped bytes, a silent stream, a fall
to Passive, banners and charger text) and its firmware quirks. The simulated
world behind it (the robot, the seed, the floor, the room, the start pose and
the simulator's own faults) stays the emulator's own keyword arguments. Section
numbers ("spec §6.3", "G21") refer to ``../shared/spec/roomba_oi.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["DEFAULT_BANNER", "DEFAULT_CHARGER_TEXT", "VirtualRoombaOptions"]

#: Boot banner printed after Reset (7), assembled from real banners quoted in spec §6.3.
DEFAULT_BANNER = ("bl-start\r\nSTR730\r\n2007-05-14-1715-L   \r\nRoomba by iRobot!\r\n"
                  "r3_robot/tags/release-3.2.6:4975 CLEAN\r\nbattery-current-zero 253\r\n")
#: Unsolicited charging-status text of a robot on its charger (spec §6.3, G21).
DEFAULT_CHARGER_TEXT = "bat:   min 0  sec 12  mV 15605  mA 1203  deg-C 26  mAH 2100  state 5\r\n"


@dataclass(frozen=True, kw_only=True)
class VirtualRoombaOptions:
    """How a :class:`~drivers.roomba.VirtualRoomba` runs and what its line does wrong
    (defaults: ``VirtualRoombaOptions()``, real time on a clean line).

    Attributes
    ----------
    speed : float
        Wall-clock speed-up, robot seconds per wall second: 1.0 is real time;
        20.0 sends a frame every 0.75 ms of wall time. Give the driver
        ``RoombaOptions(clock_rate=speed)``.
    corrupt_probability : float
        Probability that each outgoing byte gets one random bit flipped, in [0, 1].
    drop_probability : float
        Probability that each outgoing byte is dropped, in [0, 1].
    stall_at_s : float, optional
        Robot time [s] at which the stream falls silent (the robot keeps running
        and keeps reading commands).
    stall_duration_s : float
        How long it stays silent [s], > 0.
    passive_at_s : float, optional
        Robot time [s] of a wheel drop that forces the OI to Passive and stops
        the motors (spec §2); the wheel-drop bits of packet 7 stay set for
        ``passive_duration_s``, during which Safe falls back to Passive again
        (Full holds, its safeties being off). Applied in Full too, so a test
        of the driver's fallback does not depend on the mode.
    passive_duration_s : float
        See ``passive_at_s`` [s], > 0.
    banner_text : str
        ASCII printed after Reset (7) (spec §6.3).
    charger_text_at_s : float, optional
        Robot time [s] at which unsolicited charger text is sent (G21).
    charger_text : str
        That text.
    light_bumper_threshold : int
        Signal above which a light-bumper bit of packet 45 is set.
    mode_report_offset : int
        Added to the reported OI mode, to emulate the off-by-one firmware (G8).
    max_catch_up_periods : int
        Lateness, in periods, beyond which the schedule is re-anchored.

    Raises
    ------
    ValueError
        For a speed, probability or duration out of range.

    Examples
    --------
    >>> VirtualRoombaOptions(speed=10.0, corrupt_probability=0.01).drop_probability
    0.0
    >>> VirtualRoombaOptions(drop_probability=1.5)
    Traceback (most recent call last):
    ...
    ValueError: drop_probability must be in [0, 1], got 1.5
    """

    speed: float = 1.0
    corrupt_probability: float = 0.0
    drop_probability: float = 0.0
    stall_at_s: float | None = None
    stall_duration_s: float = 0.5
    passive_at_s: float | None = None
    passive_duration_s: float = 1.0
    banner_text: str = DEFAULT_BANNER
    charger_text_at_s: float | None = None
    charger_text: str = DEFAULT_CHARGER_TEXT
    light_bumper_threshold: int = 100
    mode_report_offset: int = 0
    max_catch_up_periods: int = 100

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"speed must be a finite positive factor, got {self.speed!r}")
        for name in ("corrupt_probability", "drop_probability"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {p!r}")
        for name in ("stall_duration_s", "passive_duration_s"):
            v = getattr(self, name)
            if not v > 0:
                raise ValueError(f"{name} must be > 0 s, got {v!r}")
