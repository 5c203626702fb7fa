"""The paper's closed-route evaluation (Table II) on the simulator, in lock step."""

import numpy as np
import pytest

from drivers.sim import Simulator
from drivers.sim_config import Room, get_preset
from lti_motion.calibration import CalibrationPlan, calibrate
from lti_motion.experiments.route import ROUTE_M, ArxHybrid, Odometry, SensorLess, drive_route

P = get_preset("create2")


@pytest.fixture(scope="module")
def cal():
    sim = Simulator(P, seed=201, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT)
    return calibrate(sim, wheel_base_m=P.wheel_base_m, plan=CalibrationPlan(seed=1),
                     before_stage=lambda s: s != "rotation" and sim.place(Room.OPEN_FLOOR))


def test_route_is_about_10_m_and_closed():
    length = np.linalg.norm(np.diff(ROUTE_M, axis=0), axis=1).sum()
    assert 9.5 < length < 11.0 and np.array_equal(ROUTE_M[0], ROUTE_M[-1])


def test_odometry_run_stops_where_it_believes_it_started(cal):
    est = Odometry(m_per_tick=cal.m_per_tick, wheel_base_m=P.wheel_base_m)
    result = drive_route(P, est, seeds=range(10))
    assert result.finished.all()
    believed = np.linalg.norm(result.est_poses[:, -1, :2] - ROUTE_M[0], axis=1)
    assert believed.max() < 0.04                            # it stopped on its estimate
    # the closure offset is the truth's, and odometry is not perfect on this robot
    np.testing.assert_allclose(
        result.closure_offset_m, np.linalg.norm(result.true_poses[:, -1, :2], axis=1))
    assert 0.02 < result.closure_offset_m.mean() < 0.2
    # the robot really went round: it passed near every checkpoint
    for checkpoint in ROUTE_M[1:-1]:
        assert np.linalg.norm(result.true_poses[0, :, :2] - checkpoint, axis=1).min() < 0.25


@pytest.mark.parametrize("kind", ["arx", "hybrid"])
def test_model_estimators_complete_the_route(cal, kind):
    est = SensorLess(cal.arx) if kind == "arx" else ArxHybrid(cal.arx)
    result = drive_route(P, est, seeds=range(6))
    assert result.finished.all()
    assert result.closure_offset_m.max() < 1.0


class _Peeking:
    """An estimator that fails if it is shown the simulator's truth."""

    def reset(self, n_robots, pose0):
        self.pose = np.array(pose0, dtype=float)

    def step(self, frame, cmd_m_s, observations=None):
        assert frame.true_pose is None and frame.true_body_m_s is None
        return self.pose


def test_estimators_never_see_the_truth():
    result = drive_route(P, _Peeking(), seeds=[0, 1], max_s=1.0)
    assert result.true_poses.shape[0] == 2


def test_ekf_with_landmarks_closes_the_route_within_3_cm(cal):
    """The main job's target for this row (demo: 0.025 +- 0.004 m over 30 runs)."""
    from lti_motion.experiments.route import ROUTE_LANDMARKS, EkfEstimator

    result = drive_route(P, EkfEstimator(cal.arx, landmarks=ROUTE_LANDMARKS), seeds=range(8),
                         landmarks=ROUTE_LANDMARKS)
    assert result.finished.all()
    assert result.closure_offset_m.mean() <= 0.03, result.closure_offset_m
