"""Plots of ``lti-motion replay``: trajectories, and position error against time.

Drawn with matplotlib's object-oriented API (no pyplot: no backend is chosen or switched).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from lti_motion.app.plots import save_figure

if TYPE_CHECKING:
    from lti_motion.app.replay_sources import ReplaySource

__all__ = ["plot_errors", "plot_trajectories"]


#: Line styles per estimator, so that overlapping lines stay distinguishable.
_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)), (0, (1, 1)))


def plot_trajectories(path: Path, src: ReplaySource, poses: Mapping[str, np.ndarray]
                      ) -> Path:
    """Every estimate in the plane, with the truth and the landmarks when known; a PNG."""
    fig = Figure(figsize=(7, 6))
    ax = fig.subplots()
    if src.has_truth:
        ax.plot(src.truth[:, 0], src.truth[:, 1], "k-", lw=1.5, label="ground truth")
    for i, (name, p) in enumerate(poses.items()):
        # one dash pattern per estimator: estimators that agree (odometry and an EKF on the
        # same counts) stay visible on top of each other
        ax.plot(p[:, 0], p[:, 1], ls=_STYLES[i % len(_STYLES)], color=f"C{i}", lw=1.1,
                label=src.label(name))
    if src.landmarks is not None and src.sightings:
        xy = np.array([src.landmarks.position(k) for k in src.landmarks.ids])
        ax.plot(xy[:, 0], xy[:, 1], "k^", ms=7, label="landmarks")
    start = next(iter(poses.values()))[0]
    ax.plot(start[0], start[1], "ko", ms=6, mfc="none", label="start")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title=src.name)
    return _finish(fig, ax, path)


def plot_errors(path: Path, src: ReplaySource, poses: Mapping[str, np.ndarray]) -> Path:
    """Position error against the ground truth over time, per estimator; a PNG."""
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    t = src.t_s - src.t_s[0]
    for i, (name, p) in enumerate(poses.items()):
        err = np.hypot(*(p[:, :2] - src.truth[:, :2]).T)        # NaN where no truth
        ax.plot(t, err, ls=_STYLES[i % len(_STYLES)], color=f"C{i}", lw=1.1,
                label=src.label(name))
    ax.set(xlabel="time from the first frame [s]", ylabel="position error [m]",
           title=f"{src.name}: position error against ground truth")
    return _finish(fig, ax, path)


def _finish(fig: Figure, ax: Axes, path: Path) -> Path:
    """Grid, legend, and the figure written to ``path`` (folders made) and closed."""
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, path, dpi=100)
