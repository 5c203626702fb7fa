"""The encoder counts a filter holds between frames: the ring, the reference and the last frame.

:class:`EncoderCounts` is the one place the model EKF and the monitored filter
keep raw wheel counts. Counts are cumulative and wrap on a ``2**counter_bits``
ring, so the filter remembers

- the *reference*: the counts of the last fused (or anchoring) frame; the next
  reading is differenced against it, so gated, NaN or lost readings lose no
  motion (:mod:`fusion.ekf.functions`, *Gated readings*), and the periods
  predicted since;
- the *last frame*: the counts of the latest reading and its step from the one
  before (``step``: the frame delta, computed once, in :meth:`observe`), for the
  single-frame jump test of a span (:func:`~fusion.ekf.span_verdict`) and for
  the monitor's per-frame count changes;
- the largest frame jump since the reference (``span_jump_ticks``).

Every difference is the shortest signed step on the counters' ring,
``((d + half) mod 2**bits) - half`` (:func:`lti_motion.recordings.tick_deltas`,
Open Interface spec section 7.2), in scalar integer arithmetic: it runs at
every reading. From 63 bits the counters never wrap and the step is the plain
difference.
"""

from __future__ import annotations

import numpy as np

from fusion.exceptions import FilterOptionError

__all__ = ["EncoderCounts", "check_counter_bits"]


def check_counter_bits(counter_bits: int) -> int:
    """``counter_bits`` if an int in 8..64, else a :class:`~fusion.exceptions.FilterOptionError`."""
    if not (isinstance(counter_bits, int) and 8 <= counter_bits <= 64):
        raise FilterOptionError(f"counter_bits must be an int in 8..64 (16 for a Roomba), "
                                f"got {counter_bits!r}")
    return counter_bits


class EncoderCounts:
    """Raw wheel counts held between frames, on a ``2**counter_bits`` ring.

    Parameters
    ----------
    counter_bits : int
        Width of the encoder counters [bits], 8..64 (16: the Open Interface's).
    initial_ticks : tuple of 2 int, optional
        Counts ``(left, right)`` [ticks] at the start: the reference and the
        last frame (otherwise the first :meth:`observe` has no step).

    Attributes
    ----------
    counter_bits : int
        Width of the counters [bits].
    reference : tuple of 2 int or None
        Counts of the last fused (or anchoring) frame [ticks]; None before one.
    periods : int
        Periods predicted since the reference.
    frame : tuple of 2 int or None
        Counts of the latest reading [ticks]; None before one.
    step : tuple of 2 int or None
        Signed step of the latest reading from the one before [ticks] (the frame
        delta); None while fewer than two readings were observed.
    span_jump_ticks : float
        Largest frame jump (:meth:`observe`) since the reference [ticks].

    Raises
    ------
    FilterOptionError
        If ``counter_bits`` is not an int in 8..64.

    Examples
    --------
    >>> counts = EncoderCounts(initial_ticks=(65530, 100))
    >>> counts.observe(0, 106), counts.step        # 6 ticks each, the left counter wrapped
    (0.0, (6, 6))
    >>> counts.observe(9, 112), counts.span()      # the increment changed by 3 ticks
    (3.0, (15, 12))
    """

    __slots__ = ("_half", "_modulus", "counter_bits", "frame", "periods", "reference",
                 "span_jump_ticks", "step")

    def __init__(self, *, counter_bits: int = 16,
                 initial_ticks: tuple[int, int] | None = None) -> None:
        self.counter_bits = check_counter_bits(counter_bits)
        # shortest signed step on the counters' ring: (d + half) % modulus - half
        self._half = 0 if counter_bits >= 63 else 1 << (counter_bits - 1)
        self._modulus = 0 if counter_bits >= 63 else 1 << counter_bits
        self.reference: tuple[int, int] | None = None
        self.periods = 0
        self.frame: tuple[int, int] | None = None
        self.step: tuple[int, int] | None = None
        self.span_jump_ticks = 0.0
        if initial_ticks is not None:
            self.frame = self.reference = (int(initial_ticks[0]), int(initial_ticks[1]))

    def ring_step(self, d_left: int, d_right: int) -> tuple[int, int]:
        """Both wheels' count differences as the shortest signed steps on the ring [ticks].

        :func:`lti_motion.recordings.tick_deltas` in scalar arithmetic.
        """
        if not self._modulus:
            return d_left, d_right
        half, modulus = self._half, self._modulus
        return (d_left + half) % modulus - half, (d_right + half) % modulus - half

    def observe(self, left: int, right: int) -> float:
        """Take a reading's counts as the last frame; return its jump [ticks].

        The jump is ``max | |d_k| - |d_(k-1)| |`` over the wheels: how much this
        frame's increment ``d_k`` (:attr:`step`) differs from the last frame's (a
        wheel's speed changes by about a tick per period); 0 until two steps
        are known.

        Parameters
        ----------
        left, right : int
            The reading's raw counts [ticks].

        Returns
        -------
        float
            The frame jump [ticks].
        """
        last, previous = self.frame, self.step
        if last is None:                    # no frame before: no step (the reading anchors)
            self.frame, self.step = (left, right), None
            return 0.0
        step = self.ring_step(left - last[0], right - last[1])
        jump = 0.0
        if previous is not None:
            jump = float(max(abs(abs(step[0]) - abs(previous[0])),
                             abs(abs(step[1]) - abs(previous[1]))))
        self.frame, self.step = (left, right), step
        return jump

    def advance(self) -> None:
        """One more period predicted since the reference."""
        self.periods += 1

    def rebase(self) -> None:
        """The last frame becomes the reference (a fused or judged reading): no periods,
        no jump since."""
        self.reference = self.frame
        self.periods = 0
        self.span_jump_ticks = 0.0

    def hold(self, jump_ticks: float) -> None:
        """A reading not fused: the reference stays, and the span keeps the frame's jump
        [ticks] if it is the largest since the reference."""
        self.span_jump_ticks = max(self.span_jump_ticks, jump_ticks)

    def span(self) -> tuple[int, int]:
        """Signed counts ``(left, right)`` from the reference to the last frame [ticks]."""
        (l0, r0), (l1, r1) = self.reference, self.frame
        return self.ring_step(l1 - l0, r1 - r0)

    def pair(self) -> np.ndarray:
        """The reference's and the last frame's counts, rows ``(left, right)``, (2, 2) int64."""
        return np.array((self.reference, self.frame), dtype=np.int64)

    @property
    def accumulating(self) -> bool:
        """Whether a reference is held and periods were predicted since it (the speed state
        then sums them; :mod:`fusion.ekf.functions`, *Gated readings*)."""
        return self.reference is not None and self.periods > 0
