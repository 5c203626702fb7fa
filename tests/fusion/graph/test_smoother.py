"""The smoother on the simulator, against its ground truth: the factor-graph acceptance runs.

One ARX model is calibrated per module on the nominal Create 2 (hard floor) and reused.
Runs are 20 simulated robots driving for 60 s among known landmarks (the example's
waypoint driver and camera model, ``examples/factor_graph.py``).

The "true" calibration of a run is what the calibration-aware factors would estimate if
every keyframe pose were known exactly: :func:`fusion.graph.fit_calibration` on
the true keyframe poses. On the nominal robot it is ``s = 1.004``: the encoder scale
from the rotation manoeuvre (paper eq. 13) uses the nominal wheel base, 0.4% short of the
true one, so encoder (and model) speeds are 0.4% low. With wheels 10% larger than the
model was calibrated with (``wheel_diameter_errors=(0.1, 0.1)``) the speed loop still
holds the commanded wheel rotation, so every tick carries 10% more ground:
``s = 1.1 x 1.004 = 1.104`` in geometry; measured 1.102 (a little more slip; checked below).

The paper: ``docs/architecture.md``, "The paper".
"""

from dataclasses import dataclass, replace

import gtsam
import numpy as np
import pytest
from graph_scenes import feed_online, ring_sightings
from scipy import stats

from drivers.sim.config import Fault, get_preset
from fusion.exceptions import (
    EmptyIntervalError,
    KeyframeOrderError,
    LandmarkIdError,
    UnknownPoseError,
)
from fusion.graph.factors import observe_landmarks
from fusion.graph.preintegration import (
    Preintegrated,
    compose_motions,
    fit_calibration,
    preintegrate,
    preintegrate_model,
)
from fusion.graph.smoother import (
    IncrementalSmoother,
    SmootherOptions,
    SmootherResult,
    log_keyframes,
    smooth_batch,
    smooth_log,
    smoother_ates,
)
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing, range_bearing
from fusion.sensor_pose import CENTRED, SensorPose
from lti_motion.calibration.manoeuvres import speeds_from_log
from lti_motion.metrics import ate

N_RUNS = 20
DURATION_S = 60.0


@pytest.fixture(scope="module")
def example(load_example):
    return load_example("factor_graph")


@pytest.fixture(scope="module")
def calibration(example):
    return example.calibrated_model_and_noise()


@pytest.fixture(scope="module")
def model(calibration):
    return calibration[0]


@pytest.fixture(scope="module")
def phi(calibration):
    """Long-run speed covariance measured on the model's calibration logs, conditioned on its
    wheel tracking error, plus the EKF's ground-slip prior (no hand factor;
    fusion.graph.transient_noise)."""
    return calibration[1]


@pytest.fixture(scope="module")
def landmarks(example):
    return example.landmark_grid()


@dataclass(frozen=True)
class Run:
    log: object
    obs: RangeBearing
    result: SmootherResult
    pre: Preintegrated          # on the result's keyframes
    truth: np.ndarray           # true keyframe poses

    @property
    def dead_reckoning(self) -> np.ndarray:
        return compose_motions(self.pre.delta_pose, initial_pose=self.log.true_pose[0])


def _drive_and_smooth(example, model, phi, landmarks, robot, *, seed, duration_s=DURATION_S,
                      faults=(), n_runs=N_RUNS):
    batch = example.drive(robot, n_robots=n_runs, seed=seed, duration_s=duration_s,
                          faults=faults)
    runs = []
    for r in range(n_runs):
        log = batch.robot(r)
        obs = example.observe(log, landmarks, rng=np.random.default_rng(1000 * seed + r))
        res = smooth_log(model, log, initial_pose=log.true_pose[0], observations=obs,
                         landmarks=landmarks, speed_covariance=phi, covariances=True)
        u, _ = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
        pre = preintegrate_model(model, u, keyframes=res.keyframes, speed_covariance=phi)
        runs.append(Run(log, obs, res, pre, log.true_pose[res.keyframes]))
    return runs


@pytest.fixture(scope="module")
def nominal(example, model, phi, landmarks):
    return _drive_and_smooth(example, model, phi, landmarks, get_preset("create2"), seed=3)


@pytest.fixture(scope="module")
def big_wheels(example, model, phi, landmarks):
    robot = get_preset("create2", wheel_diameter_errors=(0.1, 0.1))
    return _drive_and_smooth(example, model, phi, landmarks, robot, seed=4)


# -- accuracy ------------------------------------------------------------------------------

def test_smoothed_trajectory_is_accurate_and_far_better_than_dead_reckoning(nominal):
    ates = np.array([ate(r.truth, r.result.poses) for r in nominal])
    dead = np.array([ate(r.truth, r.dead_reckoning) for r in nominal])
    assert ates.max() < 0.012, ates          # about 5 mm with 3 cm / 1 degree landmarks
    assert np.all(ates < dead / 4), (ates, dead)
    assert dead.mean() > 20 * ates.mean(), (dead.mean(), ates.mean())


def test_smoother_ates_reports_one_ate_per_run(model, phi, landmarks, nominal):
    runs = nominal[:2]
    out = smoother_ates(model, [r.log for r in runs], [r.obs for r in runs],
                        landmarks=landmarks, speed_covariance=phi)
    np.testing.assert_allclose(out, [ate(r.truth, r.result.poses) for r in runs], rtol=1e-6)


@pytest.mark.parametrize("mode", ["one_step", "filtered"])
def test_encoder_aided_speeds_also_smooth_accurately(model, landmarks, nominal, mode):
    runs = nominal[:3]
    ates = smoother_ates(model, [r.log for r in runs], [r.obs for r in runs],
                         landmarks=landmarks, mode=mode)
    assert ates.max() < 0.012, ates


# -- consistency ---------------------------------------------------------------------------

def _nees(run: Run) -> np.ndarray:
    est, cov = run.result.poses, run.result.pose_covariances
    err = np.array([gtsam.Pose2(*e).localCoordinates(gtsam.Pose2(*t))
                    for e, t in zip(est, run.truth, strict=True)])
    return np.einsum("ki,kij,kj->k", err, np.linalg.inv(cov), err)


def _keyframe_anees(runs: list[Run]) -> tuple[np.ndarray, float, float]:
    """Per-keyframe ANEES over the runs (keyframe 0, the prior, and 1 skipped) and the
    two-sided 95% interval of a consistent estimator."""
    n = min(len(r.result.keyframes) for r in runs)
    anees = np.array([_nees(r)[2:n] for r in runs]).mean(axis=0)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * len(runs)) / len(runs)
    return anees, lo, hi


def test_pose_nees_is_inside_the_95_percent_interval(nominal):
    """No hand factor: the motion factors carry the long-run covariance of the model's
    speed errors measured on its calibration logs, conditioned on the wheel tracking error
    (fusion.graph.transient_noise), plus the EKF's slip prior. Measured ANEES 2.78 (seeds 3;
    2.43-3.01 on eight design seed sets; 95% interval 2.02-4.16); with the unconditioned
    covariance 3.60 (3.13-3.84), the model's own 7-9 (docs/factor_graph.md)."""
    anees, lo, hi = _keyframe_anees(nominal)
    assert lo < anees.mean() < hi, (lo, anees.mean(), hi)


def test_few_keyframes_are_over_confident(nominal):
    """The heavy tails at sharp turns: with one long-run covariance for all driving, 26% of
    the keyframes' ANEES were above the interval (seeds 3; 14-31% on eight design sets).
    Conditioned on the transients: 4.9% (0-1.6% on the design sets)."""
    anees, _, hi = _keyframe_anees(nominal)
    assert np.mean(anees > hi) < 0.1, np.mean(anees > hi)


def test_most_keyframes_have_their_anees_inside_the_interval(nominal):
    """Measured 82.0% inside (seeds 3), 78-97% on eight design seed sets (mean 89%); the
    unconditioned covariance gave 69% (68-80%, mean 73%)."""
    anees, lo, hi = _keyframe_anees(nominal)
    assert np.mean((anees > lo) & (anees < hi)) > 0.75, np.mean((anees > lo) & (anees < hi))


@pytest.mark.xfail(strict=True, reason="known gap: 82.0% of the keyframes' ANEES inside "
                   "(seeds 3; 78-97% on eight design sets); the rest mostly *below* the "
                   "interval (13% on seeds 3): on straight driving one 0.5 s interval's "
                   "covariance is 3-4x its error (the long-run covariance is made for long "
                   "chains), while the sharpest turns stay 1.5-2x over-confident")
def test_ninety_percent_of_keyframes_have_their_anees_inside_the_interval(nominal):
    anees, lo, hi = _keyframe_anees(nominal)
    # a consistent estimator has 95% of keyframes inside
    assert np.mean((anees > lo) & (anees < hi)) >= 0.9, np.mean((anees > lo) & (anees < hi))


def test_marginal_covariances_are_symmetric_positive_definite(nominal):
    res = nominal[0].result
    for cov in (*res.pose_covariances, *res.calibration_covariances):
        np.testing.assert_allclose(cov, cov.T, atol=1e-15)
        assert np.linalg.eigvalsh(cov).min() > 0


# -- calibration ---------------------------------------------------------------------------

def _true_calibration(run: Run) -> np.ndarray:
    return fit_calibration(run.pre, run.truth)[0]


def test_true_scale_of_big_wheels_is_ten_percent_over_the_nominal_robots(nominal, big_wheels):
    s_nominal = np.mean([_true_calibration(r)[0] for r in nominal])
    s_big = np.mean([_true_calibration(r)[0] for r in big_wheels])
    assert s_nominal == pytest.approx(1.004, abs=0.002)
    # 10% more ground per tick, less about 0.2% of extra slip (more torque for the same
    # wheel acceleration)
    assert s_big / s_nominal == pytest.approx(1.10, abs=0.004)


def test_calibration_recovers_a_ten_percent_scale_change_within_one_percent_in_60_s(big_wheels):
    truth = np.array([_true_calibration(r) for r in big_wheels])
    est = np.array([r.result.calibrations[-1] for r in big_wheels])    # online, at 60 s
    sigma = np.array([np.sqrt(np.diag(r.result.calibration_covariances[-1]))
                      for r in big_wheels])
    rel = est[:, 0] / truth[:, 0] - 1.0
    assert np.abs(rel).max() < 0.01, rel
    assert np.mean(np.abs(est[:, 0] - truth[:, 0]) < 2 * sigma[:, 0]) >= 0.9
    # the yaw-rate gain moves with it (both wheels carry 10% more ground per tick)
    assert np.mean(np.abs(est[:, 1] - truth[:, 1]) < 2 * sigma[:, 1]) >= 0.8
    assert np.all(est[:, 1] > 1.04)


def test_calibration_follows_a_floor_change(example, model, phi, landmarks):
    """Hard floor to carpet at 40 s: about 4% less ground per tick (true s 1.004 -> 0.964)."""
    change_s = 40.0
    runs = _drive_and_smooth(example, model, phi, landmarks, get_preset("create2"), seed=5,
                             duration_s=120.0, n_runs=4,
                             faults=[Fault("floor", t_s=change_s, floor="carpet")])
    for run in runs:
        t = run.result.keyframes * run.log.dt_s
        cut, settled = int(np.argmax(t >= change_s)), int(np.argmax(t > change_s + 20.0))
        s_before = fit_calibration(run.pre[:cut - 1], run.truth[:cut])[0][0]
        s_after = fit_calibration(run.pre[settled:], run.truth[settled:])[0][0]
        assert s_after / s_before == pytest.approx(0.96, abs=0.01)
        est = run.result.calibrations[:, 0]
        assert est[int(np.argmax(t >= 20.0))] == pytest.approx(s_before, rel=0.01)  # smoothed
        assert est[-1] == pytest.approx(s_after, rel=0.01)         # online, 80 s after


# -- the two solvers -----------------------------------------------------------------------

def test_incremental_and_batch_smoothing_agree(model, phi, landmarks, nominal):
    run = nominal[0]
    batch = smooth_log(model, run.log, initial_pose=run.log.true_pose[0], observations=run.obs,
                       landmarks=landmarks, speed_covariance=phi,
                       method="batch", covariances=True)
    np.testing.assert_allclose(batch.poses[:, :2], run.result.poses[:, :2], atol=2e-3)
    np.testing.assert_allclose(batch.calibrations[-1], run.result.calibrations[-1], atol=2e-3)
    np.testing.assert_allclose(np.sqrt(batch.pose_covariances[:, 0, 0]),
                               np.sqrt(run.result.pose_covariances[:, 0, 0]), rtol=0.1)


def test_unknown_landmarks_are_mapped_alongside_the_path(model, phi, landmarks, nominal):
    run = nominal[1]
    res = smooth_log(model, run.log, initial_pose=run.log.true_pose[0], observations=run.obs,
                     speed_covariance=phi)      # no map given
    assert ate(run.truth, res.poses) < 0.05
    true_xy = np.array([landmarks.position(i) for i in res.landmark_ids])
    assert np.abs(res.landmarks_xy - true_xy).max() < 0.1
    # landmarks with uncertain known positions (a prior, not a constant)
    res = smooth_log(model, run.log, initial_pose=run.log.true_pose[0], observations=run.obs,
                     landmarks=landmarks, speed_covariance=phi,
                     options=SmootherOptions(landmark_sigma_m=0.05))
    assert ate(run.truth, res.poses) < 0.02


def test_a_mounted_sensor_smooths_as_well_as_a_centred_one(example, model, phi, landmarks,
                                                            nominal):
    """Sightings from a sensor 0.15 m ahead and turned 0.3 rad: with the mount, as accurate
    as the centred sensor's, also with the landmarks unknown; taken as centred, far worse."""
    run, mount = nominal[0], SensorPose(0.15, 0.0, 0.3)
    frames = np.arange(0, len(run.log) - 1, example.KEYFRAME_EVERY)
    obs = observe_landmarks(run.log.true_pose[frames], landmarks,
                            rng=np.random.default_rng(77),
                            bearing_sigma_rad=example.BEARING_SIGMA_RAD,
                            range_sigma_m=example.RANGE_SIGMA_M, max_range_m=example.MAX_RANGE_M,
                            field_of_view_rad=example.FIELD_OF_VIEW_RAD, index=frames,
                            sensor_pose=mount)
    assert obs.sensor_pose == mount

    def smooth(sightings, known=landmarks):
        return smooth_log(model, run.log, initial_pose=run.log.true_pose[0],
                          observations=sightings, landmarks=known, speed_covariance=phi)

    mounted = ate(run.truth, smooth(obs).poses)
    assert mounted < 0.012, mounted
    assert ate(run.truth, smooth(obs, known=None).poses) < 0.05      # landmarks mapped too
    centred = ate(run.truth, smooth(replace(obs, sensor_pose=CENTRED)).poses)
    assert centred > 4 * mounted, (centred, mounted)


def test_plain_model_factors_smooth_too(model, phi, landmarks, nominal):
    run = nominal[2]
    res = smooth_log(model, run.log, initial_pose=run.log.true_pose[0], observations=run.obs,
                     landmarks=landmarks, speed_covariance=phi,
                     options=SmootherOptions(calibrate=False))
    assert res.calibrations is None
    assert ate(run.truth, res.poses) < 0.012


# -- the incremental API and bad input ------------------------------------------------------

@pytest.fixture
def straight():
    return preintegrate(np.tile([0.2, 0.0], (100, 1)), 0.01, keyframes=[0, 50, 100],
                        speed_covariance=np.eye(2) * 1e-4)


def test_incremental_api_reads_poses_covariances_and_calibration(straight):
    lm = LandmarkMap({7: (0.1, 1.0)})
    sm = IncrementalSmoother(initial_pose=np.zeros(3), landmarks=lm)
    assert sm.add_motion(straight[0]) == 1
    sm.add_observations(RangeBearing([1], [7], [1.0], [np.pi / 2], cov=[np.eye(2) * 1e-4]))
    sm.update()
    assert sm.add_motion(straight[1]) == 2
    np.testing.assert_allclose(sm.pose(2), [0.2, 0.0, 0.0], atol=1e-6)   # flushes pending
    assert sm.keyframes.tolist() == [0, 50, 100]
    cov = sm.pose_covariance(2)
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)
    np.testing.assert_allclose(sm.calibration(2), [1.0, 1.0], atol=1e-6)
    assert sm.calibration_covariance(0).shape == (2, 2)
    res = sm.result()
    assert res.landmark_ids.tolist() == [7]
    np.testing.assert_allclose(res.landmarks_xy[0], [0.1, 1.0], atol=1e-5)


def test_an_unknown_landmark_starts_where_the_mounted_sensor_puts_it():
    """One noise-free sighting from a sensor 0.2 m ahead, turned 1 rad: the landmark's first
    guess (the pose composed with the mount) is the truth, so the solve leaves it there."""
    pose, mount, truth = np.array([1.0, 2.0, 0.5]), SensorPose(0.2, -0.05, 1.0), [1.5, 4.0]
    r, b = range_bearing(pose, np.array(truth), sensor=mount)
    sm = IncrementalSmoother(initial_pose=pose)
    sm.add_observations(RangeBearing(0, [9], [r], [b], cov=[np.eye(2) * 1e-4],
                                     sensor_pose=mount))
    sm.update()
    np.testing.assert_allclose(sm.result().landmarks_xy[0], truth, atol=1e-9)


def _scaled_drive(n_intervals: int, *, scale: float):
    """Arcs preintegrated at (1, 1) while the robot really moves ``scale`` times as far, seen
    from a ring of landmarks at every keyframe (noise-free observations of the truth)."""
    speeds = np.column_stack([np.full(50 * n_intervals, 0.2),
                              0.6 * np.sin(np.arange(50 * n_intervals) * 0.004)])
    kf = np.arange(0, 50 * n_intervals + 1, 50)
    pre = preintegrate(speeds, 0.01, keyframes=kf, speed_covariance=np.eye(2) * 1e-5)
    truth = compose_motions(preintegrate(speeds * [scale, 1.0], 0.01, keyframes=kf,
                                         speed_covariance=np.eye(2) * 1e-5).delta_pose,
                            initial_pose=np.zeros(3))
    obs, lm = ring_sightings(truth)
    return pre, obs, lm


@pytest.mark.parametrize("read_midway", [False, True])
def test_incremental_groups_end_as_the_batch_graph(read_midway):
    """Closed groups are group factors, the open one natives until ``result`` closes it: the
    final estimate is the batch solution of the same graph, whenever results were read."""
    pre, obs, lm = _scaled_drive(25, scale=1.05)        # 2.5 calibration groups of 10
    opts = SmootherOptions(calibration_walk_sigmas=(1e-4, 1e-4))
    sm = IncrementalSmoother(initial_pose=np.zeros(3), landmarks=lm, options=opts)

    def midway(k):
        if read_midway and k in (5, 13):               # partial group factors, replaced later
            sm.result(covariances=False)

    online = feed_online(sm, pre, obs, after_update=midway).result()
    batch = smooth_batch(pre, initial_pose=np.zeros(3), observations=obs, landmarks=lm,
                         options=opts)
    np.testing.assert_allclose(online.calibrations, batch.calibrations, atol=2e-5)
    np.testing.assert_allclose(online.poses, batch.poses, atol=1e-5)
    np.testing.assert_allclose(online.calibrations[-1, 0], 1.05, atol=2e-3)
    # marginals at iSAM2's linearisation point, not exactly the batch optimum's
    sigmas = [np.sqrt(np.diagonal(r.calibration_covariances, axis1=1, axis2=2))
              for r in (online, batch)]
    np.testing.assert_allclose(*sigmas, rtol=0.01)


def test_known_landmarks_need_integer_ids(straight):
    with pytest.raises(LandmarkIdError, match="integer id"):
        IncrementalSmoother(initial_pose=np.zeros(3), landmarks=LandmarkMap({"door": (1, 0)}))


def test_observation_of_a_missing_pose_raises_unknown_pose_error(straight):
    sm = IncrementalSmoother(initial_pose=np.zeros(3))
    sm.add_motion(straight)
    with pytest.raises(UnknownPoseError, match=r"pose 5, but the graph holds poses 0 \.\. 2"):
        sm.add_observations(RangeBearing([1, 5], [0, 0], [1.0, 1.0], [0.0, 0.0]))
    with pytest.raises(UnknownPoseError):
        sm.pose(3)
    assert issubclass(UnknownPoseError, ValueError)


def test_motion_that_does_not_continue_the_last_keyframe_raises(straight):
    sm = IncrementalSmoother(initial_pose=np.zeros(3))
    sm.add_motion(straight[0])
    with pytest.raises(KeyframeOrderError, match="starts at sample 0 but the last keyframe is "
                                                 "at sample 50"):
        sm.add_motion(straight[0])
    with pytest.raises(EmptyIntervalError):
        preintegrate(np.zeros((10, 2)), 0.01, keyframes=[0, 5, 5], speed_covariance=np.eye(2))


def test_calibration_queries_need_a_calibrating_smoother(straight):
    sm = IncrementalSmoother(initial_pose=np.zeros(3), options=SmootherOptions(calibrate=False))
    sm.add_motion(straight)
    with pytest.raises(ValueError, match="calibrate=False"):
        sm.calibration(1)


@pytest.mark.parametrize("kwargs, match", [
    ({"calibration_every": 0}, "calibration_every"),
    ({"calibration_prior_sigmas": (0.1, -1.0)}, "calibration_prior_sigmas"),
    ({"relinearize_threshold": 0.0}, "relinearize_threshold"),
    ({"landmark_sigma_m": -0.1}, "landmark_sigma_m"),
])
def test_bad_options_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SmootherOptions(**kwargs)


def test_log_helpers_check_their_input(model, nominal):
    with pytest.raises(UnknownPoseError, match="outside"):
        log_keyframes(100, every=33, extra=[101])
    with pytest.raises(ValueError, match="m_per_tick"):
        smooth_log(model.updated(m_per_tick=None), nominal[0].log, initial_pose=np.zeros(3))
    with pytest.raises(ValueError, match="method"):
        smooth_log(model, nominal[0].log, initial_pose=np.zeros(3), method="magic")


def test_batch_smoothing_without_landmarks_is_dead_reckoning(straight):
    res = smooth_batch(straight, initial_pose=np.array([1.0, 2.0, np.pi / 2]),
                       options=SmootherOptions(calibrate=False))
    np.testing.assert_allclose(res.poses[-1], [1.0, 2.2, np.pi / 2], atol=1e-9)
    # variance grows along the chain
    assert np.all(np.diff(res.pose_covariances[:, 0, 0]) > 0)


# -- the example ---------------------------------------------------------------------------

def test_example_runs_on_a_short_horizon(example, model, phi, tmp_path):
    out = tmp_path / "factor_graph.png"
    summary = example.run(seed=1, duration_s=20.0, out=out, model=model, speed_covariance=phi)
    assert out.stat().st_size > 10_000
    assert summary["ate_smoother_m"] < 0.02 < summary["ate_dead_reckoning_m"]


def test_a_model_with_intrinsics_smooths_on_each_wheels_scale(model, phi, landmarks, nominal):
    from lti_motion.intrinsics import OdometryIntrinsics

    run = nominal[0]
    kwargs = dict(initial_pose=run.log.true_pose[0], observations=run.obs, landmarks=landmarks,
                  speed_covariance=phi, method="batch", mode="one_step")   # encoder-aided
    plain = smooth_log(model, run.log, **kwargs)
    same = smooth_log(model.updated(intrinsics=OdometryIntrinsics.symmetric(
        m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)), run.log, **kwargs)
    np.testing.assert_array_equal(same.poses, plain.poses)
    skew = smooth_log(model.updated(intrinsics=OdometryIntrinsics(
        1.02 * model.m_per_tick, model.m_per_tick, model.wheel_base_m)), run.log, **kwargs)
    assert np.abs(skew.poses - plain.poses).max() > 1e-4
