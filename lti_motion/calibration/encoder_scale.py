"""Encoder scale from a rotation in place (paper section III.A, eq. 13).

While the robot turns in place, a range-like sensor (the six light-bump IR
signals) sees the same surroundings once per turn, so its signal is periodic in
encoder ticks, whatever the rotation speed. The period ``D``, measured as the
difference of right and left tick counts over one turn, gives the encoder
scale: each wheel travels ``pi b`` per turn, so ``D = 2 pi b / scale``.

Two period detectors, as the paper suggests:

- ``"autocorr"`` (cluttered room): the channels are resampled onto a uniform
  grid in tick difference, and the normalised autocorrelation of all channels
  together (weighted by their variance) is searched for its first dominant
  peak: the shortest lag whose peak is nearly as high as the highest
  (within ``max(0.01, (1 - highest) / 4)``, so that ``2P`` does not win over
  ``P`` by noise, nor ``P / 2`` over ``P`` in a nearly symmetric room). The lag
  is refined to sub-tick precision by a parabola through the three highest
  samples, then by least squares over the peaks at ``k P`` that have a full
  period of overlap.
- ``"peaks"`` (one obstacle nearby): each channel is a narrow bump once per
  turn; the bumps' centroids are found above a hysteresis threshold and the
  period is the least-squares slope of centroid against turn number.

``"auto"`` runs the autocorrelation, and the peak detector next to it, and
returns the peak detector's result in two cases: every informative channel is
one narrow, isolated bump per turn (above its lower threshold for under 30 %
of the record, with 95 % of its energy in the bumps: the paper's "single
obstacle") and both detectors agree within 2 %; or the autocorrelation is
ambiguous (several nearly equal peaks) and the peak detector matches one of the
longer lags. Otherwise it returns the autocorrelation's result, which uses all
channels and their whole shape (two equal bumps per turn, as in a corridor,
fool a peak detector; in clutter, a dominant bump with smaller features beside
it gave the peak detector a worse tail on synthetic data). When the
autocorrelation finds no peak, ``"auto"`` raises: on synthetic data a peak
detector fallback never rescued a valid record, and it returned wrong periods
(often half a turn) for records of under two turns. Every result must correlate at least
``min_confidence`` across its period, and the record must span two periods.

A recording of under two turns in surroundings that look alike after half a
turn can still alias to a fraction of the period; ``period_range_ticks`` (the
datasheet value +- 30 %) rules most such aliases out.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import fft

from lti_motion.exceptions import (
    CalibrationNonFiniteError,
    CalibrationShapeError,
    NoSignalError,
    NotPeriodicError,
)

__all__ = ["RotationPeriod", "encoder_scale_m_per_tick", "rotation_period_ticks"]

_log = logging.getLogger(__name__)

#: A single narrow bump per turn stays above its lower threshold for less than this
#: fraction of the record.
_NARROW_DUTY = 0.3
#: Relative agreement needed between the two detectors in "auto" mode.
_AGREE = 0.02


@dataclass(frozen=True)
class RotationPeriod:
    """Period of a rotation-in-place recording, in encoder tick difference.

    Attributes
    ----------
    period_ticks : float
        One full turn as ``right - left`` ticks (sub-tick precision) [ticks].
    confidence : float
        Normalised autocorrelation of the channels at ``period_ticks``, in
        ``[0, 1]``; near 1 for a clean periodic signal.
    method : {"autocorr", "peaks"}
        The detector that produced ``period_ticks``.
    n_turns : float
        Turns covered by the recording, ``span / period_ticks``.
    channels : tuple of int
        Indices of the channels that carried information.
    """

    period_ticks: float
    confidence: float
    method: Literal["autocorr", "peaks"]
    n_turns: float
    channels: tuple[int, ...]


def encoder_scale_m_per_tick(period_ticks: float, *, wheel_base_m: float) -> float:
    """Encoder scale from the tick-difference period of one turn in place.

    Parameters
    ----------
    period_ticks : float
        ``right - left`` tick difference over one full turn [ticks].
    wheel_base_m : float
        Distance between the wheels' contact points ``b`` [m].

    Returns
    -------
    float
        ``2 pi b / D`` [m/tick].

    Raises
    ------
    ValueError
        If an argument is not positive and finite.

    Notes
    -----
    Paper eq. 13 as restated in ``docs/architecture.md``: during one turn each wheel
    travels ``pi b`` (half the circumference of the circle of diameter ``b``),
    the right one forwards and the left one backwards, so
    ``D = pi b / s - (-pi b / s) = 2 pi b / s``.

    Examples
    --------
    >>> round(encoder_scale_m_per_tick(3321.0, wheel_base_m=0.235) * 1e3, 4)
    0.4446
    """
    d = float(period_ticks)
    b = float(wheel_base_m)
    if not (np.isfinite(d) and d > 0 and np.isfinite(b) and b > 0):
        raise ValueError(
            f"period_ticks and wheel_base_m must be positive and finite, got {d} and {b}"
        )
    return 2.0 * np.pi * b / d  # paper eq. 13


def _prepare(signals: np.ndarray, tick_diff: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate; orient the tick difference to increase; drop samples that do not advance."""
    sig = np.asarray(signals, dtype=float)
    if sig.ndim == 1:
        sig = sig[:, None]
    td = np.asarray(tick_diff, dtype=float)
    if sig.ndim != 2 or td.ndim != 1 or td.shape[0] != sig.shape[0]:
        raise CalibrationShapeError(
            f"expected signals of shape (n, n_channels) and tick_diff of shape (n,), got "
            f"{np.shape(signals)} and {np.shape(tick_diff)}"
        )
    for name, arr in (("signals", sig), ("tick_diff", td)):
        if not np.all(np.isfinite(arr)):
            where = np.argwhere(~np.isfinite(arr))[0].tolist()
            raise CalibrationNonFiniteError(
                f"{name} holds NaN or infinite values (first at index {where}); drop the "
                "damaged frames or record the rotation again"
            )
    net = td[-1] - td[0] if td.size else 0.0
    if net == 0:
        raise NotPeriodicError(
            "the tick difference does not change: the robot did not rotate; command a "
            "rotation in place of at least two full turns"
        )
    x = td * np.sign(net)  # a clockwise turn counts the same as a counter-clockwise one
    advances = np.concatenate([[True], x[1:] > np.maximum.accumulate(x)[:-1]])
    return sig[advances], x[advances]


def _autocorrelation(z: np.ndarray) -> np.ndarray:
    """Normalised autocorrelation of zero-mean channels z (N, C), all channels together.

    ``rho[k] = sum_c sum_i z[i] z[i+k] / sqrt(E_head(k) E_tail(k))`` with the
    energies of the two overlapping windows, so ``rho[P] = 1`` for an exactly
    periodic signal whatever the record length (Cauchy-Schwarz: ``|rho| <= 1``).
    """
    n = z.shape[0]
    nfft = fft.next_fast_len(2 * n, real=True)
    spec = fft.rfft(z, nfft, axis=0)
    num = fft.irfft((spec * spec.conj()).real.sum(axis=1), nfft)[:n]  # Wiener-Khinchin
    cum = np.concatenate([[0.0], np.cumsum((z * z).sum(axis=1))])
    lags = np.arange(n)
    denom = np.sqrt(cum[n - lags] * (cum[n] - cum[lags]))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(denom > 0, num / np.where(denom > 0, denom, 1.0), 0.0)
    return np.clip(rho, -1.0, 1.0)


def _parabolic_peak(y: np.ndarray, k: int) -> float:
    """Position of the vertex of the parabola through y[k-1], y[k], y[k+1]."""
    a, b, c = y[k - 1], y[k], y[k + 1]
    curv = a - 2.0 * b + c
    return float(k) if curv >= 0 else k + 0.5 * (a - c) / curv


def _autocorr_period(
    rho: np.ndarray, *, lag_range: tuple[float, float], min_confidence: float, use_multiples: bool
) -> tuple[float, list[float]]:
    """Period [grid samples] from the combined autocorrelation, and the lags of all peaks
    nearly as high as the highest (more than one: ambiguous)."""
    n = rho.size
    k_max = int(min(n // 2, np.floor(lag_range[1])))
    crossing = np.flatnonzero(rho[1 : k_max + 1] <= 0.0)
    if crossing.size == 0:
        raise NotPeriodicError(
            f"the autocorrelation does not fall below zero within half the record ({k_max} "
            "grid steps): the signal does not repeat; rotate at least two full turns"
        )
    k_min = max(int(crossing[0]) + 1, int(np.ceil(lag_range[0])), 1)
    ks = np.arange(max(k_min, 1), k_max)
    ks = ks[(ks + 1 < n) & (rho[ks] >= rho[ks - 1]) & (rho[ks] > rho[ks + 1])]
    if ks.size == 0 or rho[ks].max() < min_confidence:
        best = float(rho[ks].max()) if ks.size else float("nan")
        raise NotPeriodicError(
            f"no autocorrelation peak reaches {min_confidence} (best {best:.2f}) between lags "
            f"{k_min} and {k_max} grid steps: the record covers fewer than two turns of any "
            "candidate period, or nothing repeats; rotate at least two full turns near "
            "stationary surroundings"
        )
    strong = ks[rho[ks] >= min_confidence]
    # first dominant peak: the shortest lag nearly as high as the highest (avoids 2P, 3P);
    # "nearly" scales with the shortfall 1 - best that noise and drift cause
    best = float(rho[strong].max())
    close = strong[rho[strong] >= best - max(0.01, 0.25 * (1.0 - best))]
    candidates = [_parabolic_peak(rho, int(k)) for k in close]
    lag1 = candidates[0]
    lags, mults = [lag1], [1.0]
    m = 2
    while use_multiples and (m + 1) * lag1 <= n - 1:  # a full period of overlap at m P
        half_width = max(2, int(0.01 * m * lag1))
        centre = round(m * lag1)
        lo, hi = centre - half_width, centre + half_width + 1
        k = lo + int(np.argmax(rho[lo:hi]))
        if lo < k < hi - 1 and rho[k] >= min_confidence:
            lags.append(_parabolic_peak(rho, k))
            mults.append(float(m))
        m += 1
    lags_arr, mults_arr = np.asarray(lags), np.asarray(mults)
    period = float(mults_arr @ lags_arr / (mults_arr @ mults_arr))  # least squares lag_m = m P
    _log.debug("autocorr peaks at lags %s (multiples %s) -> period %.3f", lags, mults, period)
    return period, candidates


def _bump_centres(s: np.ndarray, min_swing: float) -> tuple[np.ndarray, bool]:
    """Centroids [grid samples] of the complete bumps of one channel, and whether the channel
    is a narrow, isolated bump: above its lower threshold for under 30 % of the record, with
    at least 95 % of its energy (about the median) there, i.e. flat elsewhere."""
    base, top = float(np.median(s)), float(s.max())
    amp = top - base
    if amp < min_swing:
        return np.empty(0), False
    lo_thr, hi_thr = base + 0.25 * amp, base + 0.5 * amp  # hysteresis
    inside = s > lo_thr
    energy = (s - base) ** 2
    isolated = bool(inside.mean() < _NARROW_DUTY and energy[inside].sum() >= 0.95 * energy.sum())
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
    centres = []
    for a, b in zip(edges[0::2], edges[1::2], strict=True):
        if a == 0 or b == s.size or s[a:b].max() < hi_thr:
            continue  # cut by the record's ends, or noise above the lower threshold
        w = s[a:b] - lo_thr
        centres.append(float(np.arange(a, b) @ w / w.sum()))
    return np.asarray(centres), isolated


def _peaks_period(grid: np.ndarray, min_swing: float) -> tuple[float, bool, tuple[int, ...]]:
    """Period [grid samples] from bump centroids; whether all channels used are isolated
    narrow bumps; the channels used (columns of grid)."""
    per_channel = {}
    for c in range(grid.shape[1]):
        centres, isolated = _bump_centres(grid[:, c], min_swing)
        if centres.size < 2:
            continue
        gaps = np.diff(centres)
        med = float(np.median(gaps))
        if np.max(np.abs(gaps - med)) <= 0.05 * med:  # one bump per turn, regularly spaced
            per_channel[c] = (centres, med, isolated)
    if not per_channel:
        raise NotPeriodicError(
            "the peak detector found no channel with one regular bump per turn over at least "
            "two turns; rotate at least two full turns, or use method='autocorr' in a "
            "cluttered room"
        )
    p0 = float(np.median([med for _, med, _ in per_channel.values()]))
    used = {c: v for c, v in per_channel.items() if abs(v[1] - p0) <= 0.05 * p0}
    if not used:
        raise NotPeriodicError(
            "the channels' bump spacings disagree: no common period; rotate at least two full "
            "turns, or use method='autocorr' in a cluttered room"
        )
    num = den = 0.0
    for centres, _, _ in used.values():
        turn = np.round((centres - centres[0]) / p0)
        tc, cc = turn - turn.mean(), centres - centres.mean()
        num += float(tc @ cc)  # pooled least squares: centre = offset_c + turn * P
        den += float(tc @ tc)
    return num / den, all(v[2] for v in used.values()), tuple(sorted(used))


def _lag_range(period_range_ticks: tuple[float, float] | None, step: float
               ) -> tuple[float, float]:
    """The plausible period in grid steps, from ``period_range_ticks`` [ticks]."""
    if period_range_ticks is None:
        return (1.0, np.inf)
    lo, hi = (float(v) for v in period_range_ticks)
    if not 0 < lo < hi:
        raise ValueError(
            f"period_range_ticks must be (low, high) with 0 < low < high, got "
            f"{period_range_ticks}"
        )
    return (lo / step, hi / step)


def _peak_period(grid: np.ndarray, channels: np.ndarray, *, lag_range: tuple[float, float],
                 step: float, period_range_ticks: tuple[float, float] | None,
                 min_swing_counts: float, strict: bool
                 ) -> tuple[float, bool, tuple[int, ...]] | None:
    """The peak detector's period [grid steps], whether its bumps are isolated, and the
    channels it used; None when it finds no period (raises instead when ``strict``)."""
    try:
        p_pk, isolated, used = _peaks_period(grid, min_swing_counts)
        if not lag_range[0] <= p_pk <= lag_range[1]:
            raise NotPeriodicError(
                f"the peak detector's period {p_pk * step:.1f} ticks lies outside "
                f"period_range_ticks {period_range_ticks}; check the range, or rotate "
                "near a single obstacle"
            )
    except NotPeriodicError:
        if strict:
            raise
        return None
    return p_pk, isolated, tuple(int(channels[c]) for c in used)


def _peaks_preferred(p_pk: float, isolated: bool, used: tuple[int, ...],
                     autocorr_channels: tuple[int, ...], candidates: Sequence[float]) -> bool:
    """``method="auto"``: take the peak detector's period over the autocorrelation's."""
    agrees = [abs(p_pk - c) <= _AGREE * c for c in candidates]
    if isolated and used == autocorr_channels and agrees[0]:
        return True         # one narrow isolated bump per turn in every channel
    return any(agrees[1:]) and not agrees[0]   # it resolves an ambiguous autocorrelation


def _interpolated(rho: np.ndarray, lag_steps: float) -> float:
    """The autocorrelation at a fractional lag (linear interpolation), clipped to [0, 1]."""
    k = int(np.clip(np.floor(lag_steps), 0, rho.size - 2))
    frac = lag_steps - k
    return float(np.clip((1 - frac) * rho[k] + frac * rho[k + 1], 0.0, 1.0))


def rotation_period_ticks(
    signals: np.ndarray,
    tick_diff: np.ndarray,
    *,
    method: Literal["auto", "autocorr", "peaks"] = "auto",
    grid_step_ticks: float = 1.0,
    min_confidence: float = 0.5,
    min_swing_counts: float = 16.0,
    period_range_ticks: tuple[float, float] | None = None,
    use_multiples: bool = True,
) -> RotationPeriod:
    """Period, in encoder tick difference, of range signals recorded while rotating in place.

    Parameters
    ----------
    signals : array_like, shape (n,) or (n, n_channels)
        Range-like signals, larger when a surface is nearer (light bumps:
        ``0..4095`` counts); saturated samples are fine.
    tick_diff : array_like, shape (n,)
        Unwrapped ``right - left`` encoder count of each sample [ticks] (unwrap
        each wheel with :func:`lti_motion.recordings.unwrap_ticks` first). It
        increases in a counter-clockwise turn; a clockwise turn is accepted too.
        Samples that do not advance past all earlier ones (standstill at the
        start and end, backlash) are dropped.
    method : {"auto", "autocorr", "peaks"}
        Period detector (module notes).
    grid_step_ticks : float
        Spacing of the uniform resampling grid [ticks].
    min_confidence : float
        Lowest acceptable autocorrelation at the period, for either method.
        Clean recordings of two to three turns score close to 1; a low value
        lets records of under two turns in look-alike surroundings pass with a
        wrong period.
    min_swing_counts : float
        A channel whose 1-99 percentile range is below this sees nothing and is dropped [counts].
    period_range_ticks : (float, float), optional
        Plausible range of the period [ticks], e.g. +-30 % around the
        datasheet value; restricts the autocorrelation search.
    use_multiples : bool
        Refine the autocorrelation period with the peaks at ``k P``.

    Returns
    -------
    RotationPeriod

    Raises
    ------
    CalibrationShapeError
        If the shapes do not match.
    CalibrationNonFiniteError
        If an input is NaN or infinite.
    NoSignalError
        If every channel is flat (nothing within sensor range).
    NotPeriodicError
        If the robot did not rotate, covered fewer than two turns, or no clear
        period exists.

    Notes
    -----
    Paper section III.A: "peak detector" for a single obstacle, autocorrelation
    for unstructured surroundings; the result feeds eq. 13
    (:func:`encoder_scale_m_per_tick`). Parabolic peak interpolation: Smith,
    *Spectral Audio Signal Processing*, 2011, "Quadratic Interpolation of
    Spectral Peaks".

    Examples
    --------
    About 2.4 turns past one bright spot, one turn being 3321 ticks, sampled
    every 13 to 41 ticks:

    >>> d = np.cumsum(np.r_[0, np.tile([13, 41, 27], 100)])  # 301 frames, 8100 ticks
    >>> ir = np.round(3000 * np.exp(-0.5 * (((d + 1000) % 3321 - 1660) / 150) ** 2))
    >>> result = rotation_period_ticks(ir, d)
    >>> round(result.period_ticks, 1), result.method, round(result.n_turns, 2)
    (3321.0, 'peaks', 2.44)
    >>> round(encoder_scale_m_per_tick(result.period_ticks, wheel_base_m=0.235) * 1e3, 4)
    0.4446
    """
    if method not in ("auto", "autocorr", "peaks"):
        raise ValueError(f"method must be 'auto', 'autocorr' or 'peaks', got {method!r}")
    step = float(grid_step_ticks)
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"grid_step_ticks must be positive, got {grid_step_ticks}")
    lag_range = _lag_range(period_range_ticks, step)
    sig, x = _prepare(signals, tick_diff)
    span = float(x[-1] - x[0])
    swing = np.ptp(np.percentile(sig, [1.0, 99.0], axis=0), axis=0)
    channels = np.flatnonzero(swing >= min_swing_counts)
    if channels.size == 0:
        raise NoSignalError(
            f"every channel is flat (1-99 % swing below {min_swing_counts} counts): nothing "
            "was within sensor range; rotate within about 0.3 m of a wall or furniture"
        )
    grid_x = x[0] + step * np.arange(int(np.floor(span / step)) + 1)
    grid = np.column_stack([np.interp(grid_x, x, sig[:, c]) for c in channels])
    rho = _autocorrelation(grid - grid.mean(axis=0))

    chosen: Literal["autocorr", "peaks"] = "peaks" if method == "peaks" else "autocorr"
    if method != "peaks":
        period_steps, candidates = _autocorr_period(
            rho, lag_range=lag_range, min_confidence=min_confidence, use_multiples=use_multiples
        )
        used_channels = tuple(int(c) for c in channels)
    if method != "autocorr":
        found = _peak_period(grid, channels, lag_range=lag_range, step=step,
                             period_range_ticks=period_range_ticks,
                             min_swing_counts=min_swing_counts, strict=method == "peaks")
        if found is not None and (method == "peaks" or _peaks_preferred(*found, used_channels,
                                                                        candidates)):
            chosen = "peaks"
            period_steps, _, used_channels = found
    period_ticks = period_steps * step
    if span < 2.0 * period_ticks:
        raise NotPeriodicError(
            f"the record spans {span:.0f} ticks, fewer than two turns of the detected period "
            f"{period_ticks:.1f} ticks; rotate at least two full turns"
        )
    confidence = _interpolated(rho, period_steps)
    if confidence < min_confidence:
        raise NotPeriodicError(
            f"the signals correlate only {confidence:.2f} (< {min_confidence}) across the "
            f"detected period of {period_ticks:.1f} ticks ({chosen}): no clear repetition; "
            "rotate at least two full turns near stationary surroundings"
        )
    _log.info(
        "rotation period %.2f ticks by %s (confidence %.3f, %.2f turns, channels %s)",
        period_ticks,
        chosen,
        confidence,
        span / period_ticks,
        used_channels,
    )
    return RotationPeriod(
        period_ticks=float(period_ticks),
        confidence=confidence,
        method=chosen,
        n_turns=span / period_ticks,
        channels=used_channels,
    )
