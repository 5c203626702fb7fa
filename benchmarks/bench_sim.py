"""Simulator throughput: simulated robot-seconds per wall-clock second.

Baselines: the same robots run one at a time (one ``run`` call per robot), and
one robot stepped period by period, so the ratios show what lock-step batching
buys in whole-sequence and in closed-loop (``step``) use.
"""

from __future__ import annotations

import numpy as np

from benchmarks.harness import Figure, benchmark, median_seconds
from drivers.sim.config import Room
from drivers.sim.simulator import Simulator

DURATION_S = 60.0
N_BATCH = 30


def _commands(n_robots: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.uniform(-0.3, 0.3, (n_robots, n, 2))


@benchmark("sim")
def sim_throughput() -> list[Figure]:
    n = int(DURATION_S / 0.015)
    cmd = _commands(N_BATCH, n)
    room = Room.cluttered()

    def batch() -> None:
        Simulator("create2", n_robots=N_BATCH, seed=0, room=room).run(cmd)

    def one_at_a_time() -> None:
        for i in range(N_BATCH):
            Simulator("create2", seed=i, room=room).run(cmd[i])

    def one() -> None:
        Simulator("create2", seed=0, room=room).run(cmd[0])

    def stepped() -> None:
        sim = Simulator("create2", seed=0, room=room)
        for k in range(n // 10):
            sim.step(cmd[0, k])

    def batch_stepped() -> None:
        sim = Simulator("create2", n_robots=N_BATCH, seed=0, room=room)
        for k in range(n // 10):
            sim.step(cmd[:, k])

    t_batch = median_seconds(batch, repeat=5)
    t_batch_step = median_seconds(batch_stepped, repeat=3)
    t_serial = median_seconds(one_at_a_time, repeat=3)
    t_one = median_seconds(one, repeat=7)
    t_step = median_seconds(stepped, repeat=3)
    robot_s = N_BATCH * DURATION_S
    return [
        Figure("sim.batch30_robot_s_per_s", robot_s / t_batch, "robot-s/s", target=1000.0,
               baseline="30 robots one at a time", baseline_value=robot_s / t_serial),
        Figure("sim.one_robot_robot_s_per_s", DURATION_S / t_one, "robot-s/s", target=100.0),
        Figure("sim.one_robot_stepped_robot_s_per_s", DURATION_S / 10 / t_step, "robot-s/s",
               target=100.0),
        Figure("sim.batch30_stepped_robot_s_per_s", robot_s / 10 / t_batch_step, "robot-s/s",
               target=1000.0, baseline="one robot stepped",
               baseline_value=DURATION_S / 10 / t_step),
        Figure("sim.batch30_60s_route_wall_s", t_batch, "s", target=2.0, better="lower"),
    ]
