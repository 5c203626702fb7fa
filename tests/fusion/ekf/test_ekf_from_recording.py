"""What the EKF fuses from a recording of any robot: the grid's measured body speeds
(docs/log_format.md), here from wheel angles as a JointState robot reports them."""

from __future__ import annotations

import numpy as np

from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf.model_ekf import ModelEKF
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.recording import Recording
from lti_motion.recordings.resample import on_grid
from lti_motion.recordings.ticks import unwrap_ticks


def test_wheel_angles_through_the_grid_track_like_the_counts(route_model: MotionModel):
    params = get_preset("create2")
    dt = params.period_s
    cmd = random_held_normal(n=round(20 / dt), dt_s=dt, rng=np.random.default_rng(8),
                             std_m_s=0.15, mean_m_s=0.1, hold_s=(0.5, 2.0), correlation=0.85)
    log = Simulator(params, seed=8, room=Room.empty()).run(cmd)
    scale, start = route_model.m_per_tick, log.true_pose[0]
    angles = unwrap_ticks(log.ticks) * scale / 0.036
    rec = Recording.from_streams(wheel_t_s=log.t_s, dt_s=dt, wheel_angles_rad=angles,
                                 cmd_t_s=log.t_s - dt, cmd_wheel_m_s=log.cmd_m_s)
    grid = on_grid(rec, wheel_base_m=route_model.wheel_base_m, wheel_radius_m=0.036)
    by_speeds = ModelEKF(route_model, initial_pose=start)
    for u, speeds, measured in zip(grid.cmd_m_s, grid.speeds, grid.measured, strict=True):
        by_speeds.predict(u)
        if measured:
            by_speeds.update_speeds(speeds)
    by_counts = ModelEKF(route_model, initial_pose=start, initial_ticks=log.ticks[0])
    for u, ticks in zip(log.cmd_m_s[1:], log.ticks[1:], strict=True):
        by_counts.predict(u)
        by_counts.update_encoders(ticks)
    travelled = np.sum(np.hypot(*np.diff(log.true_pose[:, :2], axis=0).T))
    assert travelled > 1.0
    err_speeds = np.hypot(*(by_speeds.pose[:2] - log.true_pose[-1, :2]))
    err_counts = np.hypot(*(by_counts.pose[:2] - log.true_pose[-1, :2]))
    # measured (seed 8): 7 mm by speeds, 3 mm by counts, over 2.1 m
    assert err_speeds < 0.01 * travelled, (err_speeds, err_counts, travelled)
    assert abs(err_speeds - err_counts) < 0.005 * travelled, (err_speeds, err_counts)
