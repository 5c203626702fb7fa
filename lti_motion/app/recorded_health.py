"""The health gate of ``calibrate --log`` and ``calibrate --bag``: a held-out time span,
the README's healthy fit, orders and delays at their range's edge, and ``--dt``.

A model fitted on a recorded drive is measured on a time span it never saw: the last
:data:`HELD_OUT_FRACTION` of the drive, or the window ``--start-s`` / ``--duration-s``
names (:func:`held_out_span`); that span neither fits the model nor chooses its order
and delay (:func:`lti_motion.calibration.calibrate_recording`, ``held_out_s``). A model
whose held-out free-run fit of ``v`` or ``w`` is below
:data:`~lti_motion.app.calibrate_run.HEALTHY_FIT_PERCENT`, or whose order or delay is
still at the top of its widened search range, is not written unless
``--accept-unhealthy`` (:func:`recorded_problems`). A ``--dt`` far from the
recording's own period is refused before any fit (:func:`check_period`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lti_motion.app.calibrate_run import HEALTHY_FIT_PERCENT
from lti_motion.calibration import OfflineCalibration

__all__ = [
    "HELD_OUT_FRACTION",
    "MAX_PERIOD_MISMATCH",
    "MIN_HELD_OUT_S",
    "HeldOut",
    "check_period",
    "held_out_line",
    "held_out_span",
    "recorded_problems",
    "refuse_unhealthy",
]

#: The part of the drive held out by default: its last 20% [fraction of its duration].
HELD_OUT_FRACTION = 0.2
#: The shortest held-out span the fit is measured on [s].
MIN_HELD_OUT_S = 5.0
#: A ``--dt`` further than this from the recording's own period is refused [fraction].
MAX_PERIOD_MISMATCH = 0.1


@dataclass(frozen=True)
class HeldOut:
    """The held-out window the command line names [s from the drive's start]:
    ``--start-s`` and ``--duration-s`` (``None``: the last 20% of the drive)."""

    start_s: float | None = None
    duration_s: float | None = None


def held_out_span(held: HeldOut, duration_s: float) -> tuple[float, float]:
    """The held-out span ``(start, end)`` [s from the drive's start]: ``--start-s`` for
    ``--duration-s`` (either alone: to the end, or from the start of the last 20%), else the
    last :data:`HELD_OUT_FRACTION` of the drive.

    Raises
    ------
    ValueError
        A span outside the drive, or shorter than :data:`MIN_HELD_OUT_S`, in one line
        naming the options and the drive's length.
    """
    start, length = held.start_s, held.duration_s
    if start is None and length is None:
        return ((1.0 - HELD_OUT_FRACTION) * duration_s, duration_s)
    if start is None:
        start = max(0.0, duration_s - length)
    end = duration_s if length is None else start + length
    if not (0.0 <= start < duration_s and end > start):
        raise ValueError(f"--start-s {start:g} / --duration-s "
                         f"{'to the end' if length is None else f'{length:g}'} holds out no "
                         f"part of the {duration_s:.1f} s drive: give a window inside it")
    end = min(end, duration_s)
    if end - start < MIN_HELD_OUT_S:
        raise ValueError(f"the held-out span {start:.1f}-{end:.1f} s is shorter than "
                         f"{MIN_HELD_OUT_S:g} s, too short to measure the model's fit on: give "
                         "a longer --duration-s or an earlier --start-s")
    return (start, end)


def check_period(dt_s: float | None, own_period_s: float, what: str) -> None:
    """Refuse a ``--dt`` further than :data:`MAX_PERIOD_MISMATCH` from the recording's own
    period (the median interval of its wheel stamps, ``what`` says whose).

    Raises
    ------
    ValueError
        One line with both periods and what to give.
    """
    if dt_s is None or not (math.isfinite(own_period_s) and own_period_s > 0):
        return
    if abs(dt_s / own_period_s - 1.0) > MAX_PERIOD_MISMATCH:
        raise ValueError(f"--dt {dt_s * 1e3:g} ms is far from the recording's own period "
                         f"{own_period_s * 1e3:.4g} ms ({what}): a model of another period "
                         f"would not describe this robot; leave --dt out or give one within "
                         f"{MAX_PERIOD_MISMATCH:.0%} of it")


def held_out_line(cal: OfflineCalibration) -> str:
    """The held-out fit, the span it was measured on, and the order search."""
    m = cal.model
    line = (f"ARX order {m.orders['na']}, delay {m.orders['delay']}; free-run fit on the "
            f"validation tail that chose them: v {cal.fit_percent[0]:.1f} %, "
            f"w {cal.fit_percent[1]:.1f} %")
    if cal.held_out_fit_percent is not None and cal.held_out_s is not None:
        a, b = cal.held_out_s
        line += (f"; on the held-out {a:.1f}-{b:.1f} s (never fitted): "
                 f"v {cal.held_out_fit_percent[0]:.1f} %, w {cal.held_out_fit_percent[1]:.1f} %")
    return line


def recorded_problems(cal: OfflineCalibration, *,
                      healthy_fit_percent: float = HEALTHY_FIT_PERCENT) -> list[str]:
    """Why a model fitted on a recording is unhealthy; empty when it is healthy.

    The held-out span's free-run fit of ``v`` and ``w`` (the validation tail's when no
    span was held out) against ``healthy_fit_percent``; an order or delay at the top of
    its widened search range.
    """
    fit = cal.held_out_fit_percent if cal.held_out_fit_percent is not None else cal.fit_percent
    where = "held-out" if cal.held_out_fit_percent is not None else "validation"
    problems = [f"{where} fit of {name} {value:.1f}% is below the healthy "
                f"{healthy_fit_percent:g}%"
                for name, value in zip("vw", np.asarray(fit), strict=True)
                if not value >= healthy_fit_percent]
    problems += [f"{edge} even after widening the search" for edge in cal.at_edge]
    return problems


def refuse_unhealthy(problems: list[str], *, accept_unhealthy: bool,
                     print_fn=print) -> None:
    """Raise the one-line refusal of an unhealthy model, or say it is saved as asked.

    Raises
    ------
    ValueError
        With the problems, unless ``accept_unhealthy``.
    """
    if not problems:
        return
    if not accept_unhealthy:
        raise ValueError(f"the model is unhealthy and was not saved: {'; '.join(problems)} "
                         "(the README's healthy bar for calibrate; "
                         "docs/guide_calibrate_real_robot.md, section 4): check the drive's "
                         "excitation and clocks above, or save it anyway with --accept-unhealthy")
    print_fn(f"saving an unhealthy model as --accept-unhealthy asks: {'; '.join(problems)}")
