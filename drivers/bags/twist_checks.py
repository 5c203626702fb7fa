"""Odometry messages are measurements, not truth: a twist inconsistent with its neighbours.

A robot's ``nav_msgs/Odometry`` twist is what its driver computed, and drivers glitch: a
real TurtleBot3's ``/odom`` holds one yaw rate of -143.6 rad/s, its IMU's yaw wrapping by
2 pi within one 43.7 ms message interval. One such message, integrated, turns the robot by
-52 deg; fitted, it ruins the model. :func:`twist_outliers` finds the messages whose ``v``
or ``w`` stands apart from the running median of their neighbours (a Hampel identifier:
Pearson 2002) by more than :data:`OUTLIER_K` robust standard deviations of the whole
topic's residuals, and never less than :data:`MIN_JUMP` (so that a quantised, almost
noiseless twist keeps its honest steps). :func:`drop_twist_outliers` leaves them out and
says which, by topic, index and time.

References
----------
R. K. Pearson, "Outliers in process modeling and identification", IEEE Transactions on
Control Systems Technology 10(1), 2002, section IV (the Hampel identifier).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import median_filter

from drivers.bags.topics import StampedSeries

__all__ = ["HALF_WINDOW", "MIN_JUMP", "OUTLIER_K", "TwistOutliers", "drop_twist_outliers",
           "twist_outliers"]

#: Neighbours on each side whose median a twist is compared with (a window of 7 messages:
#: up to 3 glitches in a row are found, and a step held for 4 messages is not one).
HALF_WINDOW = 3
#: A twist this many robust standard deviations (1.4826 MAD, Pearson 2002 eq. 21) of the
#: topic's residuals from its running median is inconsistent with its neighbours.
OUTLIER_K = 10.0
#: And never closer to its neighbours' median than this: (v [m/s], w [rad/s]).
MIN_JUMP = (0.5, 2.0)


@dataclass(frozen=True)
class TwistOutliers:
    """The twists left out of an odometry topic.

    Attributes
    ----------
    topic : str
    index : ndarray of int
        Each one's index among the topic's messages.
    t_s : ndarray
        Each one's time [s from the bag's first stamp].
    values : ndarray, shape (m, 2)
        Their ``(v [m/s], w [rad/s])``.
    median : ndarray, shape (m, 2)
        Their neighbours' median ``(v, w)``.
    """

    topic: str
    index: np.ndarray
    t_s: np.ndarray
    values: np.ndarray
    median: np.ndarray

    def __len__(self) -> int:
        return len(self.index)

    def lines(self, *, shown: int = 3, left_out: bool = True) -> list[str]:
        """One line for the count and up to ``shown`` of them, for people (``left_out``:
        whether they were left out or kept, for the monitor's tests to find)."""
        if not len(self):
            return []
        each = "; ".join(f"message {i} at {t:.3f} s (v {v:.3g} m/s, w {w:.3g} rad/s; its "
                         f"neighbours' median v {mv:.3g}, w {mw:.3g})"
                         for i, t, (v, w), (mv, mw) in zip(self.index[:shown], self.t_s[:shown],
                                                          self.values[:shown],
                                                          self.median[:shown], strict=True))
        more = f"; and {len(self) - shown} more" if len(self) > shown else ""
        fate = "left out" if left_out else "kept for the monitor's tests"
        return [f"topic {self.topic}: {len(self)} twist(s) inconsistent with their neighbours "
                f"{fate}: {each}{more}"]


def twist_outliers(values: np.ndarray, *, half_window: int = HALF_WINDOW,
                   k: float = OUTLIER_K,
                   min_jump: tuple[float, float] = MIN_JUMP) -> tuple[np.ndarray, np.ndarray]:
    """Which twists stand apart from their neighbours (the Hampel identifier).

    Parameters
    ----------
    values : ndarray, shape (n, 2)
        ``(v [m/s], w [rad/s])`` per message.
    half_window : int
        Neighbours on each side.
    k : float
        Threshold in robust standard deviations of the residuals ``x - median``
        (1.4826 times their median absolute value over the whole topic).
    min_jump : tuple of 2 float
        The smallest residual flagged, per column.

    Returns
    -------
    flagged : ndarray of bool, shape (n,)
    median : ndarray, shape (n, 2)
        The running median of the ``2 half_window + 1`` messages around each.

    Examples
    --------
    >>> w = np.r_[np.linspace(0.0, 1.0, 20), -143.6, np.linspace(1.0, 0.5, 20)]
    >>> flagged, _ = twist_outliers(np.column_stack([np.full(41, 0.2), w]))
    >>> np.flatnonzero(flagged).tolist()
    [20]
    """
    x = np.asarray(values, float)
    if len(x) < 2 * half_window + 1:
        return np.zeros(len(x), bool), x.copy()
    med = median_filter(x, size=(2 * half_window + 1, 1), mode="nearest")
    resid = np.abs(x - med)
    scale = 1.4826 * np.median(resid, axis=0)               # Pearson 2002, eq. 21
    limit = np.maximum(k * scale, np.asarray(min_jump, float))
    return np.any(resid > limit, axis=1), med


def drop_twist_outliers(series: StampedSeries, start_ns: int
                        ) -> tuple[StampedSeries, TwistOutliers]:
    """An odometry series without its twists inconsistent with their neighbours.

    Parameters
    ----------
    series : StampedSeries
        ``nav_msgs/Odometry`` (columns x, y, theta, v, w).
    start_ns : int
        The bag's first stamp [ns] (the times reported count from it).

    Returns
    -------
    StampedSeries
        The messages kept.
    TwistOutliers
        The ones left out.
    """
    twist = series.values[:, 3:5]
    flagged, med = twist_outliers(twist)
    idx = np.flatnonzero(flagged)
    out = TwistOutliers(series.topic, idx, (series.t_ns[idx] - start_ns) * 1e-9, twist[idx],
                        med[idx])
    if not idx.size:
        return series, out
    keep = ~flagged
    return replace(series, t_ns=series.t_ns[keep], values=series.values[keep],
                   recv_ns=None if series.recv_ns is None else series.recv_ns[keep]), out
