"""Dynamics-change tests on integrated encoder residuals (docs/monitor.md).

Closed-form checks (a plant that is the model gives zero residual; a late
plant's residual lies along the lag signature and the lag evidence recovers
the lag; the start evidence grows by sqrt(b) a period of lag; the threshold
arithmetic, Siegmund's and the Pareto tail's), then the simulator: the
closed route, 20 seeded runs per dynamics fault with onsets drawn
in 15-40 s, and one hour of nominal driving for the false-alarm rate (the
benchmark runs ten: ``benchmarks/bench_monitor.py``, ``docs/monitor.md``).
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import genpareto

# the route drives and the fault runs are the benchmark's own (pytest puts the project
# root on the path: pyproject's pythonpath)
from benchmarks.bench_monitor import (
    DYNAMICS_FAULTS,
    alarm_times,
    fault_runs,
    route_drives,
)
from drivers.sim.config import Fault
from fusion.exceptions import FilterOptionError
from fusion.monitoring.cusum import cusum_llr_threshold, lag_cusum_threshold
from fusion.monitoring.dynamics import (
    DynamicsMonitor,
    integrated_residuals,
    start_scores,
    window_statistics,
)
from fusion.monitoring.dynamics_null import _error_and_cov
from fusion.monitoring.dynamics_start import (
    drive_start_anchors,
    start_cusum_maxima,
    start_evidence,
    start_threshold_from_maxima,
)
from fusion.monitoring.residual import MonitorOptions, ResidualMonitor


@pytest.fixture(scope="module")
def model(route_model):
    return route_model


@pytest.fixture(scope="module")
def null(route_null):
    return route_null


def _model_ticks(model, u):
    """Per-period wheel travel [ticks] of the model's own free run from rest."""
    y = model.simulate(u)
    b = model.wheel_base_m
    wheels = np.stack([y[:, 0] - 0.5 * b * y[:, 1], y[:, 0] + 0.5 * b * y[:, 1]], axis=1)
    return wheels * model.dt_s / model.m_per_tick


def test_a_plant_that_is_the_model_leaves_no_residual(model, rng):
    u = np.repeat(rng.uniform(0.0, 0.3, (20, 2)), 45, axis=0)
    w = integrated_residuals(model, u, _model_ticks(model, u), window_periods=30)
    assert w.residual_ticks.shape == (30, 2) and np.all(w.valid)
    assert np.max(np.abs(w.residual_ticks)) < 1e-6
    # the lag signature is the change of predicted travel per period across each window
    assert np.max(np.abs(w.lag_signature_ticks)) > 1.0


def test_a_late_plant_gives_a_residual_along_the_lag_signature(model):
    u = np.repeat(np.array([[0.1, 0.1], [0.3, 0.3], [0.15, 0.15]]), 90, axis=0)
    ticks = _model_ticks(model, u)
    late = np.vstack([np.zeros((3, 2)), ticks[:-3]])           # 3 periods late
    w = integrated_residuals(model, u, late, window_periods=30)
    s, r = w.lag_signature_ticks, w.residual_ticks
    step = np.abs(s[:, 0]) > 5.0
    # r ~ -theta s with theta = 3 periods where the window holds a speed change
    theta = -np.sum(r[step] * s[step]) / np.sum(s[step] ** 2)
    assert 2.0 < theta < 4.0


def test_lag_evidence_recovers_the_lag_and_is_zero_without_one(model, null):
    # a = -s' S^-1 e, b = s' S^-1 s: the generalised least-squares lag is a / b (B&N 7.2.1);
    # the nominal mean of the null is a lag of its own, so compare late against on time
    u = np.repeat(np.array([[0.1, 0.1], [0.3, 0.3], [0.15, 0.15], [0.0, 0.0]]), 90, axis=0)
    ticks = _model_ticks(model, u)
    late = np.vstack([np.zeros((3, 2)), ticks[:-3]])
    on_time = window_statistics(null, integrated_residuals(model, u, ticks))
    delayed = window_statistics(null, integrated_residuals(model, u, late))
    b = on_time.lag_information
    assert np.allclose(b, delayed.lag_information)          # b depends on the commands only
    step = b > 1.0
    assert step.sum() >= 3
    extra = np.sum(delayed.lag_evidence[step] - on_time.lag_evidence[step]) / np.sum(b[step])
    assert 2.5 < extra < 3.5, extra
    assert np.all(b[~step] < 1.0) and np.all(on_time.q >= 0.0)

def test_threshold_from_the_false_alarm_budget():
    # Lorden 1971: ARL0 >= exp(h); 8,000 windows of 0.45 s an hour, 0.5 alarms an hour
    h = cusum_llr_threshold(3600.0 / (30 * 0.015), 0.5)
    assert math.exp(h) == pytest.approx(16_000)
    # the lag CUSUM: Siegmund's ARL0 of the standardised normal CUSUM (k = mu / 2,
    # threshold h / mu) equals N_inf / F; check it by the formula itself
    mu, n_inf, f = 2.5, 3000.0, 0.5
    h_lag = lag_cusum_threshold(n_inf, f, shift_sigma=mu)
    x = h_lag + 1.166 * mu
    assert (math.exp(x) - x - 1.0) / (mu * mu / 2.0) == pytest.approx(n_inf / f, rel=1e-6)
    # a smaller budget, a higher threshold; Lorden's bound for the same budget is higher still
    assert lag_cusum_threshold(n_inf, f / 10, shift_sigma=mu) > h_lag
    assert h_lag < math.log(n_inf / f)
    with pytest.raises(FilterOptionError, match="shift_sigma"):
        lag_cusum_threshold(n_inf, f, shift_sigma=0.0)


def test_drive_starts_anchor_in_the_window_holding_most_of_them():
    h = 30
    u = np.zeros((300, 2))
    u[10:40] = 0.2            # start at period 10 (first half of window 0): window 0
    u[75:100] = 0.2           # period 75 = window 2, position 15 (second half): window 3
    u[130:160] = [-0.1, 0.1]  # a turn in place: no drive start
    u[160:200] = 0.2          # moving before: not a start from rest
    u[250:] = [0.1, 0.3]      # an arc from rest counts (both wheels forward)
    anchors = drive_start_anchors(u, window_periods=h)
    assert np.flatnonzero(anchors).tolist() == [0, 3, 8]
    assert drive_start_anchors(np.stack([u, np.zeros_like(u)]), window_periods=h).shape == (2, 10)
    with pytest.raises(ValueError, match="shape"):
        drive_start_anchors(np.zeros(10), window_periods=h)


def test_start_evidence_grows_by_sqrt_b_a_period_of_lag(model, null):
    # a late start by theta periods moves e_j by -theta s_j: z_0 grows by theta sqrt(b)
    # (B&N 7.2.1, the lag evidence a = theta b normalised); the catch-up windows of a
    # pure lag do not move (the predictor restarts from the measured state)
    u = np.zeros((600, 2))
    u[250:450] = 0.25
    ticks = _model_ticks(model, u)
    rows = []
    for lag in (0, 1, 2, 3):
        late = np.vstack([np.zeros((lag, 2)), ticks[:len(ticks) - lag]])
        w = integrated_residuals(model, u, late, window_periods=null.window_periods)
        e, cov = _error_and_cov(null, w.residual_ticks, w.lag_signature_ticks,
                                w.predicted_ticks, w.previous_signature_ticks)
        z = start_evidence(e, cov, w.lag_signature_ticks, w.valid,
                           drive_start_anchors(u, window_periods=null.window_periods))
        j = np.flatnonzero(np.isfinite(z[:, 0]))
        assert j.tolist() == [250 // null.window_periods]
        b = window_statistics(null, w).lag_information[j[0]]
        rows.append((z[j[0]], start_scores(null, w, u)[j[0] + 2]))
    z0 = np.array([r[0][0] for r in rows])
    assert np.allclose(np.diff(z0), math.sqrt(b), rtol=0.05), (np.diff(z0), math.sqrt(b))
    assert np.allclose([r[0][1:] for r in rows], rows[0][0][1:], atol=1e-3)
    scores = np.array([r[1] for r in rows])
    assert np.allclose(np.diff(scores), math.sqrt(b) / null.start.std, rtol=0.05)


def test_start_threshold_is_the_pareto_tails_return_level():
    rng = np.random.default_rng(3)
    # maxima with a generalised Pareto tail of shape 0.2 above 0: P(M > h) = p at the
    # distribution's own quantile (Coles 2001, eq. 4.13)
    m = genpareto.rvs(0.2, scale=1.0, size=40_000, random_state=rng)
    h = start_threshold_from_maxima(m, runs_per_hour=60.0, false_alarms_per_hour=0.06)
    assert h == pytest.approx(genpareto.ppf(1.0 - 1e-3, 0.2), rel=0.1)
    assert start_threshold_from_maxima(m, runs_per_hour=60.0, false_alarms_per_hour=0.006) > h
    with pytest.raises(FilterOptionError, match="tail_fraction"):
        start_threshold_from_maxima(m, runs_per_hour=60.0, false_alarms_per_hour=30.0)
    with pytest.raises(FilterOptionError, match="at least 20"):
        start_threshold_from_maxima(m[:100], runs_per_hour=60.0, false_alarms_per_hour=0.06)
    # the CUSUM's maxima: one event of Z = 3 with mu1 = 3 gives 9 - 4.5
    assert start_cusum_maxima(np.array([[np.nan, 3.0, np.nan, -1.0]]),
                              shift_sigma=3.0).tolist() == [4.5]


def test_the_first_windows_are_not_tested(model, null):
    # the null leaves out the first windows of each run; the monitor does as well
    u = np.full((300, 2), 0.2)
    wrong = 3.0 * _model_ticks(model, u)         # far from the model: alarms if tested
    assert null.skip_windows == 7
    quiet = DynamicsMonitor(model, null)
    loud = DynamicsMonitor(model, dataclasses.replace(null, skip_windows=0))
    for k in range(7 * null.window_periods):
        t = (k + 1) * model.dt_s
        assert quiet.update(t, u[k], wrong[k]) == []
        loud.update(t, u[k], wrong[k])
    assert loud.alarms and not quiet.alarms and np.all(quiet.statistic == 0.0)
    with pytest.raises(FilterOptionError, match="start_shift_sigma"):
        DynamicsMonitor(model, null, start_shift_sigma=0.0)
    with pytest.raises(FilterOptionError, match="start distribution"):
        w = integrated_residuals(model, u, wrong)
        start_scores(dataclasses.replace(null, start=None), w, u)


def test_spikes_do_not_count_as_dynamics(model, null):
    u = np.full((600, 2), 0.2)
    ticks = _model_ticks(model, u)
    ticks[[200, 260, 320, 380]] += 150.0
    w = integrated_residuals(model, u, ticks, window_periods=null.window_periods)
    assert np.sum(~w.valid) == 4
    with pytest.raises(FilterOptionError, match="variance_ratio"):
        DynamicsMonitor(model, null, variance_ratio=1.0)


# -- on the simulator ----------------------------------------------------------------------------
def test_null_statistics_are_near_their_laws_on_fresh_nominal_drives(model, null):
    cmd, deltas = route_drives(model, range(1100, 1110))
    w = integrated_residuals(model, cmd, deltas, window_periods=null.window_periods)
    st = window_statistics(null, w)
    moving = np.any(w.predicted_ticks != 0.0, axis=-1)
    q = st.q[:, 7:][moving[:, 7:]]
    # chi-square with 2 degrees of freedom: median 1.39, mean 2 (the tail is heavier)
    assert 0.9 < np.median(q) < 2.0
    assert 1.5 < np.mean(q) < 3.0
    # lag evidence of informative windows: a / sqrt(b) ~ N(0, 1) under the null
    b = st.lag_information[:, 7:]
    z = st.lag_evidence[:, 7:][b > 1.0] / np.sqrt(b[b > 1.0])
    assert z.size > 300                 # about 48 informative windows a run
    assert abs(np.mean(z)) < 0.2 and 0.85 < np.std(z) < 1.2, (np.mean(z), np.std(z))
    # start scores: N(0, 1) by construction on the null's own starts (4 a run after 3 s)
    assert null.start.n_starts == 120
    sc = start_scores(null, w, cmd)
    sc = sc[np.isfinite(sc)]
    assert sc.size == 40 and abs(np.mean(sc)) < 0.5 and 0.7 < np.std(sc) < 1.4, sc


def test_streamed_start_cusum_equals_the_batch_scores(model, null):
    cmd, deltas = route_drives(model, [1100, 1101], [Fault("payload", t_s=20.0, robots=(1,),
                                                            payload_kg=1.8)])
    # budgets so small that no test alarms: the start CUSUM runs free
    mon = DynamicsMonitor(model, null, n_robots=2, lag_false_alarms_per_hour=1e-30,
                          covariance_false_alarms_per_hour=1e-30, start_threshold=1e30)
    g = []
    for k in range(cmd.shape[1]):
        mon.update((k + 1) * model.dt_s, cmd[:, k], deltas[:, k])
        if (k + 1) % null.window_periods == 0:
            g.append(mon.start_statistic.copy())
    w = integrated_residuals(model, cmd, deltas, window_periods=null.window_periods)
    sc = start_scores(null, w, cmd)
    mu = mon.start_shift_sigma
    batch = np.zeros(2)
    for j, got in enumerate(g):
        batch = np.where(np.isfinite(sc[:, j]),
                         np.maximum(0.0, batch + mu * sc[:, j] - 0.5 * mu * mu), batch)
        assert np.allclose(got, batch), j
    assert np.isfinite(sc).sum() == 8 and not mon.alarms


@pytest.mark.parametrize("label", list(DYNAMICS_FAULTS))
def test_dynamics_faults_detected(model, null, label):
    kind, params = DYNAMICS_FAULTS[label]
    res = fault_runs(model, null, kind, params)
    d = res.delays_s
    # The target: 95% and a median of 2 s. Measured (docs/monitor.md): delay 20/20, 0.97 s;
    # motor 20/20, 1.03 s; payload 20/20, 7.29 s (a payload shows only when the robot starts
    # from rest, a median 5.07 s after the onset on this route). Bounds: the measured level
    # (the design before the start test: payload 17/20, 9.68 s).
    if kind == "payload":
        assert res.detected >= 19 and np.median(d[np.isfinite(d)]) <= 8.0, d
        assert np.all(res.left_s > 19.0) and np.all(np.isfinite(res.first_start_s))
    else:
        assert res.detected >= 19 and np.median(d) <= 2.0, d


def test_nominal_false_alarms_one_hour(model, null):
    cmd, deltas = route_drives(model, range(2000, 2060))
    hours = cmd.shape[0] * cmd.shape[1] * model.dt_s / 3600.0
    alarms = sum(len(t) for t in alarm_times(model, null, cmd, deltas))
    assert hours > 0.9
    assert alarms <= 3, alarms          # measured 0.46-0.74 an hour; > 3 is a 0.7% tail at 0.74


def test_residual_monitor_raises_dynamics_changed_and_skips_innovation_tests(model, null):
    onset = 25.0
    cmd, deltas = route_drives(model, [300],
                               [Fault("delay", t_s=onset, extra_periods=3.0)])
    seen = []
    dyn = DynamicsMonitor(model, null)
    mon = ResidualMonitor(MonitorOptions(dt_s=model.dt_s), m_per_tick=model.m_per_tick,
                          on_alarm=seen.append, dynamics=dyn)
    for k in range(cmd.shape[1]):
        mon.update_commands((k + 1) * model.dt_s, cmd[0, k], deltas[0, k])
        mon.update_innovation((k + 1) * model.dt_s, np.array([5.0, 5.0]), np.eye(2) * 1.0)
    kinds = [(e.kind, e.test) for e in mon.events]
    assert kinds and kinds[0] == ("dynamics_changed", "integrated"), kinds
    assert onset <= mon.events[0].t_s <= onset + 4.0
    assert mon.events[0].onset_s <= mon.events[0].t_s
    # the delay is a lag: the lag test raised it, with a lag estimate near 3 periods
    first = next(a for a in dyn.alarms if a.onset_s >= onset - 1.0)
    assert first.test == "lag" and 1.5 < first.lag_periods < 4.5, first
    assert seen == mon.events
    # each event carries the dynamics test's alarm: its sub-test and lag estimate
    assert all(e.dynamics in dyn.alarms for e in mon.events)
    assert next(e.dynamics for e in mon.events if e.onset_s >= onset - 1.0) is first
    with pytest.raises(FilterOptionError, match="DynamicsMonitor"):
        ResidualMonitor().update_commands(0.0, np.zeros(2), np.zeros(2))

