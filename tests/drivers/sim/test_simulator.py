"""The simulator's physics, determinism, faults and input checks, each against a number."""

import numpy as np
import pytest

from drivers.exceptions import SimulatorError
from drivers.sim.config import Fault, FloorMap, Room, get_preset
from drivers.sim.simulator import Simulator, ground_m_per_tick
from lti_motion.recordings.ticks import tick_deltas, unwrap_ticks

PRESETS = ["create2", "paper"]


def _hold(value, n, start=10):
    cmd = np.zeros((n, 2))
    cmd[start:] = value
    return cmd


def _encoder_wheel_speeds(log, params):
    """Wheel speeds [m/s] over each frame interval, from the encoders alone."""
    return tick_deltas(log.ticks) * params.m_per_tick / np.diff(log.t_s)[:, None]


@pytest.mark.parametrize("speed", [0.05, 0.2, -0.3, 0.5])
def test_pid_holds_wheel_speed_within_2_percent_on_hard_floor(speed):
    p = get_preset("create2")
    log = Simulator(p, seed=4, floor="hard", room=Room.empty()).run(_hold(speed, 400))
    last_2_s = slice(-134, None)
    ticks = unwrap_ticks(log.ticks)[last_2_s]
    wheel = (ticks[-1] - ticks[0]) * p.m_per_tick / (log.t_s[-1] - log.t_s[-134])
    np.testing.assert_allclose(wheel, speed, rtol=0.02)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("amplitude", [0.1, 0.3, 0.5])
def test_step_response_settles_within_the_presets_settling_time(preset, amplitude):
    p = get_preset(preset)
    start = 10
    log = Simulator(p, seed=7).run(_hold(amplitude, start + 200, start=start))
    v = log.true_body_m_s[:, 0]
    settled_at = start + int(np.ceil(p.settling_time_s / p.period_s))
    final = v[-60:].mean()
    assert abs(final - amplitude) < 0.02 * amplitude
    assert np.all(np.abs(v[settled_at:] - final) <= 0.02 * final)
    # and it is not settled much earlier: the dynamics are not trivial
    assert np.any(np.abs(v[start:settled_at] - final) > 0.02 * final)


@pytest.mark.parametrize("preset", PRESETS)
def test_delay_from_command_to_first_encoder_motion_is_3_to_6_periods(preset):
    p = get_preset(preset)
    delays = []
    for seed in range(8):
        log = Simulator(p, seed=seed).run(_hold(0.3, 40, start=10))
        moved = np.flatnonzero(np.any(unwrap_ticks(log.ticks) != 0, axis=1))[0]
        delays.append(moved - 10)   # frame k closes period k; the command went out at 10
    assert 3 <= min(delays) and max(delays) <= 6, delays


def test_carpet_gives_less_ground_travel_per_tick_than_hard_floor():
    per_tick = {}
    for floor in ("hard", "carpet"):
        log = Simulator("create2", seed=1, floor=floor, room=Room.empty()).run(_hold(0.25, 600))
        ticks = unwrap_ticks(log.ticks)[-1].mean()
        per_tick[floor] = np.linalg.norm(log.true_pose[-1, :2] - log.true_pose[0, :2]) / ticks
    p = get_preset("create2")
    assert per_tick["carpet"] < 0.98 * per_tick["hard"]
    # the contact model's rolling radius explains most of it; slip the rest
    assert per_tick["carpet"] < ground_m_per_tick(p, "carpet") < per_tick["hard"] * 1.001


def test_slip_under_hard_acceleration_shows_in_truth_not_encoders():
    """On tile the motors out-pull the traction limit: the wheels spin and the encoders,
    which count wheel rotation, over-count the ground travelled."""
    p = get_preset("create2")

    def encoder_excess(floor):
        cmd = np.zeros((125, 2))
        cmd[5:] = 0.5                                   # a full-speed step from rest
        log = Simulator(p, seed=2, floor=floor, room=Room.empty()).run(cmd)
        ticks = unwrap_ticks(log.ticks)
        moving = np.flatnonzero(ticks.mean(axis=1) > 0)[0]
        out = []
        for span in (slice(moving - 1, moving + 20), slice(80, 101)):   # accelerating, cruising
            encoder_m = (ticks[span][-1] - ticks[span][0]).mean() * p.m_per_tick
            true_m = np.linalg.norm(log.true_pose[span][-1, :2] - log.true_pose[span][0, :2])
            out.append((encoder_m - true_m) / encoder_m)
        return out

    tile_accel, tile_cruise = encoder_excess("tile")
    hard_accel, _ = encoder_excess("hard")
    assert tile_accel > 0.03                  # > 3% of the travel is wheel spin
    assert tile_accel > 2 * hard_accel        # the traction limit, not just tyre creep
    assert tile_cruise < 0.01


def test_rollover_forward_and_backward_is_unwrapped():
    p = get_preset("create2")
    for speed in (0.5, -0.5):
        # 63 s at full speed: more than the 29 m of one 16-bit wrap
        log = Simulator(p, seed=3, room=Room.empty()).run(_hold(speed, 4200, start=1))
        raw = log.ticks[:, 0]
        assert np.any(np.abs(np.diff(raw)) > 30000)                  # it did wrap
        travel = unwrap_ticks(log.ticks)[-1].mean() * ground_m_per_tick(p, "hard")
        path = np.linalg.norm(np.diff(log.true_pose[:, :2], axis=0), axis=1).sum()
        assert np.sign(travel) == np.sign(speed)
        np.testing.assert_allclose(abs(travel), path, rtol=0.01)


def test_encoders_count_in_the_commanded_direction():
    """Roomba encoders are not quadrature: a wheel still rolling forward counts down
    once the command is negative (spec §6.2, :mod:`drivers.roomba.oi`)."""
    cmd = np.concatenate([_hold(0.4, 100), np.full((40, 2), -0.4)])
    log = Simulator("create2", seed=1).run(cmd)
    deltas = tick_deltas(log.ticks)
    forward_but_counting_down = (log.true_body_m_s[1:, 0] > 0.05) & (deltas.mean(axis=1) < 0)
    assert forward_but_counting_down.sum() >= 1


def test_same_seed_same_frames_step_equals_run_and_seeds_differ(rng):
    cmd = rng.uniform(-0.3, 0.3, (3, 250, 2))
    ran = Simulator("create2", n_robots=3, seed=5).run(cmd)
    again = Simulator("create2", n_robots=3, seed=5).run(cmd)
    stepped = Simulator("create2", n_robots=3, seed=5)
    frames = [stepped.step(cmd[:, k]) for k in range(cmd.shape[1])]
    for name in ("t_s", "ticks", "light_bump", "bumps", "true_pose", "true_body_m_s"):
        np.testing.assert_array_equal(getattr(ran, name), getattr(again, name))
        np.testing.assert_array_equal(
            getattr(ran, name), np.stack([getattr(f, name) for f in frames], axis=1)
        )
    other = Simulator("create2", n_robots=3, seed=50).run(cmd)
    assert not np.array_equal(ran.light_bump, other.light_bump)
    assert not np.array_equal(ran.t_s, other.t_s)
    # robots of one batch have their own seeds, so their noise differs too
    assert not np.array_equal(ran.true_pose[0], ran.true_pose[1])


def test_light_bumps_repeat_once_per_turn_and_see_walls():
    p = get_preset("create2")
    sim = Simulator(p, seed=1, room=Room.single_wall(), initial_pose=(0.0, 0.35, 0.0))
    turns_per_s = 2 * 0.15 / p.wheel_base_m / (2 * np.pi)
    log = sim.run(np.tile([-0.15, 0.15], (int(3 / turns_per_s / p.period_s), 1)))
    heading = log.true_pose[:, 2]
    centre_left = log.light_bump[:, 2]
    near = heading[centre_left > 0.8 * centre_left.max()]
    # one cluster of strong readings per turn, one turn apart
    breaks = np.flatnonzero(np.diff(near) > 1.0)
    centres = [c.mean() for c in np.split(near, breaks + 1)]
    assert len(centres) >= 3
    np.testing.assert_allclose(np.diff(centres), 2 * np.pi, atol=0.05)
    # the wall lies at heading -pi/2 for a sensor pointing 13 degrees left of forward
    phase = np.mod(np.array(centres) + np.deg2rad(13.0) + np.pi / 2 + np.pi, 2 * np.pi) - np.pi
    assert np.all(np.abs(phase) < 0.1)
    empty = Simulator(p, seed=1, room=Room.empty()).run(np.full((50, 2), 0.1))
    assert empty.light_bump.max() < 6 * p.ir_noise


def test_bumper_and_wall_stop_the_robot():
    log = Simulator("create2", seed=1, room=Room.box(), initial_pose=(2.5, 2.5, 0.0)).run(
        _hold(0.3, 800)
    )
    assert log.bumps[:, 0].any() and log.bumps[:, 1].any()
    assert log.true_pose[:, 0].max() <= 5.0 - 0.17 + 1e-6
    # on hard floor the current-limited motors cannot spin the wheels: they stall
    contact = np.flatnonzero(log.bumps.any(axis=1))[0]
    assert np.abs(tick_deltas(log.ticks[contact + 20:])).max() <= 1
    assert np.all(np.abs(log.true_body_m_s[contact + 20:, 0]) < 1e-3)


def _fault_run(fault, n=700, cmd=None, **kw):
    cmd = _hold(0.3, n) if cmd is None else cmd
    return Simulator("create2", seed=9, faults=[fault] if fault else [], room=Room.empty(),
                     **kw).run(cmd)


def test_faults_each_change_what_they_should():
    base = _fault_run(None)
    t_fault = 4.0
    k = int(t_fault / 0.015)
    # lost frames: marked invalid, the rest untouched
    lost = _fault_run(Fault("lost_frames", t_s=t_fault, duration_s=1.0, probability=0.5))
    assert 20 < (~lost.valid).sum() < 50 and lost.valid[:k].all()
    np.testing.assert_array_equal(lost.ticks, base.ticks)
    # stuck encoder: the right count stops, then continues from where it froze
    stuck = _fault_run(Fault("stuck_encoder", t_s=t_fault, duration_s=1.0, wheel="right"))
    right = unwrap_ticks(stuck.ticks)[:, 1]
    assert np.all(np.diff(right[k + 2:k + 60]) == 0)
    assert np.diff(right[-50:]).min() > 0
    # spikes: single-frame jumps of about the given size
    spiky = _fault_run(Fault("encoder_spikes", t_s=t_fault, duration_s=2.0, rate_hz=5.0))
    jump = np.abs(tick_deltas(spiky.ticks) - tick_deltas(base.ticks))
    assert (jump > 60).sum() >= 10 and jump[: k - 1].max() == 0
    # floor change: less ground per tick afterwards
    carpet = _fault_run(Fault("floor", t_s=t_fault, floor="carpet"))
    after = slice(k + 100, None)

    def per_tick(log):
        dist = np.linalg.norm(np.diff(log.true_pose[after, :2], axis=0), axis=1).sum()
        return dist / np.diff(unwrap_ticks(log.ticks)[after], axis=0).mean(axis=1).sum()

    assert per_tick(carpet) < 0.97 * per_tick(base)
    # stall: the left wheel stops, the robot pivots
    stall = _fault_run(Fault("stall", t_s=t_fault, duration_s=1.0, wheel="left"))
    assert np.all(np.diff(unwrap_ticks(stall.ticks)[k + 5:k + 60, 0]) == 0)
    assert stall.true_body_m_s[k + 30, 1] > 0.5      # right wheel drives: turns left
    # payload, weak motor, longer delay: the same steady speed, a different transient
    hold = 120
    steps = np.zeros((800, 2))
    steps[:, :] = np.where((np.arange(800) // hold) % 2 == 0, 0.1, 0.45)[:, None]
    nominal = _fault_run(None, cmd=steps)
    for fault in (Fault("payload", t_s=t_fault, payload_kg=6.0),
                  Fault("motor", t_s=t_fault, weakening=0.3),
                  Fault("delay", t_s=t_fault, extra_periods=3)):
        faulty = _fault_run(fault, cmd=steps)
        v_nom, v_bad = nominal.true_body_m_s[:, 0], faulty.true_body_m_s[:, 0]
        np.testing.assert_array_equal(v_nom[:k - 10], v_bad[:k - 10])
        assert np.abs(v_nom[k + 10:] - v_bad[k + 10:]).max() > 0.03, fault.kind
        hold_end = ((k + 30) // hold + 2) * hold
        steady = slice(hold_end - 10, hold_end)   # end of a hold: the PID hides the fault again
        np.testing.assert_allclose(v_bad[steady], v_nom[steady], atol=0.01, err_msg=fault.kind)


def test_floor_map_regions():
    fmap = FloorMap(default="hard", regions=((3.0, 10.0, -10.0, 10.0, "carpet"),))
    log = Simulator("create2", seed=1, floor=fmap, room=Room.empty(),
                    initial_pose=(0.0, 0.0, 0.0)).run(_hold(0.4, 900))
    ticks = unwrap_ticks(log.ticks).mean(axis=1)
    x = log.true_pose[:, 0]
    hard = (x > 0.5) & (x < 2.5)
    carpet = x > 3.5
    rate = [np.polyfit(ticks[m], x[m], 1)[0] for m in (hard, carpet)]
    assert rate[1] < 0.97 * rate[0]


def test_batch_of_robots_with_their_own_parameters():
    p = get_preset("create2")
    robots = [p, p.replace(payload_kg=5.0), p.replace(motor_balance=0.9)]
    cmd = np.tile(_hold(0.4, 120), (3, 1, 1))
    log = Simulator(robots, seed=[1, 1, 1]).run(cmd)
    assert log.n_robots == 3 and log.ticks.shape == (3, 120, 2)
    assert not np.allclose(log.true_body_m_s[0, 15:25, 0], log.true_body_m_s[1, 15:25, 0])
    one = log.robot(1)
    assert one.n_robots is None and one.true_pose.shape == (120, 3)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Simulator("create2").run(np.zeros((10, 3))), r"shape \(n, 2\).*\(10, 3\)"),
        (lambda: Simulator("create2").step(np.zeros(3)), r"shape \(2,\).*\(3,\)"),
        (lambda: Simulator("create2", n_robots=2).step(np.zeros(2)), r"\(2, 2\)"),
        (lambda: Simulator("create2").run(np.array([[0.1, np.nan]])), "finite"),
        (lambda: Simulator("create2").run(np.array([[0.1, 0.7]])), "exceeds"),
        (lambda: Simulator("roomba9000"), "unknown preset 'roomba9000'.*create2"),
        (lambda: Simulator("create2", floor="ice"), "unknown floor 'ice'.*carpet"),
        (lambda: get_preset("create2", period_s=-0.015), "period_s must be positive"),
        (lambda: get_preset("create2", internal_step_s=-1e-3), "internal_step_s must be positive"),
        (lambda: Fault("meteor", t_s=1.0), "unknown fault kind"),
        (lambda: Fault("floor", t_s=1.0, floor="lava"), "unknown floor"),
        (lambda: Simulator([get_preset("create2"), get_preset("paper")], seed=[1, 2]),
         "share one period_s"),
    ],
)
def test_bad_input_raises_a_clear_error(make, match):
    with pytest.raises(SimulatorError, match=match):
        make()
