"""The posterior change time (``fusion.monitoring.change_time``) and, on the route, faults
that come together: found no slower than the slower alone, never dated before they began by
more than the stated interval."""

import math

import numpy as np
import pytest

from benchmarks.bench_monitor import route_drives
from drivers.sim.config import Fault
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitoring.change_time import (
    ChangeTimeRule,
    ChangeTimeTracker,
    change_time,
    change_time_posterior,
)
from fusion.monitoring.dynamics import DynamicsMonitor


def _lag_llr(a, b, theta1=1.0):
    """The lag test's increments (``fusion.monitoring.dynamics`` eq. 3)."""
    return theta1 * a - 0.5 * theta1 ** 2 * b


def test_posterior_finds_a_lag_that_starts_late_in_a_long_quiet_history(rng):
    # 100 windows of null evidence, then a lag of 2 periods: a ~ N(2 b, b)
    b = rng.uniform(0.0, 6.0, 130)
    theta = np.r_[np.zeros(100), np.full(30, 2.0)]
    a = theta * b + np.sqrt(b) * rng.standard_normal(130)
    t0 = 0.45 * np.arange(130)
    when = change_time(t0, _lag_llr(a, b), window_s=0.45)
    assert 40.0 <= when.lo_s <= 45.0 and when.hi_s == pytest.approx(t0[-1] + 0.45)
    assert abs(when.onset_s - 45.0) <= 2.0
    p = change_time_posterior(_lag_llr(a, b))
    assert p.sum() == pytest.approx(1.0) and p[:80].sum() < 0.01
    # a tempered likelihood states a wider interval
    wide = change_time(t0, _lag_llr(a, b), window_s=0.45, rule=ChangeTimeRule(temperature=0.25))
    assert wide.lo_s <= when.lo_s


def test_without_evidence_the_interval_spans_the_history():
    t0 = 0.45 * np.arange(40)
    when = change_time(t0, np.zeros(40), window_s=0.45)
    assert when.lo_s <= 2.0 and when.hi_s == pytest.approx(18.0)


def test_tracker_keeps_each_robots_windows_since_its_reset():
    tr = ChangeTimeTracker(2, 1, window_s=0.45, rule=ChangeTimeRule(max_windows=50))
    for j in range(80):                       # robot 1 lags from window 60 on
        tr.push(0.45 * j, np.array([[-1.0], [3.0 if j >= 60 else -1.0]]))
    assert tr.estimate(1, 0).onset_s == pytest.approx(0.45 * 60)
    assert tr.estimate(0, 0).lo_s >= 0.45 * 30 - 1e-9   # only the last 50 windows kept
    tr.reset(1)
    assert math.isnan(tr.estimate(1, 0).onset_s)


def test_bad_input_is_a_clear_error():
    with pytest.raises(FilterOptionError, match="level"):
        ChangeTimeRule(level=1.0)
    with pytest.raises(FilterOptionError, match="temperature"):
        ChangeTimeRule(temperature=0.0)
    with pytest.raises(MeasurementShapeError, match="non-empty 1-d array"):
        change_time_posterior(np.zeros((3, 2)))
    with pytest.raises(MeasurementShapeError, match="finite"):
        change_time_posterior(np.array([0.0, np.nan]))


# -- faults that come together, on the route ------------------------------------------------------
N = 10
MIXES = {"motor": (("motor", {"weakening": 0.2}),),
         "delay": (("delay", {"extra_periods": 3.0}),),
         "motor+delay": (("motor", {"weakening": 0.2}), ("delay", {"extra_periods": 3.0}))}


@pytest.fixture(scope="module")
def first_alarms(route_model, route_null):
    """Per mix: (onset, alarm time, first DynamicsAlarm at or after the onset) per run."""
    onsets = np.random.default_rng(11).uniform(15.0, 40.0, N)
    out = {}
    for mix, faults in MIXES.items():
        sim_faults = [Fault(kind, t_s=float(onsets[i]), robots=(i,), **params)
                      for i in range(N) for kind, params in faults]
        cmd, deltas = route_drives(route_model, range(600, 600 + N), sim_faults)
        mon = DynamicsMonitor(route_model, route_null, n_robots=N)
        hits = [None] * N
        for k in range(cmd.shape[1]):
            t = (k + 1) * route_model.dt_s
            for a in mon.update(t, cmd[:, k], deltas[:, k]):
                if hits[a.robot] is None and t >= onsets[a.robot]:
                    hits[a.robot] = (t, a)
            if all(hits):                   # every robot's first alarm is in
                break
        out[mix] = [(onsets[i], *(hits[i] or (math.inf, None))) for i in range(N)]
    return out


def test_faults_together_are_found_no_slower_than_the_slower_alone(first_alarms):
    median = {mix: float(np.median([t - on for on, t, _ in runs]))
              for mix, runs in first_alarms.items()}
    assert all(math.isfinite(m) for m in median.values()), median
    assert median["motor+delay"] <= max(median["motor"], median["delay"]), median


def test_no_onset_is_dated_before_the_fault_by_more_than_its_interval(first_alarms):
    outside = 0
    for mix, runs in first_alarms.items():
        for on, t, alarm in runs:
            assert alarm is not None, mix
            # the estimate within its interval, which ends with the alarm's window
            assert alarm.onset_lo_s <= alarm.onset_s <= alarm.onset_hi_s <= t + 1e-9
            # the true onset lies no later than the stated interval's end
            assert on <= alarm.onset_hi_s, (mix, on, alarm)
            outside += not alarm.onset_lo_s <= on
    # a 90% interval: 3 of 30 outside expected; more than 6 has a 2.6% binomial tail
    assert outside <= 6, outside
