"""Plots of a calibration: step responses, order selection, the calibration sequence.

Application layer (matplotlib): used by ``lti-motion calibrate`` and ``lti-motion demo``.
Figures are drawn with matplotlib's object-oriented API (:class:`~matplotlib.figure.Figure`
and ``savefig``): no pyplot, so no backend is chosen or switched, and nothing global.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from lti_motion.calibration import Calibration, speeds_from_log
from lti_motion.model import MotionModel
from lti_motion.persistence import atomic_write

__all__ = [
    "plot_calibration",
    "plot_order_selection",
    "plot_sequence",
    "plot_step_responses",
    "save_figure",
]


def save_figure(fig: Figure, path: Path, *, dpi: int = 110, tight: bool = False) -> Path:
    """Write ``fig`` as a PNG at ``path``, whole or not at all
    (:func:`~lti_motion.persistence.atomic_write`: Ctrl-C or a full disk leaves no
    truncated image); ``tight`` crops to the drawn content (a legend outside the axes)."""
    with atomic_write(path) as f:
        fig.savefig(f, dpi=dpi, format="png", **({"bbox_inches": "tight"} if tight else {}))
    return path


def plot_step_responses(fir: MotionModel, path: Path) -> None:
    """Step responses of the FIR model (cumulative impulse responses)."""
    n = 40
    fig = Figure(figsize=(10, 3.5))
    axes = fig.subplots(1, 2, sharex=True)
    for motor, name in ((0, "left"), (1, "right")):
        u = np.zeros((n, 2))
        u[:, motor] = 1.0
        y = fir.simulate(u)
        t_ms = np.arange(n) * fir.dt_s * 1e3
        axes[0].step(t_ms, y[:, 0], where="post", label=f"{name} motor")
        axes[1].step(t_ms, y[:, 1], where="post", label=f"{name} motor")
    axes[0].set(xlabel="time [ms]", ylabel="v per unit command", title="h_Lv, h_Rv (steps)")
    axes[1].set(xlabel="time [ms]", ylabel="w [rad/s] per m/s", title="h_Lw, h_Rw (steps)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    save_figure(fig, path)


def plot_order_selection(arx: MotionModel, path: Path) -> None:
    """Free-run validation NRMSE against order, one line per delay, the choice marked."""
    sel = arx.selection
    viridis = matplotlib.colormaps["viridis"]
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    for j, delay in enumerate(sel.delays):
        ax.plot(sel.orders, np.where(sel.stable[:, j], sel.nrmse[:, j], np.nan), lw=0.8,
                color=viridis(j / max(1, len(sel.delays) - 1)), label=f"delay {delay}")
    ax.plot(sel.orders, sel.curve, "k-", lw=2, label="best over delays")
    i = int(np.flatnonzero(sel.orders == sel.order)[0])
    ax.plot(sel.order, sel.curve[i], "ro", ms=9,
            label=f"chosen: order {sel.order}, delay {sel.delay}")
    ax.set(xlabel="ARX order (na = nb)", ylabel="free-run validation NRMSE",
           title="Order and delay selection on held-out data", yscale="log")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))   # beside the curves
    fig.tight_layout()
    save_figure(fig, path, tight=True)


def plot_sequence(cal: Calibration, path: Path, *, seconds: float = 20.0) -> None:
    """Commands and encoder speeds of the random excitation (paper Fig. 7)."""
    log = cal.logs["excitation"]
    u, y = speeds_from_log(log, m_per_tick=cal.m_per_tick, wheel_base_m=cal.arx.wheel_base_m)
    n = min(round(seconds / log.dt_s), len(u))           # a short excitation: all of it
    t = np.arange(n) * log.dt_s
    fig = Figure(figsize=(10, 6))
    axes = fig.subplots(3, 1, sharex=True)
    axes[0].step(t, u[:n, 0], where="post", label="left")
    axes[0].step(t, u[:n, 1], where="post", label="right")
    axes[0].set(ylabel="command [m/s]")
    axes[0].legend()
    axes[1].plot(t, y[:n, 0], lw=0.8)
    axes[1].set(ylabel="v [m/s]")
    axes[2].plot(t, y[:n, 1], lw=0.8)
    axes[2].set(ylabel="w [rad/s]", xlabel="time [s]")
    axes[0].set_title("Calibration sequence: random held normal commands, encoder speeds")
    fig.tight_layout()
    save_figure(fig, path)


def plot_calibration(cal: Calibration, out_dir: Path) -> list[Path]:
    """Write the step responses, order selection and calibration sequence plots to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "step_responses.png", out_dir / "order_selection.png",
             out_dir / "calibration_sequence.png"]
    plot_step_responses(cal.fir, paths[0])
    plot_order_selection(cal.arx, paths[1])
    plot_sequence(cal, paths[2])
    return paths
