"""MonitoredFilter: the model EKF and the monitor as one object, one call per frame."""

import numpy as np
import pytest

from benchmarks.bench_monitor import route_drives
from drivers.sim.config import Fault
from fusion.ekf.ekf_options import EKFOptions
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.landmarks.synthetic import synthetic_observations
from fusion.monitoring.monitored_filter import MonitoredFilter
from fusion.monitoring.phase_one import NominalFit
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import SensorFrame
from lti_motion.recordings.ticks import TICK_MODULUS, tick_deltas

DT = 0.015
M_PER_TICK = 5e-4


def _model(m_per_tick=M_PER_TICK):
    """One period of delay, then the command: v = (L + R) / 2, w = (R - L) / 0.25."""
    return MotionModel.from_fir(
        FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
               residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
        dt_s=DT, wheel_base_m=0.25, m_per_tick=m_per_tick,
        calibrated_at="2026-01-01T00:00:00+00:00")


def _frame(ticks, cmd, *, valid=True):
    """A frame of counts and commands only (a recording's row)."""
    return SensorFrame.of_counts(0.0, ticks, cmd, valid=valid)


def _straight(n, ticks_per_period=6):
    """Counts of frames 0..n driving straight at 0.2 m/s (6 ticks a period from period 2,
    after the model's period of delay), 16-bit."""
    counts = np.concatenate([[0, 0], np.full(n - 1, ticks_per_period)]).cumsum() + 65000
    return np.stack([counts, counts], axis=1) % TICK_MODULUS


def test_lost_frames_only_advance_and_the_next_counts_span_the_gap():
    ticks = _straight(200)
    cmd = np.array([0.2, 0.2])
    whole, lossy = MonitoredFilter(_model()), MonitoredFilter(_model())
    for k in range(201):
        a = whole.step(_frame(ticks[k], cmd))
        b = lossy.step(_frame(ticks[k], cmd, valid=not 100 <= k < 103))
        if 100 <= k < 103:
            assert b.encoders is None and b.tick_deltas.tolist() == [0.0, 0.0]
        elif k == 103:
            assert b.tick_deltas.tolist() == [24.0, 24.0]          # four periods
        assert a.t_s == b.t_s
    assert lossy.ekf.stats.count("encoders", "fused") == 200 - 3
    assert whole.ekf.stats.count("encoders", "fused") == 200
    assert np.allclose(a.pose, b.pose, atol=1e-4), (a.pose, b.pose)
    assert a.pose[0] == pytest.approx(0.2 * DT * 199, rel=1e-3)  # the first period is delay
    assert whole.events == [] and lossy.events == []


@pytest.mark.parametrize("fuse", [True, False])
def test_sightings_correct_a_wrong_start_when_fused(fuse, rng):
    n = 400
    ticks = _straight(n)
    truth = np.zeros((n + 1, 3))
    truth[2:, 0] = 0.2 * DT * np.arange(1, n)                       # one period of delay
    landmarks = LandmarkMap({1: (1.0, 1.0), 2: (1.0, -1.0), 3: (2.0, 0.5)})
    seen = synthetic_observations(truth, landmarks, dt_s=DT, rng=rng, rate_hz=4.0).by_index()
    mf = MonitoredFilter(_model(), landmarks=landmarks, fuse_landmarks=fuse,
                         initial_pose=(0.1, -0.05, 0.0), pose_std=(0.1, 0.1, 0.05))
    for k in range(n + 1):
        result = mf.step(_frame(ticks[k], np.array([0.2, 0.2])), sightings=seen.get(k))
    error = np.hypot(*(result.pose[:2] - truth[-1, :2]))
    landmark_updates = mf.ekf.stats.count("landmark", "fused")
    if fuse:
        n_seen = sum(len(v) for v in seen.values())
        assert error < 0.02 and landmark_updates >= 0.9 * n_seen, (error, landmark_updates)
    else:
        assert error > 0.1 and landmark_updates == 0, (error, landmark_updates)
    assert mf.scale is not None and not [e for e in mf.events if e.kind == "scale_changed"]


def test_phase_one_runs_the_dynamics_tests_with_its_gate(route_model, route_null):
    onset = 25.0
    cmd, deltas = route_drives(route_model, [300], [Fault("delay", t_s=onset, extra_periods=3.0)])
    ticks = np.concatenate([np.zeros((1, 2)), np.cumsum(deltas[0], axis=0)]) % TICK_MODULUS
    nominal = NominalFit(null=route_null, encoder_gate_nis=1e9, max_nominal_nis=1e8,
                         duration_s=0.0, n_drives=30)
    seen = []
    mf = MonitoredFilter(route_model, nominal=nominal, initial_ticks=ticks[0],
                         t0_s=route_model.dt_s, on_alarm=seen.append)
    assert mf.monitor.thresholds().gate == 1e9 and mf.dynamics is not None
    for k in range(cmd.shape[1]):
        mf.step(_frame(ticks[k + 1].astype(np.int64), cmd[0, k]))
    dynamics = [e for e in mf.events if e.kind == "dynamics_changed"]
    assert dynamics and onset <= dynamics[0].t_s <= onset + 4.0, dynamics
    assert dynamics[0].dynamics is not None and dynamics[0].dynamics.test == "lag"
    assert seen == mf.events


def test_bad_input_is_a_clear_error():
    with pytest.raises(MissingEncoderScaleError, match="the monitor needs the encoder scale"):
        MonitoredFilter(_model(m_per_tick=None))
    mf = MonitoredFilter(_model())
    with pytest.raises(MeasurementShapeError, match=r"shape \(2,\)"):
        mf.step(_frame(np.zeros(3), np.zeros(2)))     # the first frame anchors the counts
    mf.step(_frame(np.zeros(2), np.zeros(2)))
    with pytest.raises(MeasurementShapeError, match=r"shape \(2,\).*\(3,\)"):
        mf.step(_frame(np.zeros(3), np.zeros(2)))     # and every later one


def test_a_diverged_filter_resets_and_says_so_with_a_filter_reset_alarm():
    """Issue 15 item 3: a filter sure of a pose 1.1 m from the truth gates every sighting; after
    20 of them, of several landmarks, it resets (scales to the prior, pose covariance widened),
    raises one "filter_reset" alarm and the landmarks bring it back."""
    from fusion.range_bearing import RangeBearing, range_bearing

    lm = LandmarkMap({0: (3.0, 0.0), 1: (0.0, 3.0), 2: (3.0, 3.0)})
    truth = np.array([1.0, 0.5, 0.0])
    heard = []
    mf = MonitoredFilter(_model(), landmarks=lm, initial_pose=(0.0, 0.0, 0.0),
                         pose_std=(0.005, 0.005, 0.005), on_alarm=heard.append)
    rng = np.random.default_rng(3)
    for k in range(200):
        j = k % 3
        z = range_bearing(truth, np.array(lm.position(j))) + rng.normal(0.0, [0.01, 0.005])
        result = mf.step(_frame(np.array([100, 100]), np.zeros(2)),
                         sightings=RangeBearing([k], [j], [z[0]], [z[1]]))
    resets = [e for e in mf.events if e.kind == "filter_reset"]
    assert [e.test for e in resets] == ["diverged"] and resets[0] in heard
    assert mf.ekf.n_resets == 1 and resets[0].t_s == mf.ekf.resets[0].t_s
    assert np.hypot(*(result.pose[:2] - truth[:2])) < 0.05


def test_the_count_changes_are_the_filters_own_across_the_wrap_and_lost_frames():
    """The frame's count changes are those the EKF's counts took (one reference, in the
    EKF), the ring step since the last valid frame, with a 12-bit counter wrapping."""
    ticks = _straight(300) % (1 << 12)
    options = EKFOptions(history=0, counter_bits=12)
    mf = MonitoredFilter(_model(), ekf_options=options)
    lost = set(range(40, 44)) | {150}
    last = None
    for k in range(301):
        result = mf.step(_frame(ticks[k], np.array([0.2, 0.2]), valid=k not in lost))
        if k == 0 or k in lost:
            assert result.tick_deltas.tolist() == [0.0, 0.0]
            continue
        if last is not None:
            expected = tick_deltas(ticks[[last, k]], axis=0, counter_bits=12)[0]
            assert result.tick_deltas.tolist() == expected.astype(float).tolist(), k
        assert mf.ekf.encoder_counts.frame == tuple(ticks[k].tolist())
        last = k
    assert mf.ekf.options is options and mf.ekf_options is options
    assert mf.ekf.stats.count("encoders", "fused") == 300 - len(lost)
    with pytest.raises(FilterOptionError, match="ekf_options must be an EKFOptions"):
        MonitoredFilter(_model(), ekf_options={"counter_bits": 12})
