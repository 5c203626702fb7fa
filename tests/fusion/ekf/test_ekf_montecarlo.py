"""Monte Carlo acceptance of the EKF plug-in on the simulator (docs/ekf.md).

One calibration per module; seeded batches of simulated robots drive the example's
rounded-square route (pure pursuit on the simulator's truth, positive wheel commands)
in a 5 m x 5 m room. The filter sees only commands, raw encoder counts and landmark
observations drawn from the true pose with seeded noise (2% range, 1 degree bearing,
each of four landmarks at 2 Hz).

- Consistency, landmarks, 30 runs of 60 s: time-averaged pose NEES and encoder NIS,
  averaged over the runs, inside the two-sided 95% chi-square interval (Bar-Shalom et
  al. 2001, section 5.4.2: N runs of a time average with n dof lie in chi2(N n) / N,
  conservatively, since time averaging only narrows the spread). Each run starts from
  a pose drawn from the filter's initial covariance.
- No landmarks, the same 30 runs: mean final position error no worse than odometry.
- Encoder spikes on both wheels and a 3 s stuck left encoder, 30 runs of 60 s: final
  error at most half of odometry's on every run; every injected spike (found by
  comparing with a twin simulator without spikes) rejected by the gate.
- Landmark sensor 0.22 m ahead of the axle (fusion.sensor_pose), 10 runs of 60 s: with its mount
  given, position RMS error within 2 cm and at most 5% of the sightings gated, as
  centred; the same sightings taken as from the axle centre (the mount dropped)
  are mostly gated and leave several times the error.
- Landmarks, 10 minutes: 5 runs (not 30: 40,000 filter steps per run take about 2 s),
  position RMS error at most 5 cm, no divergence.
"""


from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from drivers.sim.config import Fault, Room
from drivers.sim.simulator import Simulator
from fusion.landmarks.synthetic import synthetic_observations
from fusion.sensor_pose import CENTRED, SensorPose
from lti_motion.kinematics import wrap_angle
from lti_motion.recordings.ticks import tick_deltas

N_RUNS, DURATION_S = 30, 60.0
LONG_RUNS, LONG_DURATION_S = 5, 600.0
P0_STD = 0.005          # initial pose standard deviation [m, m, rad]


@pytest.fixture(scope="module")
def example(load_example):
    return load_example("ekf_plugin")


@pytest.fixture(scope="module")
def model(ekf_example_model):
    return ekf_example_model


def _pose_errors(truth, estimate):
    e = truth - estimate
    e[:, 2] = wrap_angle(e[:, 2])
    return e


def _final_error(truth, estimate):
    return float(np.hypot(*(truth[-1, :2] - estimate[-1, :2])))


@pytest.fixture(scope="module")
def nominal(example, model):
    """30 runs with and without landmarks, and odometry, on the same drives."""
    sim = Simulator("create2", n_robots=N_RUNS, seed=100, room=Room.box(5.0, 5.0),
                    initial_pose=example.START_POSE)
    logs = example.drive_route(sim, duration_s=DURATION_S, rng=np.random.default_rng(7))
    out = {k: [] for k in ("nees", "nees_t", "nis", "rms", "final_filter", "final_odometry")}
    for i in range(N_RUNS):
        log = logs.robot(i)
        obs = synthetic_observations(log.true_pose, example.LANDMARKS, dt_s=log.dt_s,
                                     rng=np.random.default_rng(500 + i))
        start = np.array(example.START_POSE) + P0_STD * np.random.default_rng(
            900 + i).standard_normal(3)
        run = example.run_filter(model, log, initial_pose=start, observations=obs,
                                 landmarks=example.LANDMARKS, pose_std=(P0_STD,) * 3)
        e = _pose_errors(log.true_pose, run.poses)
        nees_t = np.einsum("ni,nij,nj->n", e, np.linalg.inv(run.pose_covs), e)
        out["nees_t"].append(nees_t)
        out["nees"].append(nees_t.mean())
        out["nis"].append(np.nanmean(run.encoder_nis))
        out["rms"].append(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))
        bare = example.run_filter(model, log, initial_pose=example.START_POSE)
        odometry = example.odometry_poses(log, m_per_tick=model.m_per_tick,
                                          wheel_base_m=model.wheel_base_m,
                                          initial_pose=example.START_POSE)
        out["final_filter"].append(_final_error(log.true_pose, bare.poses))
        out["final_odometry"].append(_final_error(log.true_pose, odometry))
    out = {k: np.array(v) for k, v in out.items()}
    out["bumps"] = bool(logs.bumps.any())
    return out


MOUNT_RUNS = 10


@pytest.fixture(scope="module")
def mounted(example, model):
    """Sightings from a sensor 0.22 m ahead, fused with its mount and taken as centred."""
    sim = Simulator("create2", n_robots=MOUNT_RUNS, seed=400, room=Room.box(5.0, 5.0),
                    initial_pose=example.START_POSE)
    logs = example.drive_route(sim, duration_s=DURATION_S, rng=np.random.default_rng(9))
    out = {k: [] for k in ("rms", "gated", "rms_centred", "gated_centred")}
    for i in range(MOUNT_RUNS):
        log = logs.robot(i)
        obs = synthetic_observations(log.true_pose, example.LANDMARKS, dt_s=log.dt_s,
                                     rng=np.random.default_rng(600 + i),
                                     sensor_pose=SensorPose(0.22, 0.0, 0.0))
        for suffix, sightings in (("", obs), ("_centred", replace(obs, sensor_pose=CENTRED))):
            run = example.run_filter(model, log, initial_pose=example.START_POSE,
                                     observations=sightings, landmarks=example.LANDMARKS,
                                     pose_std=(P0_STD,) * 3)
            e = _pose_errors(log.true_pose, run.poses)
            out["rms" + suffix].append(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))
            out["gated" + suffix].append(run.stats.count("landmark", "gated") / len(obs))
    return {k: np.array(v) for k, v in out.items()}


STUCK_S = (0.4 * DURATION_S, 3.0)
# Left-wheel spikes pause while the left encoder is stuck: a spike on a frozen count can
# refill part of its missing ticks, and the gate then rightly fuses a sum that matches.
FAULTS = [
    Fault("encoder_spikes", t_s=2.0, rate_hz=1.0, wheel="right"),
    Fault("encoder_spikes", t_s=2.0, duration_s=STUCK_S[0] - 2.0, rate_hz=0.5, wheel="left"),
    Fault("encoder_spikes", t_s=sum(STUCK_S), rate_hz=0.5, wheel="left"),
    Fault("stuck_encoder", t_s=STUCK_S[0], duration_s=STUCK_S[1], wheel="left"),
]


@pytest.fixture(scope="module")
def faulty(example, model):
    """30 runs with spikes and a stuck episode; spikes located with a spike-free twin."""
    sim = Simulator("create2", n_robots=N_RUNS, seed=200, room=Room.box(5.0, 5.0),
                    initial_pose=example.START_POSE, faults=FAULTS)
    logs = example.drive_route(sim, duration_s=DURATION_S, rng=np.random.default_rng(8))
    twin = Simulator("create2", n_robots=N_RUNS, seed=200, room=Room.box(5.0, 5.0),
                     initial_pose=example.START_POSE,
                     faults=[f for f in FAULTS if f.kind != "encoder_spikes"])
    twin_logs = twin.run(logs.cmd_m_s)
    spikes = tick_deltas(np.stack([twin_logs.ticks, logs.ticks]), axis=0)[0] != 0
    out = {k: [] for k in ("final_filter", "final_odometry", "spikes", "missed", "gated")}
    for i in range(N_RUNS):
        log = logs.robot(i)
        run = example.run_filter(model, log, initial_pose=example.START_POSE)
        odometry = example.odometry_poses(log, m_per_tick=model.m_per_tick,
                                          wheel_base_m=model.wheel_base_m,
                                          initial_pose=example.START_POSE)
        spike_frames = np.flatnonzero(spikes[i].any(axis=1))
        out["final_filter"].append(_final_error(log.true_pose, run.poses))
        out["final_odometry"].append(_final_error(log.true_pose, odometry))
        out["spikes"].append(len(spike_frames))
        out["missed"].append(int(run.encoder_accepted[spike_frames].sum()))
        out["gated"].append(run.stats.count("encoders", "gated"))
    out = {k: np.array(v) for k, v in out.items()}
    out["same_physics"] = bool(np.array_equal(twin_logs.true_pose, logs.true_pose))
    return out


@pytest.fixture(scope="module")
def long_drive(example, model):
    sim = Simulator("create2", n_robots=LONG_RUNS, seed=300, room=Room.box(5.0, 5.0),
                    initial_pose=example.START_POSE)
    logs = example.drive_route(sim, duration_s=LONG_DURATION_S, rng=np.random.default_rng(9))
    rms, worst, last_minute, nees = [], [], [], []
    for i in range(LONG_RUNS):
        log = logs.robot(i)
        obs = synthetic_observations(log.true_pose, example.LANDMARKS, dt_s=log.dt_s,
                                     rng=np.random.default_rng(700 + i))
        run = example.run_filter(model, log, initial_pose=example.START_POSE, observations=obs,
                                 landmarks=example.LANDMARKS)
        e = _pose_errors(log.true_pose, run.poses)
        dist = np.hypot(e[:, 0], e[:, 1])
        rms.append(np.sqrt(np.mean(dist ** 2)))
        worst.append(dist.max())
        last_minute.append(np.sqrt(np.mean(dist[-round(60 / log.dt_s):] ** 2)))
        nees.append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(run.pose_covs), e).mean())
    return {"rms": np.array(rms), "worst": np.array(worst), "last_minute": np.array(last_minute),
            "nees": np.array(nees), "bumps": bool(logs.bumps.any())}


def _interval(dof, n_runs, level=0.95):
    lo, hi = chi2.ppf([(1 - level) / 2, (1 + level) / 2], dof * n_runs) / n_runs
    return lo, hi


def test_routes_stay_clear_of_the_walls(nominal, faulty, long_drive):
    assert not nominal["bumps"] and not long_drive["bumps"]
    assert faulty["same_physics"], "spikes change only the reported counts"


def test_pose_nees_with_landmarks_inside_the_95_percent_interval(nominal):
    lo, hi = _interval(3, N_RUNS)
    assert lo <= nominal["nees"].mean() <= hi, (nominal["nees"].mean(), lo, hi)
    # per time step, the 30-run average NEES lies in its interval most of the time
    per_step = nominal["nees_t"].mean(axis=0)
    assert np.mean((per_step >= lo) & (per_step <= hi)) > 0.7


def test_encoder_nis_inside_the_95_percent_interval(nominal):
    lo, hi = _interval(2, N_RUNS)
    assert lo <= nominal["nis"].mean() <= hi, (nominal["nis"].mean(), lo, hi)


def test_landmarks_hold_the_position_to_centimetres(nominal):
    assert nominal["rms"].max() < 0.02


def test_without_landmarks_final_error_no_worse_than_odometry(nominal):
    assert nominal["final_filter"].mean() <= nominal["final_odometry"].mean()
    # and run by run within a couple of millimetres
    assert np.max(nominal["final_filter"] - nominal["final_odometry"]) < 0.002


def test_with_faults_final_error_at_most_half_of_odometrys(faulty):
    assert np.all(faulty["final_filter"] <= 0.5 * faulty["final_odometry"])
    assert faulty["final_filter"].mean() <= 0.5 * faulty["final_odometry"].mean()


def test_every_injected_spike_is_rejected_by_the_gate(faulty):
    assert faulty["spikes"].sum() > 30 * N_RUNS          # about 1.5 spikes per second
    assert faulty["missed"].sum() == 0
    assert np.all(faulty["gated"] >= faulty["spikes"])


def test_a_sensor_ahead_of_the_axle_is_as_good_as_a_centred_one_once_its_mount_is_given(
        mounted):
    assert mounted["rms"].max() < 0.02, mounted["rms"]
    assert mounted["gated"].max() <= 0.05, mounted["gated"]
    # the mount dropped: the same sightings taken as from the axle centre
    assert mounted["gated_centred"].mean() > 0.3, mounted["gated_centred"]
    assert mounted["rms_centred"].mean() > 4 * mounted["rms"].mean(), mounted["rms_centred"]


def test_ten_minute_drive_with_landmarks_within_5_cm_rms(long_drive):
    assert np.all(long_drive["rms"] <= 0.05), long_drive["rms"]
    # no divergence: bounded worst error, the last minute as good as the whole, NEES sane
    assert np.all(long_drive["worst"] < 0.10)
    assert np.all(long_drive["last_minute"] <= 0.05)
    assert np.all(long_drive["nees"] < 6.0)
