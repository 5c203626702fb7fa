"""Tests of lti_motion.model.output_error: the output-error refinement and the affine offset.

The synthetic plant (tests/synthetic_plant.py) has white noise on its *outputs*,
the case where least squares on the equation error is biased (Ljung 1999,
section 7.3) and the output-error criterion is not.
"""

import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, DT, commands, plant

from lti_motion.exceptions import CalibrationError
from lti_motion.model.arx import estimate_arx
from lti_motion.model.motion_model import MotionModel
from lti_motion.model.output_error import OutputErrorOptions, refine_output_error

OFFSET = np.array([0.004, -0.03])      # v [m/s], w [rad/s]
WARMUP = 10


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(5)
    u_fit, u_val = commands(rng, 2500), commands(rng, 2500)
    return (u_fit, plant(u_fit, rng) + OFFSET), (u_val, plant(u_val, rng) + OFFSET)


def _model(fit, offset=(0.0, 0.0)):
    return MotionModel.from_arx(fit, dt_s=DT, wheel_base_m=BASE,
                                calibrated_at="2026-12-01T00:00:00+00:00"
                                ).updated(offset_speeds=offset)


def _integrated_error(model, u, y, horizon):
    """RMS of the speed error integrated over ``horizon`` samples (moving sum x dt)."""
    e = y[WARMUP:] - model.simulate(u[WARMUP:], z0=model.state_from_data(u[:WARMUP], y[:WARMUP]))
    cs = np.vstack([np.zeros((1, 2)), np.cumsum(e, axis=0)]) * DT
    return np.sqrt(np.mean((cs[horizon:] - cs[:-horizon]) ** 2, axis=0))


def test_refinement_recovers_the_offset_and_integrates_better_on_fresh_data(data):
    (u, y), (u_val, y_val) = data
    ls = estimate_arx([(u, y)], na=2, delay=DELAY)
    oe = refine_output_error(ls, [(u, y)], dt_s=DT, warmup=WARMUP,
                             options=OutputErrorOptions(horizons_s=(1.0, 10.0)))
    assert oe.cost_end < 0.5 * oe.cost_start
    assert np.all(np.abs(oe.offset_speeds - OFFSET) < [1e-3, 3e-3]), oe.offset_speeds
    before, after = _model(ls), _model(oe.fit, oe.offset_speeds)
    h = round(10.0 / DT)
    err_ls, err_oe = (_integrated_error(m, u_val, y_val, h) for m in (before, after))
    assert np.all(err_oe < 0.5 * err_ls), (err_oe, err_ls)
    assert np.all(after.fit_percent([(u_val, y_val)], warmup=WARMUP)
                  > before.fit_percent([(u_val, y_val)], warmup=WARMUP))


def test_without_the_offset_term_the_offset_stays_zero_and_fir_is_the_na_0_case(data):
    (u, y), _ = data
    ls = estimate_arx([(u, y - OFFSET)], na=0, nb=6, delay=DELAY)
    oe = refine_output_error(ls, [(u, y - OFFSET)], dt_s=DT, warmup=WARMUP,
                             options=OutputErrorOptions(horizons_s=(1.0,), offset=False,
                                                        max_nfev=2))
    assert oe.offset_speeds.tolist() == [0.0, 0.0]
    assert oe.fit.na == 0 and oe.fit.nb == 6 and oe.cost_end <= oe.cost_start


def test_pose_horizons_join_the_criterion(data):
    (u, y), _ = data
    ls = estimate_arx([(u, y)], na=2, delay=DELAY)
    oe = refine_output_error(ls, [(u, y)], dt_s=DT, warmup=WARMUP,
                             options=OutputErrorOptions(horizons_s=(), pose_horizons_s=(3.0,),
                                                        max_nfev=8))
    assert oe.cost_end < oe.cost_start
    assert np.all(np.abs(oe.offset_speeds - OFFSET) < [2e-3, 1e-2]), oe.offset_speeds


def test_bad_input_is_refused(data):
    (u, y), _ = data
    ls = estimate_arx([(u, y)], na=2, delay=DELAY)
    with pytest.raises(CalibrationError, match="longer than the 10-sample warm-up"):
        refine_output_error(ls, [(u[:8], y[:8])], dt_s=DT, warmup=WARMUP)
    with pytest.raises(ValueError, match="horizons_s must be positive"):
        OutputErrorOptions(horizons_s=(0.0,))
    unstable = ls.__class__(**{**ls.__dict__, "a": np.array([1.5 * np.eye(2)] * 2)})
    with pytest.raises(CalibrationError, match="unstable"):
        refine_output_error(unstable, [(u, y)], dt_s=DT, warmup=WARMUP)


def test_the_calibration_plan_takes_the_criterion_by_name():
    from lti_motion.calibration.manoeuvres import CalibrationPlan
    assert CalibrationPlan().arx_criterion == "equation"
    assert CalibrationPlan(arx_criterion="output_error").arx_criterion == "output_error"
    assert CalibrationPlan(arx_criterion="output_scales").arx_criterion == "output_scales"
    with pytest.raises(ValueError, match="arx_criterion must be 'equation', 'output_scales' or"):
        CalibrationPlan(arx_criterion="simulation")
