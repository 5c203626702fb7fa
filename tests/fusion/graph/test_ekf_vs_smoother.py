"""The factor graph against the EKF: with landmarks, the smoothed trajectory's ATE is
lower than the EKF's on the same runs, with the same observations and noise settings.

20 simulated drives of 60 s in a 5 m room with four landmarks seen at 2 Hz each (range
noise 5 cm, bearing 1 degree). Both estimators get the encoders, the same observations and
the true start pose; ATE is taken at the smoother's keyframes for both, without alignment.
Measured: EKF 5.6 +- 1.1 mm, smoother 4.6 +- 1.0 mm; the smoother is better in 16 of 20.
"""


import numpy as np
import pytest

from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from fusion.ekf.ekf_options import EKFOptions
from fusion.graph.smoother import SmootherOptions, smooth_log
from fusion.landmarks.synthetic import synthetic_observations
from fusion.noise import LandmarkNoise
from lti_motion.metrics import ate

N_RUNS = 20
DURATION_S = 60.0
NOISE = LandmarkNoise(range_std_frac=0.0, range_std_m=0.05, bearing_std_rad=np.radians(1.0))


@pytest.fixture(scope="module")
def runs(load_example, ekf_example_model):
    ekf_ex = load_example("ekf_plugin")
    model = ekf_example_model
    sim = Simulator("create2", n_robots=N_RUNS, seed=300, room=Room.box(5.0, 5.0),
                    initial_pose=ekf_ex.START_POSE)
    logs = ekf_ex.drive_route(sim, duration_s=DURATION_S, rng=np.random.default_rng(17))
    out = []
    for i in range(N_RUNS):
        log = logs.robot(i)
        obs = synthetic_observations(log.true_pose, ekf_ex.LANDMARKS, dt_s=log.dt_s,
                                     rng=np.random.default_rng(700 + i), noise=NOISE)
        ekf = ekf_ex.run_filter(model, log, initial_pose=log.true_pose[0], observations=obs,
                                landmarks=ekf_ex.LANDMARKS,
                                options=EKFOptions(landmark_noise=NOISE))
        sm = smooth_log(model, log, initial_pose=log.true_pose[0], observations=obs,
                        landmarks=ekf_ex.LANDMARKS, mode="filtered",
                        options=SmootherOptions(landmark_noise=NOISE))
        kf = sm.keyframes
        out.append((ate(log.true_pose[kf], ekf.poses[kf]), ate(log.true_pose[kf], sm.poses)))
    return np.array(out)


def test_smoother_ate_lower_than_the_ekfs_on_the_same_runs(runs):
    ekf_ate, smoother_ate = runs[:, 0], runs[:, 1]
    assert smoother_ate.mean() < ekf_ate.mean(), (smoother_ate.mean(), ekf_ate.mean())
    # run by run: measured 16 of 20 (seeds 300 / 17 / 700+i); a paired majority at least
    assert np.sum(smoother_ate < ekf_ate) > N_RUNS // 2, np.sum(smoother_ate < ekf_ate)
