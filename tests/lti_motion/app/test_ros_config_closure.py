"""The exported multipliers in diff_drive_controller's own odometry (its formula, written once
in ``benchmarks.bench_ros_config``) close the route as the project's calibrated odometry does:
on the robot with a 1% larger left wheel, from 0.9 m (nominal parameters) to under 0.10 m."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_intrinsics import FLOOR, asymmetric_robot, calibration_run
from benchmarks.bench_ros_config import DiffDriveControllerOdometry, exported
from lti_motion.app.ros_config import Nominal
from lti_motion.app.route import Odometry, drive_route
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import pose_step
from lti_motion.recordings.frames import SensorFrame

SEEDS = list(range(10))


@pytest.fixture(scope="module")
def robot():
    params = asymmetric_robot()
    nominal = Nominal(wheel_radius_m=params.wheel_diameter_m / 2,
                      wheel_separation_m=params.wheel_base_m, ticks_per_rev=params.ticks_per_rev)
    return params, nominal


def _frame(ticks) -> SensorFrame:
    n = len(ticks)
    return SensorFrame(t_s=0.0, ticks=np.asarray(ticks, np.int64),
                       light_bump=np.zeros((n, 6)), bumps=np.zeros((n, 2), bool),
                       cmd_m_s=np.zeros((n, 2)), valid=np.ones(n, bool))


def test_the_controllers_formula_agrees_with_paper_eq_11_on_an_arc_and_a_line():
    k = OdometryIntrinsics(4.5e-4, 4.4e-4, 0.235)
    ddc = DiffDriveControllerOdometry({"wheel_radius": 0.036, "left_wheel_radius_multiplier":
                                       4.5e-4 * 508.8 / (2 * np.pi * 0.036),
                                       "right_wheel_radius_multiplier":
                                       4.4e-4 * 508.8 / (2 * np.pi * 0.036),
                                       "wheel_separation": 0.235,
                                       "wheel_separation_multiplier": 1.0}, ticks_per_rev=508.8)
    ddc.reset(2, np.zeros((2, 3)))
    ddc.step(_frame([[100, 100], [100, 100]]), None)            # anchors the counts
    steps = np.array([[30, 45], [40, 40]])                      # an arc; a line (one wheel
    pose = ddc.step(_frame([[130, 145], [140, 140]]), None)     # larger: still a slight arc)
    ds, dth = k.body_motion(steps).T
    np.testing.assert_allclose(pose, pose_step(np.zeros((2, 3)), ds, dth, 1.0), atol=1e-15)


def test_the_exported_parameters_close_the_route_as_the_calibrated_odometry(robot, tiny_model):
    params, nominal = robot
    k = calibration_run(params, 0)[0]
    ddc = DiffDriveControllerOdometry(exported(tiny_model.with_intrinsics(k), nominal),
                                      ticks_per_rev=nominal.ticks_per_rev)
    closure = drive_route(params, ddc, seeds=SEEDS, floor=FLOOR).closure_offset_m
    project = drive_route(params, Odometry(intrinsics=k), seeds=SEEDS,
                          floor=FLOOR).closure_offset_m
    assert closure.mean() <= 0.10
    np.testing.assert_allclose(closure, project, atol=1e-3)     # the same odometry
    spec = OdometryIntrinsics.symmetric(m_per_tick=params.m_per_tick,
                                        wheel_base_m=params.wheel_base_m)
    base = DiffDriveControllerOdometry(exported(tiny_model.with_intrinsics(spec), nominal),
                                       ticks_per_rev=nominal.ticks_per_rev)
    assert base.left_radius == pytest.approx(nominal.wheel_radius_m)   # multipliers 1
    before = drive_route(params, base, seeds=SEEDS, floor=FLOOR).closure_offset_m
    assert before.mean() > 0.5                                   # the 0.9 m of the robot


def test_a_lost_frame_spans_the_gap_in_the_controller_too():
    ddc = DiffDriveControllerOdometry({"wheel_radius": 0.036, "left_wheel_radius_multiplier": 1.0,
                                       "right_wheel_radius_multiplier": 1.0,
                                       "wheel_separation": 0.235,
                                       "wheel_separation_multiplier": 1.0}, ticks_per_rev=508.8)
    ddc.reset(1, np.zeros((1, 3)))
    ddc.step(_frame([[0, 0]]), None)
    lost = _frame([[50, 50]])
    lost = SensorFrame(t_s=0.0, ticks=lost.ticks, light_bump=lost.light_bump, bumps=lost.bumps,
                       cmd_m_s=lost.cmd_m_s, valid=np.zeros(1, bool))
    ddc.step(lost, None)
    pose = ddc.step(_frame([[100, 100]]), None)
    assert pose[0, 0] == pytest.approx(100 * 2 * np.pi / 508.8 * 0.036)
