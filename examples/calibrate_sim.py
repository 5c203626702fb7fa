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

import numpy as np

from drivers.sim.calibration import calibrate_simulator, print_progress, summarize
from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.app.plots import plot_calibration, plot_validation
from lti_motion.calibration import Calibration, CalibrationPlan, speeds_from_log
from lti_motion.excitation import random_held_normal
from lti_motion.model import MotionModel


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
    plot_calibration(cal, args.out)
    plot_validation(cal, u, y, args.out / "validation.png")
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
