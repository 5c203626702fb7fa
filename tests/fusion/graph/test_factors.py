"""Preintegration and the GTSAM factors: closed forms, Monte Carlo, numerical Jacobians, errors."""

import gtsam
import numpy as np
import pytest
import scipy.linalg
from graph_scenes import DT, PHI, factor_values, group_values
from graph_scenes import speeds as _speeds
from gtsam.utils.numerical_derivative import numericalDerivative11

from fusion.exceptions import (
    EmptyIntervalError,
    FusionError,
    GraphInputError,
    KeyframeOrderError,
    LandmarkIdError,
    UnknownLandmarkError,
    UnknownPoseError,
)
from fusion.graph.calibrated_factors import pose2_log, pose2_log_derivative
from fusion.graph.factors import (
    calibrated_motion_error,
    calibrated_motion_factor,
    calibrated_motion_group_factor,
    calibration_key,
    calibration_walk_factor,
    landmark_key,
    motion_factor,
    mounted_range_bearing_factor,
    observe_landmarks,
    pose_key,
    predict_range_bearing,
    range_bearing_factors,
)
from fusion.graph.preintegration import (
    Preintegrated,
    compose_motions,
    fit_calibration,
    preintegrate,
    preintegrate_model,
    relative_pose_errors,
    speed_error_covariance,
)
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing
from fusion.sensor_pose import SensorPose
from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.kinematics import integrate_poses
from lti_motion.model.arx import ArxFit
from lti_motion.model.motion_model import MotionModel


def _relative(poses, i, j):
    return gtsam.Pose2(*poses[i]).between(gtsam.Pose2(*poses[j]))


@pytest.fixture
def arx_model():
    """A small stable ARX model (order 2, delay 1) with correlated noise."""
    a = np.stack([np.array([[-0.6, 0.05], [0.0, -0.5]]), np.array([[0.1, 0.0], [0.02, 0.08]])])
    b = np.stack([np.array([[0.2, 0.2], [-1.0, 1.0]]), np.array([[0.15, 0.15], [-0.8, 0.8]])])
    fit = ArxFit(a=a, b=b, delay=1, residual_cov=np.array([[4e-5, 1e-6], [1e-6, 3e-3]]),
                 n_rows=1000, rank=8, condition_number=10.0, input_condition_number=None,
                 information_inv=np.eye(16))
    return MotionModel.from_arx(fit, dt_s=DT, wheel_base_m=0.235, q_scale=1.5, m_per_tick=4.4e-4,
                                calibrated_at="2026-01-01T00:00:00+00:00")


# -- preintegration: the mean ------------------------------------------------------------------

CASES = {
    "straight": (np.tile([0.3, 0.0], (200, 1)), [0, 100, 200]),
    "arc": (np.tile([0.25, 0.5], (300, 1)), [0, 40, 41, 300]),
    "spin in place": (np.tile([0.0, 2.0], (150, 1)), [0, 150]),
    "offset keyframes": (None, [7, 60, 61, 180, 233]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_mean_equals_integrating_the_same_speeds(name, rng):
    speeds, kf = CASES[name]
    speeds = _speeds(rng, 240) if speeds is None else speeds
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI)
    for k in range(len(kf) - 1):
        direct = integrate_poses(speeds[kf[k]:kf[k + 1]], DT)[-1]
        np.testing.assert_allclose(pre.delta_pose[k], direct, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pre.duration_s, np.diff(kf) * DT)


def test_closed_forms_straight_line_and_arc():
    pre = preintegrate(np.tile([0.3, 0.0], (100, 1)), 0.01, keyframes=[0, 100],
                       speed_covariance=PHI)
    np.testing.assert_allclose(pre.delta_pose[0], [0.3, 0.0, 0.0], atol=1e-14)
    # a half circle of radius 0.5 m: v = 0.5 w
    pre = preintegrate(np.tile([0.5 * np.pi, np.pi], (100, 1)), 0.01, keyframes=[0, 100],
                       speed_covariance=PHI)
    np.testing.assert_allclose(pre.delta_pose[0], [0.0, 1.0, np.pi], atol=1e-12)


def test_per_sample_periods_and_calibration_scale_the_speeds(rng):
    speeds = _speeds(rng, 120)
    dt = DT + 1e-3 * rng.uniform(-1, 1, 120)
    pre = preintegrate(speeds, dt, keyframes=[0, 50, 120], speed_covariance=PHI,
                       calibration=(1.1, 0.9))
    direct = integrate_poses(speeds[50:] * [1.1, 0.9], dt[50:])[-1]
    np.testing.assert_allclose(pre.delta_pose[1], direct, atol=1e-12)


def test_compose_motions_is_dead_reckoning_through_the_keyframes(rng):
    speeds = _speeds(rng, 300)
    kf = np.array([0, 33, 66, 100, 200, 300])
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI)
    start = np.array([1.0, -2.0, 0.7])
    direct = integrate_poses(speeds, DT, initial_pose=start)[kf]
    np.testing.assert_allclose(compose_motions(pre.delta_pose, initial_pose=start), direct,
                               atol=1e-12)
    np.testing.assert_allclose(relative_pose_errors(pre, direct), 0.0, atol=1e-12)


# -- preintegration: covariance and calibration Jacobian -------------------------------------

def test_covariance_matches_monte_carlo_of_white_speed_errors(rng):
    speeds = _speeds(rng, 80, turn=1.5)
    pre = preintegrate(speeds, DT, keyframes=[0, 80], speed_covariance=PHI, slip_density=(0, 0, 0))
    chol = np.linalg.cholesky(PHI)
    noisy = speeds + rng.standard_normal((4000, 80, 2)) @ chol.T
    ends = integrate_poses(noisy, DT)[:, -1]
    mean = gtsam.Pose2(*pre.delta_pose[0])
    errs = np.array([mean.localCoordinates(gtsam.Pose2(*p)) for p in ends])
    np.testing.assert_allclose(np.cov(errs.T), pre.covariance[0], rtol=0.1,
                               atol=0.05 * np.abs(pre.covariance[0]).max())


def test_covariance_is_symmetric_positive_definite_even_at_rest():
    pre = preintegrate(np.zeros((50, 2)), DT, keyframes=[0, 25, 50], speed_covariance=PHI)
    for cov in pre.covariance:
        np.testing.assert_array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() > 0


@pytest.mark.parametrize("cal", [(1.0, 1.0), (1.1, 0.93),
                                 (1.0, 1.0, 0.0), (1.1, 0.93, 0.08)])   # (s, g[, kappa])
def test_calibration_jacobian_matches_central_differences(cal, rng):
    speeds = _speeds(rng, 200, turn=2.5)      # the second interval turns by more than pi
    kf = [0, 60, 200]
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI, calibration=cal)
    h = 1e-6
    for col in range(len(cal)):
        step = np.zeros(len(cal))
        step[col] = h
        hi = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI, calibration=cal + step)
        lo = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI, calibration=cal - step)
        for k in range(2):
            mean = gtsam.Pose2(*pre.delta_pose[k])
            num = (mean.localCoordinates(gtsam.Pose2(*hi.delta_pose[k]))
                   - mean.localCoordinates(gtsam.Pose2(*lo.delta_pose[k]))) / (2 * h)
            np.testing.assert_allclose(pre.calibration_jacobian[k, :, col], num, atol=1e-7)


def test_first_order_correction_is_exact_in_the_speed_scale(rng):
    speeds = _speeds(rng, 100)
    pre = preintegrate(speeds, DT, keyframes=[0, 100], speed_covariance=PHI)
    scaled = preintegrate(speeds, DT, keyframes=[0, 100], speed_covariance=PHI,
                          calibration=(1.1, 1.0))
    exact = gtsam.Pose2(*pre.delta_pose[0]).localCoordinates(gtsam.Pose2(*scaled.delta_pose[0]))
    np.testing.assert_allclose(exact, pre.calibration_jacobian[0] @ [0.1, 0.0], atol=1e-12)


def test_fit_calibration_recovers_the_scale_behind_reference_poses(rng):
    speeds = _speeds(rng, 600, turn=1.2)
    kf = np.arange(0, 601, 30)
    truth = integrate_poses(speeds * [1.07, 0.96], DT)[kf]
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI)
    cal, cov = fit_calibration(pre, truth)
    np.testing.assert_allclose(cal, [1.07, 0.96], atol=2e-3)   # one Gauss-Newton step
    assert np.all(np.linalg.eigvalsh(cov) > 0)


# -- the model's speed-error covariance ---------------------------------------------------------

def test_long_run_covariance_is_the_sum_of_the_autocovariances(arx_model):
    m = arx_model
    p = scipy.linalg.solve_discrete_lyapunov(m.A, m.Q)
    total = m.C @ p @ m.C.T + m.R
    a_pow = np.eye(m.n_states)
    for _ in range(400):                      # Gamma_tau = C A^(tau-1) (A P C^T + K R)
        gamma = m.C @ a_pow @ (m.A @ p @ m.C.T + m.S)
        total += gamma + gamma.T
        a_pow = a_pow @ m.A
    np.testing.assert_allclose(speed_error_covariance(m, mode="free_run"), total, rtol=1e-9)
    np.testing.assert_array_equal(speed_error_covariance(m, mode="one_step"), m.R)
    # stationary variance is the limit of the model's own free-run error covariance
    np.testing.assert_allclose(m.output_error_covariance(400)[-1], m.C @ p @ m.C.T + m.R,
                               rtol=1e-9)


def test_preintegrate_model_uses_the_models_speeds_and_covariance(arx_model, rng):
    u = rng.uniform(-0.3, 0.3, (200, 2)).repeat(1, axis=0)
    y = arx_model.simulate(u) + 0.01 * rng.standard_normal((200, 2))
    kf = [0, 100, 200]
    for mode, speeds in (("free_run", arx_model.simulate(u)),
                         ("one_step", arx_model.predict_one_step(u, y))):
        pre = preintegrate_model(arx_model, u, keyframes=kf, mode=mode, measured_speeds=y,
                                 covariance_scale=2.0)
        ref = preintegrate(speeds, DT, keyframes=kf,
                           speed_covariance=2.0 * speed_error_covariance(arx_model, mode=mode))
        np.testing.assert_allclose(pre.delta_pose, ref.delta_pose)
        np.testing.assert_allclose(pre.covariance, ref.covariance)
    with pytest.raises(ValueError, match="measured_speeds"):
        preintegrate_model(arx_model, u, keyframes=kf, mode="one_step")
    with pytest.raises(ValueError, match="mode"):
        preintegrate_model(arx_model, u, keyframes=kf, mode="psychic")


# -- bad input -------------------------------------------------------------------------------

def test_keyframes_out_of_order_raise_keyframe_order_error():
    with pytest.raises(KeyframeOrderError, match=r"keyframes\[2\] = 10 comes after"):
        preintegrate(np.zeros((50, 2)), DT, keyframes=[0, 20, 10], speed_covariance=PHI)


def test_an_interval_with_no_samples_raises_empty_interval_error():
    with pytest.raises(EmptyIntervalError, match="holds no samples"):
        preintegrate(np.zeros((50, 2)), DT, keyframes=[0, 20, 20, 50], speed_covariance=PHI)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"keyframes": [0, 60]}, GraphInputError, r"\[0, 50\]"),
    ({"keyframes": [0]}, ShapeError, "m >= 1"),
    ({"keyframes": [0.5, 10]}, GraphInputError, "integer"),
    ({"keyframes": [0, 50], "speed_covariance": np.eye(3)}, ShapeError, r"\(2, 2\)"),
    ({"keyframes": [0, 50], "calibration": (1.0, np.nan)}, NonFiniteError, "calibration"),
])
def test_bad_preintegration_input_raises_value_errors(kwargs, error, match):
    args = {"speed_covariance": PHI, **kwargs}
    with pytest.raises(error, match=match) as info:
        preintegrate(np.zeros((50, 2)), DT, **args)
    assert issubclass(error, ValueError)
    assert isinstance(info.value, FusionError)          # the fusion package's own classes


@pytest.mark.parametrize("error", [GraphInputError, KeyframeOrderError, EmptyIntervalError,
                                   UnknownPoseError, UnknownLandmarkError])
def test_graph_errors_are_fusion_errors_and_value_errors(error):
    assert issubclass(error, FusionError) and issubclass(error, ValueError)


def test_bad_range_bearing_input_raises_fusion_errors():
    with pytest.raises(ShapeError, match="expected") as info:
        RangeBearing([1, 2], [0], [1.0, 1.0], [0.0, 0.0])
    assert isinstance(info.value, FusionError)
    with pytest.raises(FusionError, match="range_m must be positive"):
        RangeBearing([1], [0], [-1.0], [0.0])


def test_non_finite_speeds_are_refused():
    speeds = np.zeros((50, 2))
    speeds[7, 1] = np.inf
    with pytest.raises(NonFiniteError, match="speeds"):
        preintegrate(speeds, DT, keyframes=[0, 50], speed_covariance=PHI)


# -- factors -------------------------------------------------------------------------------

@pytest.fixture
def pre(rng):
    return preintegrate(_speeds(rng, 200, turn=1.5), DT, keyframes=[0, 70, 200],
                        speed_covariance=PHI, calibration=(1.02, 0.97))


def test_plain_factor_is_zero_at_directly_integrated_poses(pre, rng):
    speeds = _speeds(np.random.default_rng(20261123), 200, turn=1.5) * [1.02, 0.97]
    start = np.array([0.5, 1.0, -0.3])
    poses = integrate_poses(speeds, DT, initial_pose=start)[[0, 70, 200]]
    values = gtsam.Values()
    for i, p in enumerate(poses):
        values.insert(pose_key(i), gtsam.Pose2(*p))
    for k in range(2):
        f = motion_factor(pre, k, key_i=pose_key(k), key_j=pose_key(k + 1))
        assert isinstance(f, gtsam.BetweenFactorPose2)
        np.testing.assert_allclose(f.unwhitenedError(values), 0.0, atol=1e-12)
        np.testing.assert_allclose(f.noiseModel().covariance(), pre.covariance[k], rtol=1e-9)


@pytest.mark.parametrize("k", [0, 1])
@pytest.mark.parametrize("cal", [(1.02, 0.97), (1.12, 0.9)])
def test_calibrated_factor_jacobians_match_numerical_derivatives(pre, k, cal, rng):
    f = calibrated_motion_factor(pre, k, key_i=pose_key(0), key_j=pose_key(1),
                                 key_c=calibration_key(0))
    values = factor_values(pre, k, rng, cal=cal)
    sqrt_info = np.linalg.cholesky(np.linalg.inv(pre.covariance[k])).T
    a_whitened, _ = f.linearize(values).jacobian()
    analytic = np.linalg.solve(sqrt_info, a_whitened)          # unwhiten
    cols = {pose_key(0): slice(0, 3), pose_key(1): slice(3, 6), calibration_key(0): slice(6, 8)}
    for key, sl in cols.items():
        x0 = values.atPoint2(key) if key == calibration_key(0) else values.atPose2(key)

        def error_at(x, key=key):
            moved = gtsam.Values(values)
            moved.update(key, x)
            return f.unwhitenedError(moved)

        numeric = numericalDerivative11(error_at, x0)
        np.testing.assert_allclose(analytic[:, sl], numeric, atol=1e-8)


def test_calibrated_factor_equals_the_plain_one_at_the_linearisation_point(pre, rng):
    values = factor_values(pre, 1, rng, cal=pre.calibration)
    plain = motion_factor(pre, 1, key_i=pose_key(0), key_j=pose_key(1))
    cal = calibrated_motion_factor(pre, 1, key_i=pose_key(0), key_j=pose_key(1),
                                   key_c=calibration_key(0))
    np.testing.assert_allclose(cal.unwhitenedError(values), plain.unwhitenedError(values),
                               atol=1e-12)
    assert cal.error(values) == pytest.approx(plain.error(values), rel=1e-9)


def test_pure_error_function_agrees_with_the_factor(pre, rng):
    values = factor_values(pre, 0, rng, cal=(1.05, 0.95))
    f = calibrated_motion_factor(pre, 0, key_i=pose_key(0), key_j=pose_key(1),
                                 key_c=calibration_key(0))
    jac = [None, None, None]
    err = calibrated_motion_error(
        values.atPose2(pose_key(0)), values.atPose2(pose_key(1)),
        values.atPoint2(calibration_key(0)),
        measured_inverse=gtsam.Pose2(*pre.delta_pose[0]).inverse(),
        calibration_jacobian=pre.calibration_jacobian[0], linearization_point=pre.calibration,
        jacobians=jac)
    np.testing.assert_allclose(err, f.unwhitenedError(values), atol=1e-14)
    np.testing.assert_allclose(jac[2], -pre.calibration_jacobian[0])


def test_calibration_walk_grows_with_the_square_root_of_time():
    f = calibration_walk_factor(calibration_key(0), calibration_key(1),
                                sigma_per_sqrt_s=[1e-3, 2e-3], duration_s=4.0)
    np.testing.assert_allclose(f.noiseModel().sigmas(), [2e-3, 4e-3])


def _pose_and_point_values(pose: gtsam.Pose2, point: np.ndarray, landmark: int = 3
                           ) -> gtsam.Values:
    values = gtsam.Values()
    values.insert(pose_key(0), pose)
    values.insert(landmark_key(landmark), point)
    return values


def test_range_bearing_model_agrees_with_gtsam():
    pose, point = gtsam.Pose2(1.0, 2.0, 2.5), np.array([-1.0, 0.5])
    b, r = predict_range_bearing(np.array([1.0, 2.0, 2.5]), point)
    assert float(b) == pytest.approx(pose.bearing(point).theta(), abs=1e-12)
    assert float(r) == pytest.approx(pose.range(point), abs=1e-12)
    [f] = range_bearing_factors(RangeBearing(0, [3], [float(r)], [float(b)]),
                                landmark_noise=LandmarkNoise())
    np.testing.assert_allclose(f.unwhitenedError(_pose_and_point_values(pose, point)), 0.0,
                               atol=1e-12)


@pytest.mark.parametrize("cov", [
    [[4e-4, 0.0], [0.0, 1e-4]],                 # diagonal
    [[4e-4, 1.5e-4], [1.5e-4, 1e-4]],           # correlated
    [[4e-8, 6e-9], [6e-9, 2e-9]],               # correlated and tiny (ArUco-like): kept
])
def test_range_bearing_factor_error_is_the_mahalanobis_distance_in_range_bearing_order(cov):
    """gtsam orders the measurement (bearing, range); the row's covariance is (range, bearing).
    The factor's error must be 0.5 d^T C^-1 d with d = (r - r_hat, wrap(b - b_hat))."""
    cov = np.array(cov)
    pose, point = gtsam.Pose2(0.3, -0.2, 0.4), np.array([2.0, 1.0])
    b_hat, r_hat = (float(v) for v in predict_range_bearing(np.array([0.3, -0.2, 0.4]), point))
    d = np.array([0.7, -1.3]) * np.sqrt(np.diag(cov))         # (range, bearing) errors
    [f] = range_bearing_factors(RangeBearing(0, [3], [r_hat + d[0]], [b_hat + d[1]], cov=[cov]),
                                landmark_noise=LandmarkNoise())
    values = _pose_and_point_values(pose, point)
    assert f.error(values) == pytest.approx(0.5 * d @ np.linalg.solve(cov, d), rel=1e-7)
    np.testing.assert_allclose(f.noiseModel().covariance(), cov[::-1, ::-1], rtol=1e-12)


def test_range_bearing_factors_use_the_sensor_noise_without_a_covariance():
    """``cov=None``: the LandmarkNoise at the measured range, as ``Diagonal.Sigmas((b, r))``
    (exactly the sigmas a diagonal model of the noise has), with a Huber kernel on request."""
    noise = LandmarkNoise(range_std_frac=0.02, range_std_m=0.005, bearing_std_rad=0.01)
    obs = RangeBearing([1, 2, 2], [4, 5, 4], [3.0, 0.1, 3.0], [0.1, -0.2, 0.3])
    factors = range_bearing_factors(obs, landmark_noise=noise)
    assert [gtsam.Symbol(f.keys()[0]).index() for f in factors] == [1, 2, 2]
    assert [gtsam.Symbol(f.keys()[1]).index() for f in factors] == [4, 5, 4]
    assert factors[0].noiseModel().sigmas().tolist() == [0.01, 0.06]
    assert factors[1].noiseModel().sigmas().tolist() == [0.01, 0.005]
    assert factors[2].noiseModel() is factors[0].noiseModel()          # shared, same cov
    robust = range_bearing_factors(obs, landmark_noise=noise, huber_k=1.5)
    assert isinstance(robust[0].noiseModel(), gtsam.noiseModel.Robust)
    with pytest.raises(LandmarkIdError, match=r"integer id \(gtsam L\(id\)\); got \['door'\]"):
        range_bearing_factors(RangeBearing(0, ["door"], [1.0], [0.0]), landmark_noise=noise)


def test_observed_landmarks_are_in_range_and_in_view(rng):
    lm = LandmarkMap.from_arrays(np.arange(4), [[1.0, 0.0], [0.1, 0.0], [-1.0, 0.0], [5.0, 0.0]])
    obs = observe_landmarks(np.zeros((3, 3)), lm, rng=rng, bearing_sigma_rad=1e-3,
                            range_sigma_m=1e-3, max_range_m=3.0, field_of_view_rad=np.pi)
    # only landmark 0: 1 too close, 2 behind, 3 too far
    assert obs.landmark_id.tolist() == [0, 0, 0] and obs.index.tolist() == [0, 1, 2]
    np.testing.assert_allclose(obs.range_m, 1.0, atol=5e-3)
    np.testing.assert_array_equal(obs.cov, np.broadcast_to(np.diag([1e-6, 1e-6]), (3, 2, 2)))


def test_landmark_map_and_observations_check_their_input():
    with pytest.raises(LandmarkIdError, match=r"distinct; repeated: \[1\]"):
        LandmarkMap.from_arrays([1, 1], [[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ShapeError, match=r"\(2, 2\)"):
        LandmarkMap.from_arrays([1, 2], [[0.0, 0.0]])
    with pytest.raises(LandmarkIdError, match="integer id"):
        LandmarkMap.from_arrays(["door"], [[0.0, 0.0]])
    with pytest.raises(LandmarkIdError, match="'door'"):      # the graph needs integer ids
        observe_landmarks(np.zeros((1, 3)), LandmarkMap({"door": (1.0, 0.0)}),
                          rng=np.random.default_rng(0), bearing_sigma_rad=0.01,
                          range_sigma_m=0.01, max_range_m=3.0)
    with pytest.raises(ValueError, match="positive"):
        RangeBearing([0], [1], [-1.0], [0.1])
    with pytest.raises(NonFiniteError, match="bearing_rad"):
        RangeBearing([0], [1], [1.0], [np.nan])


def test_preintegrated_slicing_keeps_the_keyframes_consistent(pre):
    one = pre[1]
    assert isinstance(one, Preintegrated) and len(one) == 1
    assert one.keyframes.tolist() == [70, 200]
    np.testing.assert_array_equal(one.delta_pose[0], pre.delta_pose[1])
    with pytest.raises(IndexError):
        pre[::2]


# -- the vectorised Pose2 helpers and the group factor ----------------------------------------

@pytest.mark.parametrize("pose", [(0.3, -0.2, 0.4), (1.0, 2.0, 3.0), (-0.5, 0.1, -np.pi + 1e-3),
                                  (0.3, -0.1, np.pi), (0.2, 0.1, 0.0), (0.2, 0.1, 3e-6),
                                  (0.2, 0.1, -2e-5)])
def test_vectorised_pose2_log_and_its_derivative_match_gtsam(pose):
    p = np.array(pose)
    np.testing.assert_allclose(pose2_log(p[None])[0], gtsam.Pose2.Logmap(gtsam.Pose2(*p)),
                               atol=1e-12)
    np.testing.assert_allclose(pose2_log_derivative(p[None])[0], gtsam.Pose2.LogmapDerivative(p),
                               atol=1e-9)


def test_pure_error_equals_gtsams_between_and_logmap(pre, rng):
    values = factor_values(pre, 1, rng, cal=(1.05, 0.95))
    wTi, wTj = values.atPose2(pose_key(0)), values.atPose2(pose_key(1))
    c = values.atPoint2(calibration_key(0))
    m_inv = gtsam.Pose2(*pre.delta_pose[1]).inverse()
    expected = (gtsam.Pose2.Logmap(m_inv.compose(wTi.between(wTj)))
                - pre.calibration_jacobian[1] @ (c - pre.calibration))
    err = calibrated_motion_error(wTi, wTj, c, measured_inverse=m_inv,
                                  calibration_jacobian=pre.calibration_jacobian[1],
                                  linearization_point=pre.calibration)
    np.testing.assert_allclose(err, expected, atol=1e-13)


@pytest.fixture
def group(rng):
    """Three intervals, the last a spin of 4 rad (more than pi), and poses off their motion."""
    speeds = np.concatenate([_speeds(rng, 120, turn=1.5), np.tile([0.05, 2.0], (133, 1))])
    pre = preintegrate(speeds, DT, keyframes=[0, 50, 120, 253], speed_covariance=PHI,
                       calibration=(1.02, 0.97))
    values = group_values(pre, rng, [1.08, 0.93])
    return pre, values


def test_group_factor_is_the_sum_of_its_intervals_factors(group):
    pre, values = group
    keys = [pose_key(i) for i in range(4)]
    g = calibrated_motion_group_factor(pre, pose_keys=keys, key_c=calibration_key(0))
    singles = [calibrated_motion_factor(pre, k, key_i=keys[k], key_j=keys[k + 1],
                                        key_c=calibration_key(0)) for k in range(3)]
    np.testing.assert_allclose(g.unwhitenedError(values),
                               np.concatenate([f.unwhitenedError(values) for f in singles]),
                               atol=1e-13)
    assert g.error(values) == pytest.approx(sum(f.error(values) for f in singles), rel=1e-10)
    # the same intervals given as separate preintegrations (other linearisation points)
    parts = calibrated_motion_group_factor([pre[0], pre[1:]], pose_keys=keys,
                                           key_c=calibration_key(0))
    assert parts.error(values) == pytest.approx(g.error(values), rel=1e-12)
    with pytest.raises(ShapeError, match="3 intervals need 4 pose keys, got 3"):
        calibrated_motion_group_factor(pre, pose_keys=keys[:3], key_c=calibration_key(0))


def test_group_factor_jacobians_match_numerical_derivatives(group):
    pre, values = group
    keys = [pose_key(i) for i in range(4)] + [calibration_key(0)]
    g = calibrated_motion_group_factor(pre, pose_keys=keys[:4], key_c=keys[4])
    cov = scipy.linalg.block_diag(*pre.covariance)
    a_whitened, _ = g.linearize(values).jacobian()
    analytic = np.linalg.solve(np.linalg.cholesky(np.linalg.inv(cov)).T, a_whitened)
    for m, key in enumerate(keys):
        x0 = values.atPoint2(key) if m == 4 else values.atPose2(key)

        def error_at(x, key=key):
            moved = gtsam.Values(values)
            moved.update(key, x)
            return g.unwhitenedError(moved)

        numeric = numericalDerivative11(error_at, x0)
        np.testing.assert_allclose(analytic[:, 3 * m:3 * m + numeric.shape[1]], numeric,
                                   atol=1e-8)


MOUNTS = [SensorPose(0.15, 0.0, 0.0), SensorPose(-0.1, 0.06, 0.5)]


@pytest.mark.parametrize("mount", MOUNTS, ids=repr)
@pytest.mark.parametrize("cov", [None, [[4e-4, 1.5e-4], [1.5e-4, 1e-4]]])
def test_mounted_range_bearing_factor_jacobians_match_numerical_derivatives(mount, cov):
    rng = np.random.default_rng(21)
    for _ in range(5):
        pose = gtsam.Pose2(*rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi))
        point = rng.uniform(-4, 4, 2)
        obs = RangeBearing(0, [3], [2.0], [0.3], cov=None if cov is None else [cov],
                           sensor_pose=mount)
        [f] = range_bearing_factors(obs, landmark_noise=LandmarkNoise())
        assert isinstance(f, gtsam.CustomFactor)
        values = _pose_and_point_values(pose, point)
        sqrt_info = np.linalg.cholesky(np.linalg.inv(f.noiseModel().covariance())).T
        a_whitened, _ = f.linearize(values).jacobian()
        analytic = np.linalg.solve(sqrt_info, a_whitened)          # unwhiten
        for key, sl, x0 in ((pose_key(0), slice(0, 3), pose),
                            (landmark_key(3), slice(3, 5), point)):
            def error_at(x, key=key, values=values, f=f):
                moved = gtsam.Values(values)
                moved.update(key, x)
                return f.unwhitenedError(moved)

            np.testing.assert_allclose(analytic[:, sl], numericalDerivative11(error_at, x0),
                                       atol=1e-8)


def test_mounted_factor_is_zero_at_the_truth_and_centred_it_is_gtsams_own():
    pose, point = gtsam.Pose2(0.3, -0.2, 0.4), np.array([2.0, 1.0])
    values = _pose_and_point_values(pose, point)
    mount = MOUNTS[1]
    b, r = predict_range_bearing(np.array([0.3, -0.2, 0.4]), point, sensor_pose=mount)
    sensor = pose.compose(gtsam.Pose2(mount.x_m, mount.y_m, mount.yaw_rad))
    assert float(b) == pytest.approx(sensor.bearing(point).theta(), abs=1e-12)
    assert float(r) == pytest.approx(sensor.range(point), abs=1e-12)
    [f] = range_bearing_factors(RangeBearing(0, [3], [float(r)], [float(b)], sensor_pose=mount),
                                landmark_noise=LandmarkNoise())
    np.testing.assert_allclose(f.unwhitenedError(values), 0.0, atol=1e-12)
    noise = gtsam.noiseModel.Gaussian.Covariance(np.array([[1e-4, 2e-5], [2e-5, 4e-4]]), False)
    ours = mounted_range_bearing_factor(pose_key(0), landmark_key(3), 2.3, 0.1,
                                        sensor_pose=SensorPose(), noise=noise)
    native = gtsam.BearingRangeFactor2D(pose_key(0), landmark_key(3), gtsam.Rot2(0.1), 2.3, noise)
    np.testing.assert_allclose(ours.unwhitenedError(values), native.unwhitenedError(values),
                               atol=1e-12)
    a, _ = ours.linearize(values).jacobian()
    n, _ = native.linearize(values).jacobian()
    np.testing.assert_allclose(a, n, rtol=1e-9, atol=1e-9)
