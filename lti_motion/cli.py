"""The ``lti-motion`` command line (the application layer: wires core, drivers and fusion).

Sub-commands
------------
demo
    Drive the simulated robot through a manoeuvre and compare the true path
    with the path integrated from the encoders; writes a plot and metrics.

This module and the experiment runners are the only part of ``lti_motion``
allowed to import ``drivers`` and ``fusion`` (ARCHITECTURE.md, Layout).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["main"]


def _square_route(*, side_m: float, speed_m_s: float, turn_m_s: float, wheel_base_m: float,
                  dt_s: float, laps: int = 1) -> np.ndarray:
    """Open-loop commands: ``laps`` squares of straight legs and in-place left turns."""
    straight = np.full((round(side_m / speed_m_s / dt_s), 2), speed_m_s)
    turn_s = (np.pi / 2) * (wheel_base_m / 2) / turn_m_s
    turn = np.tile([-turn_m_s, turn_m_s], (round(turn_s / dt_s), 1))
    pause = np.zeros((round(0.5 / dt_s), 2))
    leg = np.concatenate([straight, pause, turn, pause])
    return np.concatenate([np.zeros((10, 2))] + [leg] * (4 * laps) + [np.zeros((40, 2))])


def run_demo(out_dir: Path, *, seed: int = 0, preset: str = "create2",
             floor: str = "hard") -> dict:
    """Drive a square on the simulator; compare encoder odometry with the truth.

    Returns
    -------
    dict
        The metrics written to ``out_dir / "metrics.json"``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from drivers.sim import Simulator
    from drivers.sim_config import get_preset
    from lti_motion.kinematics import integrate_poses
    from lti_motion.odometry import body_speeds_from_ticks, stream_clock

    params = get_preset(preset)
    start = np.array([1.75, 1.75, 0.0])
    cmd = _square_route(side_m=1.5, speed_m_s=0.3, turn_m_s=0.15,
                        wheel_base_m=params.wheel_base_m, dt_s=params.period_s)
    sim = Simulator(params, seed=seed, floor=floor, initial_pose=start)
    print(f"simulating {len(cmd) * params.period_s:.1f} s of driving "
          f"({preset}, {floor} floor, seed {seed}) ...", flush=True)
    log = sim.run(cmd)
    t_s = stream_clock(log.t_s, log.dt_s)
    speeds = body_speeds_from_ticks(log.ticks, t_s, m_per_tick=params.m_per_tick,
                                    wheel_base_m=params.wheel_base_m)
    odom = integrate_poses(speeds, np.diff(t_s), initial_pose=log.true_pose[0])
    truth = log.true_pose
    final_err = float(np.linalg.norm(odom[-1, :2] - truth[-1, :2]))
    closure = float(np.linalg.norm(truth[-1, :2] - start[:2]))
    metrics = {
        "preset": preset, "floor": floor, "seed": seed,
        "duration_s": float(len(cmd) * params.period_s),
        "odometry_final_position_error_m": final_err,
        "true_closure_offset_m": closure,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot(truth[:, 0], truth[:, 1], "k-", label="true path (simulator)")
    ax.plot(odom[:, 0], odom[:, 1], "C1--", label="encoder odometry")
    ax.plot(*start[:2], "go", label="start")
    seg = sim.room.segments
    for x1, y1, x2, y2, _ in seg:
        ax.plot([x1, x2], [y1, y2], color="0.6", lw=1)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"Open-loop square on the simulator ({floor} floor)")
    ax.legend(loc="upper right")
    fig.tight_layout()
    plot = out_dir / "trajectory.png"
    fig.savefig(plot, dpi=120)
    plt.close(fig)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    print(f"encoder odometry ends {final_err * 100:.1f} cm from the true position; "
          f"the robot stopped {closure * 100:.1f} cm from its start")
    print(f"wrote {plot} and {out_dir / 'metrics.json'}")
    return metrics


def _cmd_demo(args: argparse.Namespace) -> int:
    run_demo(Path(args.out), seed=args.seed, preset=args.preset, floor=args.floor)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lti-motion``."""
    parser = argparse.ArgumentParser(
        prog="lti-motion",
        description="Self-calibrating LTI motion models for differential-drive robots.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the main job on the simulator",
                          description="Drive the simulated robot and compare estimates "
                                      "with the truth; writes plots and metrics.json.")
    demo.add_argument("--out", default="out/demo", help="report folder (default: out/demo)")
    demo.add_argument("--seed", type=int, default=0, help="simulator seed (default: 0)")
    demo.add_argument("--preset", default="create2", choices=["create2", "paper"],
                      help="robot preset (default: create2)")
    demo.add_argument("--floor", default="hard", choices=["hard", "tile", "carpet"],
                      help="floor (default: hard)")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lti-motion`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"lti-motion {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
