"""The smoother's curvature calibration ``kappa`` (docs/factor_graph.md): preintegration, factors,
graph, and the intrinsics it implies; every Jacobian against a numerical derivative."""

import gtsam
import numpy as np
import pytest
import scipy.linalg
from graph_scenes import DT, PHI, factor_values, feed_online, group_values, ring_sightings
from graph_scenes import speeds as _speeds
from gtsam.utils.numerical_derivative import numericalDerivative11

from fusion.exceptions import GraphInputError
from fusion.graph.factors import (
    calibrated_motion_factor,
    calibrated_motion_group_factor,
    calibration_key,
    calibration_walk_factor,
    pose_key,
)
from fusion.graph.preintegration import compose_motions, fit_calibration, preintegrate
from fusion.graph.smoother import (
    IncrementalSmoother,
    SmootherOptions,
    calibration_intrinsics_estimate,
    smooth_batch,
)
from fusion.noise import ScaleErrors
from fusion.scale_errors import intrinsics_estimate
from lti_motion.exceptions import ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import integrate_poses
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel

B = 0.235



def _true_speeds(speeds, cal):
    """``(s v, g w + kappa v)``: the EKF's ``D_c s`` (fusion.ekf.functions)."""
    s, g, kappa = cal
    return np.column_stack([s * speeds[:, 0], g * speeds[:, 1] + kappa * speeds[:, 0]])


# -- preintegration ----------------------------------------------------------------------------

@pytest.mark.parametrize("cal", [(1.0, 1.0, 0.0), (1.1, 0.93, 0.08), (0.97, 1.02, -0.3)])
def test_mean_and_covariance_are_those_of_the_true_speeds(cal, rng):
    """Preintegrating at ``(s, g, kappa)`` is preintegrating ``D_c s`` with ``D_c Phi D_c^T``."""
    speeds = _speeds(rng, 200, turn=2.5)
    kf = [0, 60, 200]
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI, calibration=cal)
    d_c = np.array([[cal[0], 0.0], [cal[2], cal[1]]])
    ref = preintegrate(_true_speeds(speeds, cal), DT, keyframes=kf,
                       speed_covariance=d_c @ PHI @ d_c.T)
    np.testing.assert_allclose(pre.delta_pose, ref.delta_pose, atol=1e-14)
    np.testing.assert_allclose(pre.covariance, ref.covariance, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(pre.delta_pose[-1], integrate_poses(
        _true_speeds(speeds[60:], cal), DT, initial_pose=np.zeros(3))[-1], atol=1e-12)
    assert pre.calibration_jacobian.shape == (2, 3, 3)


# the kappa column against central differences: test_factors.py, with (s, g)


def test_without_kappa_the_first_two_columns_are_unchanged(rng):
    speeds = _speeds(rng, 150)
    two = preintegrate(speeds, DT, keyframes=[0, 70, 150], speed_covariance=PHI,
                       calibration=(1.02, 0.97))
    three = preintegrate(speeds, DT, keyframes=[0, 70, 150], speed_covariance=PHI,
                         calibration=(1.02, 0.97, 0.0))
    np.testing.assert_array_equal(three.calibration_jacobian[..., :2], two.calibration_jacobian)
    np.testing.assert_array_equal(three.delta_pose, two.delta_pose)
    np.testing.assert_array_equal(three.covariance, two.covariance)
    with pytest.raises(ShapeError, match=r"shape \(2,\) or \(3,\), got \(4,\)"):
        preintegrate(speeds, DT, keyframes=[0, 150], speed_covariance=PHI,
                     calibration=(1.0, 1.0, 0.0, 0.0))


def test_fit_calibration_recovers_a_diameter_ratio_behind_reference_poses(rng):
    """A 1% ratio is ``kappa = 0.01 / b``; the Gauss-Newton step from (1, 1, 0) finds it."""
    speeds = _speeds(rng, 1200, turn=1.2)
    kf = np.arange(0, 1201, 30)
    truth_cal = (1.004, 0.99, 0.01 / B)
    truth = integrate_poses(_true_speeds(speeds, truth_cal), DT)[kf]
    pre = preintegrate(speeds, DT, keyframes=kf, speed_covariance=PHI, calibration=(1, 1, 0))
    cal, cov = fit_calibration(pre, truth)
    np.testing.assert_allclose(cal, truth_cal, atol=2e-3)
    assert cov.shape == (3, 3)


# -- factors -----------------------------------------------------------------------------------

@pytest.fixture
def pre3(rng):
    return preintegrate(_speeds(rng, 200, turn=1.5), DT, keyframes=[0, 70, 200],
                        speed_covariance=PHI, calibration=(1.02, 0.97, 0.02))


def _check_jacobians(factor, values, keys, cov):
    a_whitened, _ = factor.linearize(values).jacobian()
    analytic = np.linalg.solve(np.linalg.cholesky(np.linalg.inv(cov)).T, a_whitened)
    col = 0
    for key in keys:
        is_cal = gtsam.Symbol(key).chr() == ord("c")
        x0 = values.atPoint3(key) if is_cal else values.atPose2(key)

        def error_at(x, key=key):
            moved = gtsam.Values(values)
            moved.update(key, x)
            return factor.unwhitenedError(moved)

        numeric = numericalDerivative11(error_at, x0)
        np.testing.assert_allclose(analytic[:, col:col + numeric.shape[1]], numeric, atol=1e-8)
        col += numeric.shape[1]
    assert col == analytic.shape[1]


@pytest.mark.parametrize("k", [0, 1])
@pytest.mark.parametrize("cal", [(1.02, 0.97, 0.02), (1.12, 0.9, -0.2)])
def test_calibrated_factor_with_kappa_jacobians_match_numerical_derivatives(pre3, k, cal, rng):
    f = calibrated_motion_factor(pre3, k, key_i=pose_key(0), key_j=pose_key(1),
                                 key_c=calibration_key(0))
    values = factor_values(pre3, k, rng, cal=cal)
    _check_jacobians(f, values, [pose_key(0), pose_key(1), calibration_key(0)],
                     pre3.covariance[k])


def test_group_factor_with_kappa_jacobians_match_numerical_derivatives(rng):
    speeds = np.concatenate([_speeds(rng, 120, turn=1.5), np.tile([0.05, 2.0], (133, 1))])
    pre = preintegrate(speeds, DT, keyframes=[0, 50, 120, 253], speed_covariance=PHI,
                       calibration=(1.02, 0.97, -0.05))
    values = group_values(pre, rng, [1.08, 0.93, 0.1])
    keys = [pose_key(i) for i in range(4)]
    g = calibrated_motion_group_factor(pre, pose_keys=keys, key_c=calibration_key(0))
    _check_jacobians(g, values, [*keys, calibration_key(0)],
                     scipy.linalg.block_diag(*pre.covariance))
    singles = [calibrated_motion_factor(pre, k, key_i=keys[k], key_j=keys[k + 1],
                                        key_c=calibration_key(0)) for k in range(3)]
    assert g.error(values) == pytest.approx(sum(f.error(values) for f in singles), rel=1e-10)


def test_first_order_correction_in_kappa_is_close_to_integrating_again(rng):
    """A 1% diameter ratio over a 0.5 s interval: the first-order update (Forster et al. eq. 44)
    against preintegrating at the new curvature, to well under a millimetre."""
    speeds = _speeds(rng, 33, turn=1.0)
    base = preintegrate(speeds, DT, keyframes=[0, 33], speed_covariance=PHI,
                        calibration=(1.0, 1.0, 0.0))
    moved = preintegrate(speeds, DT, keyframes=[0, 33], speed_covariance=PHI,
                         calibration=(1.0, 1.0, 0.01 / B))
    exact = gtsam.Pose2(*base.delta_pose[0]).localCoordinates(gtsam.Pose2(*moved.delta_pose[0]))
    first = base.calibration_jacobian[0] @ [0.0, 0.0, 0.01 / B]
    np.testing.assert_allclose(first, exact, atol=2e-6)
    assert abs(exact[2]) > 1e-3                              # the correction is not nothing


def test_a_group_of_mixed_calibration_sizes_is_refused(rng):
    speeds = _speeds(rng, 100)
    two = preintegrate(speeds, DT, keyframes=[0, 50], speed_covariance=PHI)
    three = preintegrate(speeds[50:], DT, keyframes=[0, 50], speed_covariance=PHI,
                         calibration=(1, 1, 0))
    with pytest.raises(ShapeError, match="calibrations of one size"):
        calibrated_motion_group_factor([two, three], pose_keys=[pose_key(i) for i in range(3)],
                                       key_c=calibration_key(0))


def test_calibration_walk_on_three_entries():
    f = calibration_walk_factor(calibration_key(0), calibration_key(1),
                                sigma_per_sqrt_s=(1e-3, 1e-3, 4e-3), duration_s=4.0)
    assert isinstance(f, gtsam.BetweenFactorPoint3)
    np.testing.assert_allclose(np.sqrt(np.diag(f.noiseModel().covariance())),
                               [2e-3, 2e-3, 8e-3])


# -- options and the graph ---------------------------------------------------------------------

def test_with_curvature_takes_the_ekfs_prior_walk_and_bound():
    scales = ScaleErrors(ratio_prior_std=0.02, ratio_walk_per_sqrt_s=3e-4)
    opts = SmootherOptions(calibration_prior_sigmas=(0.01, 0.01)).with_curvature(
        wheel_base_m=B, scales=scales)
    assert opts.n_calibration == 3 and opts.calibration_prior == (1.0, 1.0, 0.0)
    assert opts.calibration_prior_sigmas == pytest.approx((0.01, 0.01, scales.prior_stds(B)[2]))
    assert opts.calibration_walk_sigmas[2] == pytest.approx(scales.walk_rates(B)[2])
    assert opts.curvature_bound_rad_per_m == pytest.approx(0.1 / B)
    np.testing.assert_allclose(opts.bounded_calibration([1.0, 1.0, 0.9]), [1, 1, 0.1 / B])
    np.testing.assert_array_equal(opts.bounded_calibration([1.0, 1.0, -0.3]), [1, 1, -0.3])


@pytest.mark.parametrize("kwargs, match", [
    ({"calibration_prior": (1.0, 1.0, 0.0)}, "calibration_prior_sigmas"),
    ({"calibration_prior": (1.0,)}, "calibration_prior"),
    ({"calibration_prior": (1.0, 1.0, np.nan), "calibration_prior_sigmas": (1, 1, 1),
      "calibration_walk_sigmas": (1, 1, 1)}, "finite"),
    ({"curvature_bound_rad_per_m": 0.0}, "curvature_bound_rad_per_m"),
])
def test_bad_curvature_options_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SmootherOptions(**kwargs)


def test_motion_preintegrated_without_kappa_is_refused_by_a_kappa_smoother(rng):
    pre = preintegrate(_speeds(rng, 100), DT, keyframes=[0, 50, 100], speed_covariance=PHI)
    sm = IncrementalSmoother(initial_pose=np.zeros(3),
                             options=SmootherOptions().with_curvature(wheel_base_m=B))
    with pytest.raises(GraphInputError, match=r"estimates \(s, g, kappa\) but the motion was "
                                              r"preintegrated with calibration \[1.0, 1.0\]"):
        sm.add_motion(pre)


def _ratio_drive(n_intervals, cal):
    """Arcs and straights preintegrated at (1, 1, 0) while the robot really moves with
    ``cal``, seen from a ring of landmarks at every keyframe (noise-free)."""
    n = 50 * n_intervals
    t = np.arange(n) * 0.01
    speeds = np.column_stack([np.full(n, 0.25), 0.8 * np.sin(t / 3.0) ** 3])
    kf = np.arange(0, n + 1, 50)
    pre = preintegrate(speeds, 0.01, keyframes=kf, speed_covariance=np.eye(2) * 1e-5,
                       calibration=(1.0, 1.0, 0.0))
    truth = compose_motions(preintegrate(_true_speeds(speeds, cal), 0.01, keyframes=kf,
                                         speed_covariance=np.eye(2) * 1e-5).delta_pose,
                            initial_pose=np.zeros(3))
    obs, lm = ring_sightings(truth)
    return pre, obs, lm, truth


def test_smoothers_recover_a_diameter_ratio_online_and_in_batch():
    """1% ratio (kappa = 0.0426 rad/m) and 2% more travel: iSAM2 group by group, and the batch
    graph, find both; the smoother without kappa cannot and ends further from the truth."""
    cal = (1.02, 1.0, 0.01 / B)
    pre, obs, lm, truth = _ratio_drive(30, cal)
    opts = SmootherOptions(calibration_walk_sigmas=(1e-4, 1e-4)).with_curvature(wheel_base_m=B)
    sm = feed_online(IncrementalSmoother(initial_pose=np.zeros(3), landmarks=lm, options=opts),
                     pre, obs)
    online = sm.result()
    batch = smooth_batch(pre, initial_pose=np.zeros(3), observations=obs, landmarks=lm,
                         options=opts)
    assert online.calibrations.shape == (len(pre) + 1, 3)
    # noise-free sightings: both within 0.02% of the truth (kappa: 0.5% of its value);
    # iSAM2 keeps older poses at their first linearisation (relinearize_threshold 0.1), the
    # batch solves to convergence, so they differ by 1e-4 (s) here, not by 1e-5 as they do
    # with (s, g) alone (test_smoother.py)
    np.testing.assert_allclose(online.calibrations[-1], cal, atol=2e-4)
    np.testing.assert_allclose(batch.calibrations[-1], cal, atol=2e-4)
    sigma = np.sqrt(online.calibration_covariances[-1, 2, 2])
    assert sigma < 0.1 * opts.calibration_prior_sigmas[2]          # the landmarks taught it
    without = smooth_batch(_ratio_drive_2d(pre), initial_pose=np.zeros(3), observations=obs,
                           landmarks=lm, options=SmootherOptions(
                               calibration_walk_sigmas=(1e-4, 1e-4)))
    err_with = np.linalg.norm(batch.poses[:, :2] - truth[:, :2], axis=1).max()
    err_without = np.linalg.norm(without.poses[:, :2] - truth[:, :2], axis=1).max()
    assert err_with < 0.5 * err_without, (err_with, err_without)


def _ratio_drive_2d(pre3):
    """The same intervals as a (s, g) preintegration (the first two Jacobian columns)."""
    from fusion.graph.preintegration import Preintegrated

    return Preintegrated(pre3.keyframes, pre3.duration_s, pre3.delta_pose, pre3.covariance,
                         pre3.calibration_jacobian[..., :2], pre3.calibration[:2])


# -- the intrinsics it implies -----------------------------------------------------------------

def test_calibration_intrinsics_estimate_is_the_ekfs_of_the_shifted_scales(rng):
    k = OdometryIntrinsics(4.41e-4, 4.39e-4, 0.236)
    cal = np.array([1.004, 0.993, 0.03])
    a = rng.standard_normal((3, 3)) * 1e-3
    cov = a @ a.T
    got = calibration_intrinsics_estimate(k, cal, cov, t_s=12.0)
    ref = intrinsics_estimate(k, cal - [1.0, 1.0, 0.0], cov, t_s=12.0)
    assert got.intrinsics == ref.intrinsics and got.t_s == 12.0
    np.testing.assert_allclose(got.covariance, ref.covariance, rtol=1e-12)
    assert got.diameter_ratio_std == pytest.approx(ref.diameter_ratio_std, rel=1e-12)
    # without kappa: no ratio information, the ratio of the intrinsics in use
    two = calibration_intrinsics_estimate(k, cal[:2], cov[:2, :2])
    assert two.diameter_ratio_std == pytest.approx(0.0, abs=1e-12)
    assert two.intrinsics.diameter_ratio == pytest.approx(k.diameter_ratio, rel=1e-12)
    with pytest.raises(ValueError, match="square covariance"):
        calibration_intrinsics_estimate(k, cal, cov[:2, :2])


def test_a_smoothers_intrinsics_write_back_into_the_model(rng):
    """The online estimate of the ratio drive gives intrinsics 1% apart, left over right."""
    cal = (1.0, 1.0, 0.01 / B)
    pre, obs, lm, _ = _ratio_drive(20, cal)
    sm = feed_online(IncrementalSmoother(initial_pose=np.zeros(3), landmarks=lm,
                                         options=SmootherOptions().with_curvature(wheel_base_m=B)),
                     pre, obs)
    k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=B)
    est = sm.intrinsics_estimate(k)
    # kappa = (m_R' - m_L') / (m b') to first order: a 1% ratio, right over left
    assert 1.0 / est.intrinsics.diameter_ratio == pytest.approx(1.01, abs=2e-3)
    assert est.diameter_ratio_std < 1e-3
    res = sm.result()
    again = res.intrinsics_estimate(k)
    assert again.intrinsics.diameter_ratio == pytest.approx(est.intrinsics.diameter_ratio,
                                                            abs=1e-6)
    model = MotionModel.from_fir(
        FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
               residual_cov=np.eye(2) * 1e-6, n_samples=100, source="steps"),
        dt_s=DT, wheel_base_m=B, m_per_tick=4.4e-4, calibrated_at="2026-01-01T00:00:00+00:00")
    written = model.with_intrinsics(est.intrinsics)
    assert written.intrinsics == est.intrinsics
    with pytest.raises(ValueError, match="calibrations with covariances"):
        smooth_batch(pre, initial_pose=np.zeros(3), observations=obs, landmarks=lm,
                     options=SmootherOptions().with_curvature(wheel_base_m=B),
                     covariances=False).intrinsics_estimate(k)
