"""Recalibration after the monitor's own dynamics alarms (fault-detection issue).

The policy's bookkeeping (segments at time gaps, the excitation request, automatic
retries, the refit's steady-state gain), then a short form of the benchmark
(``benchmarks/bench_monitor.py``, ``recalibration``: 20 runs per fault): route runs with
a fault, the monitor's first alarm after the onset, an excitation manoeuvre on request,
and the fit of the model in use on fresh faulty data against the nominal fit.
"""

import numpy as np
import pytest

from benchmarks.bench_monitor import (
    DYNAMICS_FAULTS,
    calibrated_model,
    excitation_speeds,
    fit_route_null,
    recalibration_runs,
)
from fusion.exceptions import FilterOptionError
from fusion.monitor import AlarmEvent
from fusion.recalibration import Recalibrator


@pytest.fixture(scope="module")
def model():
    return calibrated_model()


@pytest.fixture(scope="module")
def null(model):
    return fit_route_null(model)


def _alarm(t_s=10.0, onset_s=0.0):
    return AlarmEvent(t_s, "dynamics_changed", "integrated", 9.0, 6.9, onset_s, 0)


def test_waiting_asks_for_excitation_once_and_retries_as_data_comes(model):
    asked = []
    rc = Recalibrator(model, min_samples=3000, retry_samples=500,
                      request_excitation=asked.append)
    u, y = excitation_speeds(model, [], seed=3, duration_s=60.0)
    for k in range(200):
        rc.add(k * model.dt_s, u[k], y[k])
    first = rc.on_alarm(_alarm(t_s=3.0))
    assert first.action == "waiting" and rc.waiting and len(asked) == 1
    assert rc.on_alarm(_alarm(t_s=3.5)).action == "waiting" and len(asked) == 1
    # more data after a gap: a new segment; the refit retries by itself every 500 samples
    for k in range(len(u) - 200):
        rc.add(10.0 + k * model.dt_s, u[200 + k], y[200 + k])
        if not rc.waiting:
            break
    assert not rc.waiting
    last = rc.history[-1]
    assert last.action in ("adopted", "kept_old") and last.n_samples >= 3000
    # attempts: the two alarms, then a retry each 500 samples until 3000 were there
    assert [r.action for r in rc.history[:-1]] == ["waiting"] * (len(rc.history) - 1)
    assert rc.retry() is None


def test_segments_split_at_gaps_and_short_ones_are_dropped(model):
    rc = Recalibrator(model, min_samples=100)
    dt = model.dt_s
    for k in range(300):
        rc.add(k * dt, np.full(2, 0.1), np.zeros(2))
    for k in range(50):                                   # too short to train on
        rc.add(20.0 + k * dt, np.full(2, 0.2), np.zeros(2))
    for k in range(400):
        rc.add(30.0 + k * dt, np.full(2, 0.3), np.zeros(2))
    runs = rc._segments(0.0)
    assert [len(u) for u, _ in runs] == [300, 50, 400]
    assert [float(u[0, 0]) for u, _ in runs] == [0.1, 0.2, 0.3]
    assert [len(u) for u, _ in rc._segments(25.0)] == [400]


def test_refit_gain_follows_the_model_in_use(model):
    assert "dc_gain_scale" in model.diagnostics              # calibrated as a wheel servo
    assert Recalibrator(model).dc_gain == "wheel_servo"
    assert Recalibrator(model, dc_gain="free").dc_gain == "free"
    with pytest.raises(FilterOptionError, match="dc_gain"):
        Recalibrator(model, dc_gain="servo")


@pytest.mark.parametrize("kind", ["delay", "payload"])
def test_after_the_monitors_alarm_the_fit_returns_within_2_points(model, null, kind):
    # benchmark (20 runs): delay adopted in 20 of 20, old model 87.8% -> in use 92.0% against
    # 92.2% before the fault; payload: the PID loop hides it from the fit (old model within
    # 1 pp), 14 of 17 keep the old model. Here 4 runs each.
    label = next(k for k, v in DYNAMICS_FAULTS.items() if v[0] == kind)
    res = recalibration_runs(model, null, kind, DYNAMICS_FAULTS[label][1], n=4)
    done = np.isfinite(res.fit_in_use)
    assert done.sum() >= 3, res.actions
    diff = res.fit_in_use[done] - res.fit_before[done]
    assert np.all(diff >= -2.0), (diff, res.actions)
    if kind == "delay":
        assert res.actions == ["adopted"] * 4
        assert np.all(res.fit_old[done] < res.fit_before[done] - 2.0)   # the fault shows
        assert np.all(res.fit_in_use[done] > res.fit_old[done] + 2.0)
