"""Frame containers and encoder odometry."""

import numpy as np
import pytest

from lti_motion.exceptions import ShapeError
from lti_motion.recordings.frames import FrameLog, SensorFrame
from lti_motion.recordings.ticks import body_speeds_from_ticks, tick_deltas, tick_step, unwrap_ticks


def _log(n=5, batch=None):
    lead = (n,) if batch is None else (batch, n)
    return FrameLog(
        t_s=np.zeros(lead) + np.arange(n) * 0.015,
        ticks=np.zeros((*lead, 2), np.int64),
        light_bump=np.zeros((*lead, 6), np.int64),
        bumps=np.zeros((*lead, 2), bool),
        cmd_m_s=np.zeros((*lead, 2)),
        valid=np.ones(lead, bool),
        dt_s=0.015,
    )


def test_framelog_checks_shapes_and_period():
    log = _log()
    assert len(log) == 5 and log.n_robots is None and not log.has_truth
    with pytest.raises(ShapeError, match=r"ticks must have shape \(5, 2\), got \(5, 3\)"):
        FrameLog(**{**log.__dict__, "ticks": np.zeros((5, 3), np.int64)})
    with pytest.raises(ValueError, match="dt_s must be a positive period"):
        FrameLog(**{**log.__dict__, "dt_s": -0.015})


def test_framelog_batch_robot_window_and_frames_round_trip():
    batch = _log(n=6, batch=3)
    assert batch.n_robots == 3 and len(batch) == 6
    one = batch.robot(2)
    assert one.ticks.shape == (6, 2) and one.meta["robot"] == 2
    assert len(batch.window(2, 5)) == 3
    frames = list(one.frames())
    again = FrameLog.from_frames(frames, dt_s=0.015)
    np.testing.assert_array_equal(again.t_s, one.t_s)
    with pytest.raises(ValueError, match="needs a batch log"):
        one.robot(0)
    with pytest.raises(ValueError, match="at least one frame"):
        FrameLog.from_frames([], dt_s=0.015)
    lost = FrameLog(**{**one.__dict__, "valid": np.array([1, 0, 1, 1, 0, 1], bool)})
    assert len(list(lost.frames())) == 4
    assert isinstance(frames[0], SensorFrame)


def test_framelog_frame_k_keeps_lost_frames_and_drops_the_truth_when_asked():
    one = _log(n=4)
    truth = np.arange(12.0).reshape(4, 3)
    log = FrameLog(**{**one.__dict__, "valid": np.array([1, 0, 1, 1], bool),
                      "true_pose": truth, "true_body_m_s": np.ones((4, 2)),
                      "yaw_rate_rad_s": np.array([0.1, 0.2, 0.3, 0.4])})
    lost = log.frame(1)
    assert lost.valid is False and lost.t_s == pytest.approx(0.015)
    np.testing.assert_array_equal(lost.true_pose, truth[1])
    assert lost.yaw_rate_rad_s == 0.2 and isinstance(lost.yaw_rate_rad_s, float)
    reported = log.frame(2, truth=False)
    assert reported.valid is True and reported.true_pose is None
    assert reported.true_body_m_s is None
    assert [f.t_s for f in log.frames()] == [log.frame(k).t_s for k in (0, 2, 3)]
    with pytest.raises(ValueError, match="needs a single-robot log"):
        _log(n=4, batch=2).frame(0)


def test_a_frame_of_counts_has_no_light_bumps_or_bumpers():
    frame = SensorFrame.of_counts(0.3, np.array([5, 7]), np.array([0.1, 0.2]), valid=False,
                                  yaw_rate_rad_s=0.05)
    assert frame.light_bump.shape == (6,) and not frame.light_bump.any()
    assert frame.bumps.dtype == bool and not frame.bumps.any()
    assert frame.valid is False and frame.yaw_rate_rad_s == 0.05
    assert frame.motor_current_a is None and frame.wheel_overcurrent is None


@pytest.mark.parametrize(
    ("prev", "cur", "step"),
    [(65530, 5, 11), (5, 65530, -11), (65535, 0, 1), (0, 65535, -1), (100, 100, 0),
     (0, 32767, 32767), (32767, 0, -32767)],
)
def test_tick_deltas_shortest_step_on_the_ring(prev, cur, step):
    """The checks of spec §7.2 (drivers.roomba.oi), and the backward wrap (G13)."""
    assert tick_deltas(np.array([prev, cur]))[0] == step


def test_one_step_of_counts_is_tick_deltas_across_the_16_bit_wrap(rng):
    prev = rng.integers(0, 1 << 16, size=(50, 2))
    now = (prev + rng.integers(-40000, 40000, size=(50, 2))) % (1 << 16)
    now[:4] = [[5, 65530], [0, 65535], [65535, 0], [32768, 0]]
    prev[:4] = [[65530, 5], [32768, 32767], [0, 32768], [0, 32768]]
    np.testing.assert_array_equal(tick_step(prev, now),
                                  tick_deltas(np.stack([prev, now]))[0])


def test_unwrap_ticks_both_directions(rng):
    true = np.cumsum(rng.integers(-300, 300, size=2000)) + 40000
    raw = true % 65536
    np.testing.assert_array_equal(unwrap_ticks(raw), true - true[0])
    both = np.stack([raw, (-true) % 65536], axis=1)
    np.testing.assert_array_equal(unwrap_ticks(both, axis=0)[:, 1], -(true - true[0]))


def test_body_speeds_from_ticks_straight_and_spin():
    t = np.arange(4) * 0.015
    straight = np.stack([np.arange(4) * 10, np.arange(4) * 10], axis=1)
    v_w = body_speeds_from_ticks(straight, t, m_per_tick=0.001, wheel_base_m=0.25)
    np.testing.assert_allclose(v_w, [[0.01 / 0.015, 0.0]] * 3)
    spin = np.stack([(-np.arange(4) * 10) % 65536, np.arange(4) * 10], axis=1)
    v_w = body_speeds_from_ticks(spin, t, m_per_tick=0.001, wheel_base_m=0.25)
    np.testing.assert_allclose(v_w, [[0.0, 2 * 0.01 / 0.015 / 0.25]] * 3, atol=1e-12)
    with pytest.raises(ShapeError, match=r"\(n, 2\)"):
        body_speeds_from_ticks(np.zeros((4, 3)), t, m_per_tick=0.001, wheel_base_m=0.25)
    with pytest.raises(ValueError, match="timestamps must increase"):
        body_speeds_from_ticks(straight, t[::-1], m_per_tick=0.001, wheel_base_m=0.25)


def test_unfold_commanded_direction_restores_the_wheels_direction():
    """Spec section 6.2: counts follow the command, so a reversing wheel counts backwards
    while it is still rolling the old way; the true speed is continuous through zero."""
    from drivers.sim.config import Room, get_preset
    from drivers.sim.simulator import Simulator
    from lti_motion.recordings.ticks import unfold_commanded_direction

    p = get_preset("create2")
    cmd = np.tile(np.repeat([0.4, -0.4], 60)[:, None], (4, 2))      # reverse every 0.9 s
    log = Simulator(p, seed=4, room=Room.empty()).run(cmd)
    raw = tick_deltas(log.ticks)
    fixed = unfold_commanded_direction(raw)
    true_v = log.true_body_m_s[1:, 0]
    moving = np.abs(true_v) > 0.03
    wrong_raw = (np.sign(raw.mean(axis=1)) != np.sign(true_v)) & moving
    wrong_fixed = (np.sign(fixed.mean(axis=1)) != np.sign(true_v)) & moving
    assert wrong_raw.sum() >= 10              # the artefact is real: several frames per reversal
    assert wrong_fixed.sum() <= 1
    np.testing.assert_array_equal(np.abs(fixed), np.abs(raw))     # only signs change


def test_unfold_leaves_quadrature_like_data_alone():
    from lti_motion.recordings.ticks import unfold_commanded_direction

    ramp = np.array([5, 3, 1, 0, -1, -3, -5])        # a wheel that really reverses
    np.testing.assert_array_equal(unfold_commanded_direction(ramp), ramp)
