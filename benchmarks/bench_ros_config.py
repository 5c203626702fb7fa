"""``lti-motion export`` checked the way a ROS user would meet it: ``diff_drive_controller``'s
own odometry fed the simulated robot's wheel angles with the exported parameters, on the
paper's route (docs/guide_ros_config.md).

The robot: the asymmetric Create 2 of ``bench_intrinsics`` (left wheel 1% larger, right
motor 10% weaker, tile). Its model (``calibrate_simulator``, seed 0, 60 s excitation) is
moved to the intrinsics of each of 5 pose-reference calibrations
(``bench_intrinsics.calibration_run``, calibration seeds 0-4) and exported against the
nominal Create 2 (wheel radius 0.036 m, separation 0.235 m, 508.8 ticks per revolution);
:class:`DiffDriveControllerOdometry` then steers the route (30 seeds) on the controller's
own formula. The estimator never reads the truth; the closures and errors are scored
against it.

Figures:

``ros_config.ddc_closure_m``
    Mean closure offset [m] of the controller's odometry with the exported multipliers, 5
    calibrations x 30 route seeds (target 0.10 m); baseline: the same controller with the
    nominal parameters (multipliers 1).
``ros_config.ddc_closure_std_m``, ``ros_config.ddc_closure_project_m``
    Their spread, and the project's calibrated encoder odometry
    (``lti_motion.app.route.Odometry(intrinsics=...)``) on the same seeds.
``ros_config.pose_nees``
    Mean over the 150 runs of the position NEES at the end of the route, ``e^T P^-1 e``
    with ``e`` the controller's position error and ``P`` its pose covariance grown along
    its path from the exported noise (``OdometryNoise.from_model``, what the project
    writes for dead reckoning): the model carries the odometry errors each calibration
    measured on its own drive (``IntrinsicsCalibration.odometry_errors``: the random walk
    per metre of wheel travel and the intrinsics' covariance); a consistent covariance
    gives a mean inside the 95% interval of ``chi^2(2 N) / N`` (``..._low`` /
    ``..._high``), ``..._inside`` 1 or 0. Baseline: the same model without the measured
    errors (the pose grown with ``R`` less the counts' rounding, the fallback).
``ros_config.pose_nees_std``
    Its spread over the runs.
``ros_config.ekf_pose_nees``
    The same for the model EKF's pose covariance (encoders, no landmarks; what
    ``replay / monitor --bag --out-bag`` write), on the same calibrations and seeds.
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks.bench_intrinsics import FLOOR, REPEATS, asymmetric_robot
from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Room
from drivers.sim.motion_capture import intrinsics_drive, motion_capture
from drivers.sim.simulator import Simulator
from lti_motion.app.ros_config import Nominal, diff_drive_parameters
from lti_motion.app.route import EkfEstimator, Odometry, drive_route
from lti_motion.calibration.intrinsics_fit import calibrate_intrinsics
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.odometry_noise import OdometryNoise
from lti_motion.recordings.ticks import tick_step

ROUTE_SEEDS = range(30)
CAL_SEEDS = range(5)


class DiffDriveControllerOdometry:
    """``diff_drive_controller``'s odometry update, as the controller publishes it, driven by
    the wheel joints' angles (a route estimator, :mod:`lti_motion.app.route`).

    Written from ros2_controllers' ``diff_drive_controller/src/odometry.cpp`` (branch
    jazzy, 4.42.1; the same arithmetic in ROS 1 ros_controllers 0.21.2): each wheel's
    position ``angle * wheel_radius * multiplier``; the increments' mean is the travel, their
    difference over ``wheel_separation * multiplier`` the turn; ``integrateExact``: an arc
    ``x += r (sin h1 - sin h0)``, ``y -= r (cos h1 - cos h0)`` with ``r = travel / turn``, or
    second-order Runge-Kutta when ``|turn| < 1e-6``. The hardware interface's joint angle
    is the encoder count times ``2 pi / ticks_per_rev``; a lost frame's angles do not
    change, so the next frame's increment spans the gap.

    Parameters
    ----------
    parameters : dict
        ``wheel_radius``, ``left_wheel_radius_multiplier``, ``right_wheel_radius_multiplier``,
        ``wheel_separation``, ``wheel_separation_multiplier`` as exported.
    ticks_per_rev : float
        The hardware interface's counts per wheel revolution.
    """

    def __init__(self, parameters: dict, *, ticks_per_rev: float) -> None:
        self.left_radius = parameters["wheel_radius"] * parameters["left_wheel_radius_multiplier"]
        self.right_radius = (parameters["wheel_radius"]
                             * parameters["right_wheel_radius_multiplier"])
        self.separation = parameters["wheel_separation"] * parameters["wheel_separation_multiplier"]
        self.rad_per_tick = 2.0 * math.pi / ticks_per_rev

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        self.pose = np.array(initial_pose, dtype=float).reshape(n_robots, 3)
        self._ticks = np.zeros((n_robots, 2), np.int64)
        self._angle = np.zeros((n_robots, 2))          # joint positions [rad]
        self._old = None                               # the wheels' last positions [m]
        self._anchored = np.zeros(n_robots, bool)
        self.increments: list[np.ndarray] = []         # (travel [m], turn [rad]) per step

    def step(self, frame, cmd_m_s, observations=None) -> np.ndarray:
        ticks = np.asarray(frame.ticks, np.int64).reshape(self._ticks.shape)
        valid = np.broadcast_to(np.asarray(frame.valid, bool), (len(ticks),))
        step = np.where((valid & self._anchored)[:, None], tick_step(self._ticks, ticks), 0)
        self._ticks = np.where(valid[:, None], ticks, self._ticks)
        self._anchored |= valid
        self._angle = self._angle + step * self.rad_per_tick
        left = self._angle[:, 0] * self.left_radius
        right = self._angle[:, 1] * self.right_radius
        if self._old is None:
            self._old = (left, right)
        d_left, d_right = left - self._old[0], right - self._old[1]
        self._old = (left, right)
        linear = 0.5 * (d_left + d_right)
        angular = (d_right - d_left) / self.separation
        x, y, h = self.pose.T.copy()
        small = np.abs(angular) < 1e-6
        direction = h + 0.5 * angular                  # integrateRungeKutta2
        safe = np.where(small, 1.0, angular)
        r = linear / safe                              # integrateExact
        h1 = h + angular
        x = np.where(small, x + linear * np.cos(direction), x + r * (np.sin(h1) - np.sin(h)))
        y = np.where(small, y + linear * np.sin(direction), y - r * (np.cos(h1) - np.cos(h)))
        self.pose = np.column_stack([x, y, h1])
        self.increments.append(np.column_stack([linear, angular]))
        return self.pose


def exported(model, nominal: Nominal) -> dict:
    """The exported ``diff_drive_controller`` parameters by name."""
    return {p.name: p.value for p in diff_drive_parameters(model, nominal)}


def nees_at_end(res, covs: np.ndarray) -> np.ndarray:
    """Position NEES of each run's last estimate against its truth, (N,)."""
    e = res.est_poses[:, -1, :2] - res.true_poses[:, -1, :2]
    p = covs[:, :2, :2]
    return np.einsum("ni,nij,nj->n", e, np.linalg.inv(p), e)


class CovarianceEkf(EkfEstimator):
    """The route's model EKF, keeping each filter's pose covariance of the last step."""

    def step(self, frame, cmd_m_s, observations=None):
        pose = super().step(frame, cmd_m_s, observations)
        if self.filters is not None:
            self.covs = np.array([f.P[:3, :3] for f in self.filters])
        return pose


def chi2_interval(n_runs: int, dof: int = 2) -> tuple[float, float]:
    """95% interval of the mean of ``n_runs`` chi-square(``dof``) values."""
    from scipy.stats import chi2

    return (float(chi2.ppf(0.025, dof * n_runs)) / n_runs,
            float(chi2.ppf(0.975, dof * n_runs)) / n_runs)


def calibrated_model(model, params, seed: int):
    """``model`` moved to the intrinsics of ``bench_intrinsics.calibration_run(params,
    seed)``'s calibration (the same drive, reference and options), carrying the odometry
    errors that calibration measured on its drive."""
    cmd = intrinsics_drive(params.period_s, repeats=REPEATS)
    log = Simulator(params, seed=seed, floor=FLOOR, room=Room.empty(),
                    initial_pose=(0, 0, 0)).run(cmd)
    t_ref, poses = motion_capture(log, rng=np.random.default_rng([seed, 0x40CA]))
    cal = calibrate_intrinsics(log.t_s, log.ticks, t_ref, poses, sensor_pose=False,
                               encoders="commanded", heading_std_rad=np.deg2rad(0.5))
    return model.with_intrinsics(cal.intrinsics, odometry_errors=cal.odometry_errors)


def end_covariances(m, ddc, res, n_runs: int) -> np.ndarray:
    """Each run's pose covariance at the end, grown along the controller's path with
    ``OdometryNoise.from_model(m)``, (N, 3, 3)."""
    noise = OdometryNoise.from_model(m)
    inc = np.stack(ddc.increments, axis=1)                       # (N, n, 2)
    start = np.broadcast_to(res.est_poses[:, :1], (n_runs, 1, 3))
    poses = np.concatenate([start, res.est_poses], axis=1)       # (N, n + 1, 3)
    return np.array([noise.pose_covariances(poses[i], inc[i] / m.dt_s,
                                            np.ones(len(inc[i])))[-1] for i in range(n_runs)])


def ros_config_runs(cal_seeds=CAL_SEEDS, route_seeds=ROUTE_SEEDS) -> dict[str, np.ndarray]:
    """Closures [m] and NEES of every (calibration, route seed), keyed by what ran."""
    params = asymmetric_robot()
    nominal = Nominal(wheel_radius_m=params.wheel_diameter_m / 2,
                      wheel_separation_m=params.wheel_base_m, ticks_per_rev=params.ticks_per_rev,
                      source="the create2 robot file")
    model = calibrate_simulator(params, seed=0, floor=FLOOR,
                                plan=CalibrationPlan(seed=2, excitation_s=60.0)).arx
    seeds = list(route_seeds)
    out: dict[str, list] = {"ddc": [], "project": [], "nees": [], "nees_unmeasured": [],
                            "ekf_nees": []}
    for cal_seed in cal_seeds:
        m = calibrated_model(model, params, cal_seed)
        ddc = DiffDriveControllerOdometry(exported(m, nominal), ticks_per_rev=nominal.ticks_per_rev)
        res = drive_route(params, ddc, seeds=seeds, floor=FLOOR)
        out["ddc"].append(res.closure_offset_m)
        out["nees"].append(nees_at_end(res, end_covariances(m, ddc, res, len(seeds))))
        unmeasured = m.updated(odometry_errors=None)
        out["nees_unmeasured"].append(nees_at_end(res, end_covariances(unmeasured, ddc, res,
                                                                       len(seeds))))
        out["project"].append(drive_route(params, Odometry(intrinsics=m.intrinsics),
                                          seeds=seeds, floor=FLOOR).closure_offset_m)
        ekf = CovarianceEkf(m)
        out["ekf_nees"].append(nees_at_end(drive_route(params, ekf, seeds=seeds, floor=FLOOR),
                                           ekf.covs))
    base = DiffDriveControllerOdometry(exported(model.with_intrinsics(
        _nominal_intrinsics(params)), nominal), ticks_per_rev=nominal.ticks_per_rev)
    out["nominal"] = [drive_route(params, base, seeds=seeds, floor=FLOOR).closure_offset_m]
    return {k: np.concatenate(v) for k, v in out.items()}


def _nominal_intrinsics(params):
    """The spec's intrinsics: exported against the spec, every multiplier 1."""
    from lti_motion.intrinsics import OdometryIntrinsics

    return OdometryIntrinsics.symmetric(m_per_tick=params.m_per_tick,
                                        wheel_base_m=params.wheel_base_m)


@benchmark("ros_config")
def run() -> list[Figure]:
    runs = ros_config_runs()
    low, high = chi2_interval(len(runs["nees"]))
    nees = float(runs["nees"].mean())
    return [
        Figure("ros_config.ddc_closure_m", float(runs["ddc"].mean()), "m", target=0.10,
               better="lower", baseline="diff_drive_controller with the nominal parameters",
               baseline_value=float(runs["nominal"].mean())),
        Figure("ros_config.ddc_closure_std_m", float(runs["ddc"].std()), "m", better="lower"),
        Figure("ros_config.ddc_closure_project_m", float(runs["project"].mean()), "m",
               better="lower"),
        Figure("ros_config.pose_nees", nees, "",    # the interval is two-sided: ..._inside
               baseline="the pose grown with R less the counts' rounding (no measurement)",
               baseline_value=float(runs["nees_unmeasured"].mean())),
        Figure("ros_config.pose_nees_std", float(runs["nees"].std()), "", better="lower"),
        Figure("ros_config.pose_nees_low", low, ""),
        Figure("ros_config.pose_nees_high", high, ""),
        Figure("ros_config.pose_nees_inside", float(low <= nees <= high), "", target=1.0),
        Figure("ros_config.ekf_pose_nees", float(runs["ekf_nees"].mean()), "", better="lower"),
    ]


def table(cal_seeds=CAL_SEEDS, route_seeds=ROUTE_SEEDS) -> None:
    """Per calibration: the closures and NEES of its route seeds, mean (standard deviation)."""
    runs = ros_config_runs(cal_seeds, route_seeds)
    n = len(list(route_seeds))
    print("| calibration seed | controller closure [m] | project closure [m] | pose NEES | "
          "pose NEES, unmeasured | EKF pose NEES |")
    print("| --- | --- | --- | --- | --- | --- |")
    for i, seed in enumerate(cal_seeds):
        row = slice(i * n, (i + 1) * n)
        cells = [f"{runs[k][row].mean():.4f} ({runs[k][row].std():.4f})"
                 for k in ("ddc", "project", "nees", "nees_unmeasured", "ekf_nees")]
        print(f"| {seed} | " + " | ".join(cells) + " |")
    print(f"nominal parameters: {runs['nominal'].mean():.4f} ({runs['nominal'].std():.4f}) m")
