"""Calibrate a motion model by driving the simulated robot, and plot what was found.

The paper's three manoeuvres (rotation in place, one-motor steps, random excitation)
run on the simulator; the script writes four plots and the model file:

- ``step_responses.png``: the FIR model's step responses, v and w to each motor
  (as paper Fig. 5-6);
- ``order_selection.png``: free-run validation error against ARX order, per delay,
  with the choice marked;
- ``calibration_sequence.png``: the commands and encoder speeds of the excitation
  (as paper Fig. 7);
- ``validation.png``: a fresh drive, encoder speeds against the models' free-run output;
- ``model_arx.json``: the calibrated ARX model.

Run: ``python examples/calibrate_sim.py --out out/calibration [--preset paper]``.

It stands on the public API only (the simulator, the calibration, the model) and draws
its figures with matplotlib's object-oriented API (``Figure`` and ``savefig``: no
pyplot, no backend to choose). ``lti-motion calibrate --sim create2`` does the same from
the command line.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivers.sim import (
    PRESETS,
    Room,
    Simulator,
    calibrate_simulator,
    get_preset,
    print_progress,
    summarize,
)
from lti_motion.calibration import Calibration, CalibrationPlan, speeds_from_log
from lti_motion.model import MotionModel, random_held_normal


def run_calibration(preset: str, *, seed: int = 0, excitation_s: float = 180.0) -> Calibration:
    """Calibrate on the simulator: rotate beside the furniture, then drive on open floor."""
    return calibrate_simulator(preset, seed=seed,
                               plan=CalibrationPlan(seed=seed, excitation_s=excitation_s),
                               progress=print_progress)


def validation_drive(preset: str, model: MotionModel, *, seed: int,
                     duration_s: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A fresh drive of the same kind as the excitation: commands and encoder speeds."""
    params = get_preset(preset)
    plan = CalibrationPlan()
    u = random_held_normal(n=round(duration_s / params.period_s), dt_s=params.period_s,
                           rng=np.random.default_rng(seed + 1000),
                           std_m_s=plan.excitation_std_m_s, hold_s=plan.hold_s,
                           correlation=plan.excitation_correlation)
    log = Simulator(params, seed=seed + 1000, room=Room.empty()).run(
        np.concatenate([np.zeros((60, 2)), u]))
    return speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=params.wheel_base_m)


#: One curve of a panel: (label, y values, matplotlib format string).
Curve = tuple[str, np.ndarray, str]


def save_panels(path: Path, title: str, x: np.ndarray, panels: list[tuple[str, list[Curve]]],
                *, xlabel: str = "time [s]", yscale: str = "linear") -> Path:
    """Stacked panels sharing the x axis, one per ``(y label, curves)``; written as a PNG."""
    fig = Figure(figsize=(9, 2.2 + 1.8 * len(panels)))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, curves) in zip(axes, panels, strict=True):
        for label, y, fmt in curves:
            ax.plot(x, y, fmt, lw=1.0, label=label)
        ax.set(ylabel=ylabel, yscale=yscale)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right", ncol=1 + len(curves) // 6)
    axes[0].set_title(title)
    axes[-1].set(xlabel=xlabel)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def plot_found(cal: Calibration, u: np.ndarray, y: np.ndarray, out: Path,
               *, seconds: float = 20.0) -> list[Path]:
    """The four figures of the module docstring, from the calibration and a fresh drive."""
    fir, arx, dt = cal.fir, cal.arx, cal.arx.dt_s
    steps = [fir.simulate(np.repeat([[1.0, 0.0] if m == 0 else [0.0, 1.0]], 40, axis=0))
             for m in (0, 1)]                             # a unit step on each motor
    sel = arx.selection
    per_delay = [(f"delay {d}", np.where(sel.stable[:, j], sel.nrmse[:, j], np.nan), "-")
                 for j, d in enumerate(sel.delays)]          # NaN: an unstable fit
    chosen = np.where(sel.orders == sel.order, sel.curve, np.nan)
    u_cal, y_cal = speeds_from_log(cal.logs["excitation"], m_per_tick=cal.m_per_tick,
                                   wheel_base_m=arx.wheel_base_m)
    n = round(seconds / dt)
    t = np.arange(n) * dt
    free = {"ARX": arx.simulate(u)[:n], "FIR": fir.simulate(u)[:n]}
    fits = {name: m.fit_percent([(u, y)]) for name, m in (("ARX", arx), ("FIR", fir))}
    return [
        save_panels(out / "step_responses.png", "FIR model: response to a unit step of one "
                    "motor", np.arange(40) * dt * 1e3,
                    [(f"{q} per m/s", [(f"{side} motor", s[:, k], "-")
                                       for side, s in zip(("left", "right"), steps,
                                                          strict=True)])
                     for k, q in enumerate(("v [m/s]", "w [rad/s]"))], xlabel="time [ms]"),
        save_panels(out / "order_selection.png", f"ARX order {sel.order}, delay {sel.delay}: "
                    "the smallest near the best held-out error", sel.orders,
                    [("free-run NRMSE", [*per_delay, ("best over delays", sel.curve, "k.-"),
                                         ("chosen", chosen, "ro")])],
                    xlabel="order (na = nb)", yscale="log"),
        save_panels(out / "calibration_sequence.png", "Random excitation: commands and "
                    "encoder speeds", t,
                    [("command [m/s]", [("left", u_cal[:n, 0], "-"),
                                        ("right", u_cal[:n, 1], "-")]),
                     ("v [m/s]", [("encoders", y_cal[:n, 0], "-")]),
                     ("w [rad/s]", [("encoders", y_cal[:n, 1], "-")])]),
        save_panels(out / "validation.png", "A fresh drive: encoders against the models' "
                    "free run (sensor-less)", t,
                    [(q, [("encoders", y[:n, k], "0.6"),
                          *((f"{name}, fit {fits[name][k]:.1f}%", s[:, k], "-")
                            for name, s in free.items())])
                     for k, q in enumerate(("v [m/s]", "w [rad/s]"))]),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/calibration"))
    parser.add_argument("--preset", default="create2", choices=list(PRESETS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--excitation-s", type=float, default=180.0,
                        help="length of the random excitation [s]")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"calibrating the simulated {args.preset} robot (seed {args.seed}) ...")
    cal = run_calibration(args.preset, seed=args.seed, excitation_s=args.excitation_s)
    u, y = validation_drive(args.preset, cal.arx, seed=args.seed)
    plot_found(cal, u, y, args.out)
    cal.arx.save(args.out / "model_arx.json")
    for line in summarize(cal):
        print(line)
    print(f"ARX order {cal.arx.orders['na']}, delay {cal.arx.orders['delay']}; "
          f"free-run fit on a fresh drive: ARX {cal.arx.fit_percent([(u, y)]).round(1)}, "
          f"FIR {cal.fir.fit_percent([(u, y)]).round(1)} (v, w) %")
    print(f"wrote plots and model_arx.json to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
