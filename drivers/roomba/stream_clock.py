"""The stream clock: count a sensor stream's periods from frame arrival times.

A Roomba streams a frame every 15 ms on its own crystal; the host sees frames
arrive late by a varying latency, in bursts (USB serial adapters deliver every
16 ms, G17), and sometimes not at all (a frame lost to corruption). Timing the
frames by arrival turns the jitter into speed noise; counting periods instead
gives the robot's own clock back, gaps included.
"""

from __future__ import annotations

import math

from drivers.roomba.oi import STREAM_PERIOD_S

__all__ = ["StreamClock"]

_ANCHOR_CREEP = 2e-4        # the arrival line may rise 200 ppm: crystal drift (StreamClock)


# ---------------------------------------------------------------------- stream clock


class StreamClock:
    """Count stream periods from frame arrival times, tolerating bursts and lost frames.

    The robot sends a frame every ``period_s``; frame ``k`` leaves at
    ``T0 + k * period_s`` and reaches the host ``L >= 0`` later. The clock
    keeps the *arrival line* ``A = min(h_j - k_j * period_s)`` over the frames
    seen (``h`` = host arrival time times ``clock_rate``; the line may creep up
    by 2e-4 s per s to follow crystal drift) and, for the last frame of each
    freshly received chunk, its lateness ``late = h - A - k * period_s`` under
    the hypothesis that no frame was lost. Each frame lost on the way
    (corruption, a stall) adds one period to ``late``; bursts (FTDI latency
    timer, G17) add at most ``latency_tolerance_s``. So:

    * ``late <= latency_tolerance_s``: no frame lost (and ``late`` updates
      ``L_typ``, a running mean of the lateness, weight 1/32);
    * otherwise ``skip = round((late - L_typ) / period_s)``, but at least
      ``ceil((late - tol) / period_s)``, the fewest lost frames consistent
      with a latency of at most the tolerance.

    The rule is exact when latencies vary by less than ``min(tol, P/2)``.
    With a tolerance above one period (an FTDI adapter at its default 16 ms
    latency timer) a single lost frame can hide in a burst; it is then found
    at a later fresh frame, since every later lateness is a period larger.
    A latency beyond the tolerance is taken for lost frames (timestamps then
    run ahead by that many periods). Chunks that waited in the OS buffer (the
    host was late reading) carry no timing and advance ``k`` by one per frame.

    Parameters
    ----------
    period_s : float
        Stream period [s] (15 ms, spec §4.1).
    clock_rate : float
        Robot seconds per host second (1.0 for a robot; the emulator's
        ``speed`` for a faster-than-real-time virtual Roomba).
    latency_tolerance_s : float
        Largest arrival latency [robot s] not taken for a lost frame;
        ``math.inf`` never takes lateness for loss (frames are counted), for a
        link that loses nothing, e.g. a pseudo-terminal to an emulator whose
        own schedule slips on a loaded host.

    Examples
    --------
    Frames 0, 1, 2 on time, frame 3 lost, frame 4 on time:

    >>> c = StreamClock(latency_tolerance_s=0.005)
    >>> c.start(0.0)
    >>> [c.assign(1, t, fresh=True)[0] for t in (0.015, 0.0301, 0.0601)]
    [1, 2, 4]
    >>> c.periods_skipped
    1
    """

    def __init__(self, *, period_s: float = STREAM_PERIOD_S, clock_rate: float = 1.0,
                 latency_tolerance_s: float = 0.02) -> None:
        for name, v in (("period_s", period_s), ("clock_rate", clock_rate)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite positive number, got {v!r}")
        if not latency_tolerance_s >= 0:
            raise ValueError(f"latency_tolerance_s must be >= 0 s (math.inf: never), got "
                             f"{latency_tolerance_s!r}")
        self.period_s = float(period_s)
        self.clock_rate = float(clock_rate)
        self.latency_tolerance_s = float(latency_tolerance_s)
        self.k = 0
        self.periods_skipped = 0
        self._anchor = 0.0
        self._h_prev = 0.0
        self._typical = 0.0

    def start(self, host_s: float) -> None:
        """Frame 0 arrived at host time ``host_s`` [s]."""
        h = host_s * self.clock_rate
        self.k, self.periods_skipped = 0, 0
        self._anchor = self._h_prev = h
        self._typical = 0.0

    def assign(self, n_frames: int, host_s: float, *, fresh: bool) -> list[int]:
        """Period indices of ``n_frames`` frames completed by one chunk read at ``host_s``.

        Parameters
        ----------
        n_frames : int
            Frames decoded from the chunk, >= 0.
        host_s : float
            Host time the chunk was read [s] (e.g. :func:`time.monotonic`).
        fresh : bool
            Whether the host was waiting when the chunk arrived, so that
            ``host_s`` is its arrival time; otherwise no gap is inferred.

        Returns
        -------
        list of int
            Increasing period indices, one per frame.
        """
        if n_frames <= 0:
            return []
        h = host_s * self.clock_rate
        self._anchor += _ANCHOR_CREEP * max(0.0, h - self._h_prev)
        self._h_prev = max(self._h_prev, h)
        skip = 0
        if fresh:
            late = h - self._anchor - (self.k + n_frames) * self.period_s
            if late > self.latency_tolerance_s:
                lo = math.ceil((late - self.latency_tolerance_s) / self.period_s - 1e-9)
                skip = max(lo, round((late - self._typical) / self.period_s))
            else:
                self._typical += (late - self._typical) / 32.0
        first = self.k + 1 + skip
        ks = list(range(first, first + n_frames))
        self.k = ks[-1]
        self.periods_skipped += skip
        self._anchor = min(self._anchor, h - self.k * self.period_s)
        return ks
