"""The model EKF's options as one frozen object.

:class:`EKFOptions` holds how a :class:`~fusion.ekf.ModelEKF` filters: its
noise (slip, scale errors, the encoder floor, landmarks, a gyro), its gate, its
judgement of encoder spans and of divergence, its counters' width and how many
records it keeps. Where the filter starts (pose, model state, counts, time) and
what it knows (the landmark map, an encoder scale for a model without one) are
the filter's own keyword arguments. :class:`~fusion.monitoring.MonitoredFilter`
forwards the same object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from fusion.ekf.encoder_counts import check_counter_bits
from fusion.exceptions import FilterOptionError
from fusion.noise import GyroNoise, LandmarkNoise, ScaleErrors, SlipNoise

__all__ = ["EKFOptions"]


@dataclass(frozen=True, kw_only=True)
class EKFOptions:
    """How a :class:`~fusion.ekf.ModelEKF` filters (its defaults: ``EKFOptions()``).

    Attributes
    ----------
    slip : SlipNoise, optional
        White ground-versus-encoder speed noise (:mod:`fusion.ekf.functions`;
        default ``SlipNoise()``).
    scales : ScaleErrors, optional
        Prior, drift and plausibility bound of the scale-error states
        ``(k_v, k_w, kappa)`` (:mod:`fusion.ekf.resets`; default ``ScaleErrors()``).
    encoder_std : tuple of 2 float
        Floor of the encoder reading noise ``(v [m/s], w [rad/s])``.
    gate_probability : float or None
        Chi-square gate of every update (0.999: a good reading is rejected
        once in a thousand); ``None`` fuses everything.
    landmark_noise : LandmarkNoise, optional
        Range-bearing noise of sightings without a covariance of their own
        (default 2% of range, 1 degree).
    unknown_landmarks : {"count", "raise"}
        What a sighting of an id not in the map does.
    history : int
        How many update records the filter keeps (0: none).
    reanchor_periods : int
        When an encoder reading is still outside the gate after spanning
        this many periods, the span is judged
        (:func:`~fusion.ekf.span_verdict`): a wheel flat while
        predicted to turn (stuck) renews the count reference and gives up the
        motion since; both wheels counting steadily means the model misses a
        transient (a start from rest), and the counts are fused anyway
        (``"forced"``); a frame whose increment jumps (a spike) waits for the
        next frame; a jump earlier in the span (a spike, a frozen wheel that
        resumed) also renews the reference. Fewer periods than this, and the
        next reading still sums from the last fused counts, which recovers
        single-frame spikes.
    max_periods : int
        Most periods one encoder reading may span after gated or lost ones
        (500 periods of 15 ms at 0.5 m/s stay far from the 16-bit counter's
        half range).
    max_jump_ticks : float
        Largest change of a frame's tick increment from the last frame's that
        still counts as steady, for the judgement above [ticks].
    diverged_after : int or None
        Absolute readings (landmark sightings, pose fixes) outside the gate in
        a row, of at least two landmarks, after which the filter is judged
        diverged: its scale states are reset and its pose covariance widened
        (:mod:`fusion.ekf.resets`); ``None`` never judges.
    counter_bits : int
        Width of the encoder counters [bits], 8..64 (16: the Open Interface's);
        counts are differenced as the shortest signed step on their
        ``2**counter_bits`` ring (63, 64: they never wrap;
        :class:`~fusion.ekf.EncoderCounts`).
    gyro : GyroNoise, optional
        A yaw-rate gyro to fuse with :meth:`ModelEKF.update_gyro
        <fusion.ekf.ModelEKF.update_gyro>` (noise, bias prior, walk and bound):
        adds its bias and the period's yaw slip to the state
        (:mod:`fusion.ekf.gyro`); default none.

    Raises
    ------
    FilterOptionError
        For a span option that is not positive, a negative ``history`` or a counter
        width outside 8..64
        (the noise, the gate and the divergence count are checked by the filter
        that uses them).

    Examples
    --------
    >>> EKFOptions(counter_bits=24, history=0).max_periods
    500
    >>> EKFOptions(max_periods=0)
    Traceback (most recent call last):
    ...
    fusion.exceptions.FilterOptionError: max_periods must be a positive int, got 0
    """

    slip: SlipNoise | None = None
    scales: ScaleErrors | None = None
    encoder_std: tuple[float, float] = (1e-5, 1e-4)
    gate_probability: float | None = 0.999
    landmark_noise: LandmarkNoise | None = None
    unknown_landmarks: Literal["count", "raise"] = "count"
    history: int = 10_000
    reanchor_periods: int = 16
    max_periods: int = 500
    max_jump_ticks: float = 10.0
    diverged_after: int | None = 20
    counter_bits: int = 16
    gyro: GyroNoise | None = None

    def __post_init__(self) -> None:
        for name in ("reanchor_periods", "max_periods"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise FilterOptionError(f"{name} must be a positive int, got {value!r}")
        if not self.max_jump_ticks > 0:
            raise FilterOptionError(f"max_jump_ticks must be positive, got "
                                    f"{self.max_jump_ticks!r}")
        if not (isinstance(self.history, int) and self.history >= 0):
            raise FilterOptionError(f"history must be an int of 0 or more (the update records "
                                    f"kept; 0 keeps none), got {self.history!r}")
        check_counter_bits(self.counter_bits)
