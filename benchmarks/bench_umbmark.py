"""Benchmark ``umbmark``: UMBmark's bidirectional square as a calibration (issue 32).

The robot: the ``intrinsics`` benchmark's (:func:`benchmarks.bench_intrinsics.
asymmetric_robot`: a Create 2 whose left wheel is 1% larger and whose right motor is 10%
weaker), on tile. The procedure: Borenstein and Feng's, 4 m squares, 5 counter-clockwise
and 5 clockwise (:func:`lti_motion.app.umbmark_cli.simulate_umbmark`), each square's
start and end pose measured with 5 mm (each axis) and 0.5 deg of Gaussian noise, fitted
as ``lti-motion calibrate --log LOG --reference RUNS`` fits them
(:func:`lti_motion.calibration.calibrate_intrinsics_runs`, ``encoders="commanded"``, the
wheels' mean scale held at the robot description's nominal ``pi D / ticks_per_rev``, as
``--umbmark`` holds it). The calibration sees the counts and the measured poses only.

The truth, for scoring only (as the ``intrinsics`` benchmark's): each wheel's contact-point
travel per tick over the squares' steady straight runs (the tyres slip about 0.25% at
cruise on tile, so the ratio is not the geometric 1.01), and the contact wheel base.

Figures, seeds 0-19 (:data:`SEEDS`):

``umbmark.diameter_ratio_error_pct``
    Worst ``|ratio / truth - 1|`` [%] of the left/right scale ratio (target 0.1);
    ``..._mean_pct`` and ``..._std_pct`` the signed error's mean and spread over the seeds.
``umbmark.wheel_base_error_pct``
    Worst ``|b / truth - 1|`` [%] (target 0.3); ``..._mean_pct``, ``..._std_pct`` likewise.
``umbmark.diameter_ratio_geometric_error_pct``
    Worst error of the ratio against the geometric 1.01 (no target).
``umbmark.wheel_base_std_over_spread``
    The mean reported standard deviation of the wheel base over its spread across the
    seeds (no target; 1 is a calibrated covariance).
``umbmark.side_1m_*``
    The same with the command line's default 1 m squares (no targets).
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_intrinsics import FLOOR, asymmetric_robot, straight_line_truth
from benchmarks.harness import Figure, benchmark
from lti_motion.app.umbmark_cli import simulate_umbmark, umbmark_squares
from lti_motion.calibration.intrinsics_runs import calibrate_intrinsics_runs

SEEDS = range(20)
#: Borenstein & Feng 1996: 4 m squares, five each way.
SIDE_M = 4.0
RUNS = 5
#: The command line's default side (``--umbmark-side``).
CLI_SIDE_M = 1.0
#: The measurement's noise (a tape measure): position [m], heading [rad].
MEASURE_STD = (0.005, np.deg2rad(0.5))


def umbmark_run(params, seed: int, *, side_m: float = SIDE_M, runs: int = RUNS
                ) -> tuple[np.ndarray, np.ndarray]:
    """One UMBmark calibration; ``(ratio, wheel base [m], wheel base std [m])`` and the
    truth ``(ratio, wheel base [m])`` it is scored against (the truth for scoring only)."""
    log, measured = simulate_umbmark(params, side_m=side_m, runs=runs, seed=seed, floor=FLOOR,
                                     measure_std=MEASURE_STD)
    t, ticks = log.t_s[log.valid], log.ticks[log.valid]
    cut = [ticks[(t >= t0) & (t <= t1)] for t0, t1 in measured.times_s]
    cal = calibrate_intrinsics_runs(cut, measured.start_poses, measured.end_poses,
                                    turns=measured.turns.tolist(), encoders="commanded",
                                    mean_m_per_tick=params.m_per_tick)
    k = cal.intrinsics
    cmd, _, _ = umbmark_squares(params.period_s, params.wheel_base_m, side_m=side_m, runs=runs)
    left, right, base = straight_line_truth(params, log, cmd)
    return (np.array([k.m_per_tick_left / k.m_per_tick_right, k.wheel_base_m, cal.std[2]]),
            np.array([left / right, base]))


def umbmark_errors(params, seeds, *, side_m: float = SIDE_M, runs: int = RUNS) -> np.ndarray:
    """Per seed: the ratio's error against the straight-line truth and against 1.01 [%],
    the wheel base's error [%] and its reported standard deviation [%]."""
    geometric = (1 + params.wheel_diameter_errors[0]) / (1 + params.wheel_diameter_errors[1])
    rows = []
    for seed in seeds:
        got, truth = umbmark_run(params, seed, side_m=side_m, runs=runs)
        rows.append([100 * (got[0] / truth[0] - 1), 100 * (got[0] / geometric - 1),
                     100 * (got[1] / truth[1] - 1), 100 * got[2] / truth[1]])
    return np.array(rows)


def _figures(prefix: str, e: np.ndarray, *, targets: bool) -> list[Figure]:
    ratio, base = e[:, 0], e[:, 2]
    return [
        Figure(f"{prefix}diameter_ratio_error_pct", float(np.abs(ratio).max()), "%",
               target=0.1 if targets else None, better="lower"),
        Figure(f"{prefix}diameter_ratio_error_mean_pct", float(ratio.mean()), "%",
               better="lower"),
        Figure(f"{prefix}diameter_ratio_error_std_pct", float(ratio.std(ddof=1)), "%",
               better="lower"),
        Figure(f"{prefix}diameter_ratio_geometric_error_pct", float(np.abs(e[:, 1]).max()), "%",
               better="lower"),
        Figure(f"{prefix}wheel_base_error_pct", float(np.abs(base).max()), "%",
               target=0.3 if targets else None, better="lower"),
        Figure(f"{prefix}wheel_base_error_mean_pct", float(base.mean()), "%", better="lower"),
        Figure(f"{prefix}wheel_base_error_std_pct", float(base.std(ddof=1)), "%",
               better="lower"),
        Figure(f"{prefix}wheel_base_std_over_spread", float(e[:, 3].mean() / base.std(ddof=1)),
               "ratio", better="lower"),
    ]


@benchmark("umbmark")
def run() -> list[Figure]:
    params = asymmetric_robot()
    return (_figures("umbmark.", umbmark_errors(params, SEEDS), targets=True)
            + _figures("umbmark.side_1m_", umbmark_errors(params, SEEDS, side_m=CLI_SIDE_M),
                       targets=False))
