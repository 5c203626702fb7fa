"""Calibrate a motion model by driving the simulated robot, and plot what was found.

The paper's three manoeuvres (rotation in place, one-motor steps, random excitation)
run on the simulator; the script writes four plots and the model file:

- ``step_responses.png``: the FIR model's step responses, v and w to each motor
  (as the paper's Fig. 5-6);
- ``order_selection.png``: free-run validation error against ARX order, per delay,
  with the choice marked;
- ``calibration_sequence.png``: the commands and encoder speeds of the excitation
  (as the paper's Fig. 7);
- ``validation.png``: a fresh drive, encoder speeds against the models' free-run output;
- ``model_arx.json``: the calibrated ARX model.

Run: ``python examples/calibrate_sim.py --out out/calibration [--preset paper]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from drivers.sim import Simulator
from drivers.sim_config import Room, get_preset
from lti_motion.calibration import Calibration, CalibrationPlan, calibrate, speeds_from_log
from lti_motion.excitation import random_held_normal
from lti_motion.model import MotionModel

OPEN_FLOOR = (30.0, 30.0, 0.0)


def run_calibration(preset: str, *, seed: int = 0, excitation_s: float = 180.0) -> Calibration:
    """Calibrate on the simulator: rotate beside the furniture, then drive on open floor."""
    params = get_preset(preset)
    sim = Simulator(params, seed=seed, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT)

    def progress(stage: str, done: int, total: int) -> None:
        print(f"\r  {stage:10s} {done:6d}/{total} frames", end="" if done < total else "\n",
              flush=True)

    def to_open_floor(stage: str) -> None:
        if stage != "rotation":
            sim.place(OPEN_FLOOR)

    return calibrate(sim, wheel_base_m=params.wheel_base_m,
                     plan=CalibrationPlan(seed=seed, excitation_s=excitation_s), floor="hard",
                     progress=progress, before_stage=to_open_floor)


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


def plot_step_responses(fir: MotionModel, path: Path) -> None:
    """Step responses of the FIR model (cumulative impulse responses)."""
    n = 40
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5), sharex=True)
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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_order_selection(arx: MotionModel, path: Path) -> None:
    """Free-run validation NRMSE against order, one line per delay, the choice marked."""
    sel = arx.selection
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for j, delay in enumerate(sel.delays):
        ax.plot(sel.orders, np.where(sel.stable[:, j], sel.nrmse[:, j], np.nan), lw=0.8,
                color=plt.cm.viridis(j / max(1, len(sel.delays) - 1)), label=f"delay {delay}")
    ax.plot(sel.orders, sel.curve, "k-", lw=2, label="best over delays")
    i = int(np.flatnonzero(sel.orders == sel.order)[0])
    ax.plot(sel.order, sel.curve[i], "ro", ms=9,
            label=f"chosen: order {sel.order}, delay {sel.delay}")
    ax.set(xlabel="ARX order (na = nb)", ylabel="free-run validation NRMSE",
           title="Order and delay selection on held-out data", yscale="log")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sequence(cal: Calibration, path: Path, *, seconds: float = 20.0) -> None:
    """Commands and encoder speeds of the random excitation (paper Fig. 7)."""
    log = cal.logs["excitation"]
    u, y = speeds_from_log(log, m_per_tick=cal.m_per_tick, wheel_base_m=cal.arx.wheel_base_m)
    n = round(seconds / log.dt_s)
    t = np.arange(n) * log.dt_s
    fig, axes = plt.subplots(3, 1, figsize=(10, 6), sharex=True)
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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_validation(cal: Calibration, u: np.ndarray, y: np.ndarray, path: Path,
                    *, seconds: float = 20.0) -> None:
    """Encoder speeds of a fresh drive against the models' free-run (sensor-less) output."""
    n = min(len(u), round(seconds / cal.arx.dt_s))
    t = np.arange(n) * cal.arx.dt_s
    fits = {name: m.fit_percent([(u, y)]) for name, m in (("ARX", cal.arx), ("FIR", cal.fir))}
    fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    for k, label in ((0, "v [m/s]"), (1, "w [rad/s]")):
        axes[k].plot(t, y[:n, k], color="0.6", lw=0.8, label="encoders")
        for name, model in (("ARX", cal.arx), ("FIR", cal.fir)):
            axes[k].plot(t, model.simulate(u)[:n, k], lw=1.2,
                         label=f"{name} free run, fit {fits[name][k]:.1f}%")
        axes[k].set(ylabel=label)
        axes[k].legend(fontsize=8, loc="upper right")
    axes[1].set(xlabel="time [s]")
    axes[0].set_title("Validation drive never used for fitting")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/calibration"))
    parser.add_argument("--preset", default="create2", choices=["create2", "paper"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--excitation-s", type=float, default=180.0,
                        help="length of the random excitation [s]")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"calibrating the simulated {args.preset} robot (seed {args.seed}) ...")
    cal = run_calibration(args.preset, seed=args.seed, excitation_s=args.excitation_s)
    u, y = validation_drive(args.preset, cal.arx, seed=args.seed)
    plot_step_responses(cal.fir, args.out / "step_responses.png")
    plot_order_selection(cal.arx, args.out / "order_selection.png")
    plot_sequence(cal, args.out / "calibration_sequence.png")
    plot_validation(cal, u, y, args.out / "validation.png")
    cal.arx.save(args.out / "model_arx.json")
    print(f"encoder scale {cal.m_per_tick * 1e3:.5f} mm/tick "
          f"(rotation period {cal.rotation.period_ticks:.1f} ticks, "
          f"confidence {cal.rotation.confidence:.3f})")
    print(f"ARX order {cal.arx.orders['na']}, delay {cal.arx.orders['delay']}; "
          f"free-run fit on a fresh drive: ARX {cal.arx.fit_percent([(u, y)]).round(1)}, "
          f"FIR {cal.fir.fit_percent([(u, y)]).round(1)} (v, w) %")
    print(f"wrote plots and model_arx.json to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
