"""One error for a model without an encoder scale, in every layer that needs the scale.

Each place that turns encoder counts into distances raises
:class:`lti_motion.exceptions.MissingEncoderScaleError` (a ``ValueError``), and its
message says what the library user can do: calibrate with the rotation in place, or pass
``m_per_tick=`` where the call takes one. (The command line's own message is tested in
``tests/lti_motion/app/test_cli.py``.)
"""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel


@pytest.fixture(scope="module")
def unscaled() -> MotionModel:
    """A small stable model with no encoder scale (``m_per_tick`` None)."""
    return MotionModel(kind="arx", A=0.5 * np.eye(2), B=np.eye(2), C=np.eye(2),
                       D=np.zeros((2, 2)), K=0.5 * np.eye(2), Q=1e-4 * np.eye(2),
                       R=1e-4 * np.eye(2), dt_s=0.015, wheel_base_m=0.235, m_per_tick=None,
                       coefficients={}, orders={}, calibrated_at="2026-01-01T00:00:00")


def _encoder_speeds(model):
    from fusion.ekf.functions import FilterModel, encoder_speeds

    encoder_speeds(np.array([[0, 0], [10, 10]]), FilterModel(model))


def _model_ekf(model):
    from fusion.ekf.model_ekf import ModelEKF

    ekf = ModelEKF(model, initial_ticks=(0, 0))
    ekf.predict((0.1, 0.1))
    ekf.update_encoders((10, 10))


def _residual_monitor(model):
    from fusion.monitoring.residual import MonitorOptions, ResidualMonitor

    ResidualMonitor(MonitorOptions(dt_s=model.dt_s)).update_counts(0.0, (0.0, 0.0), (0.1, 0.1))


def _rescale(model):
    from fusion.monitoring.rescale import rescaled_model

    rescaled_model(model, m_per_tick=4.4e-4, wheel_base_m=0.235)


def _dynamics(model):
    from fusion.monitoring.dynamics_null import WindowIntegrator

    WindowIntegrator(model)


def _smooth_log(model):
    from drivers.sim.simulator import Simulator
    from fusion.graph.smoother import smooth_log

    smooth_log(model, Simulator("create2", seed=0).run(np.zeros((5, 2))),
               initial_pose=np.zeros(3))


def _route_smoother(model):
    from lti_motion.app.route_smoother import SmootherEstimator

    SmootherEstimator(model)


def _monitor_frames(model):
    from lti_motion.app.monitor import monitor_frames

    monitor_frames(model, iter(()))


#: (where, call, the keyword the message offers, or None when only calibrating helps)
SITES = [
    ("fusion.ekf.functions.encoder_speeds", _encoder_speeds, "m_per_tick=... to the filter"),
    ("fusion.ekf.ModelEKF.update_encoders", _model_ekf, "m_per_tick=... to the filter"),
    ("fusion.monitoring.ResidualMonitor.update_counts", _residual_monitor,
     "ResidualMonitor(m_per_tick=...)"),
    ("fusion.monitoring.rescale", _rescale, None),
    ("fusion.monitoring.dynamics_null.WindowIntegrator", _dynamics, None),
    ("fusion.graph.smoother.smooth_log", _smooth_log, None),
    ("lti_motion.app.route_smoother.SmootherEstimator", _route_smoother, None),
    ("lti_motion.app.monitor.monitor_frames", _monitor_frames, None),
]


@pytest.mark.parametrize(("call", "keyword"), [pytest.param(c, k, id=w) for w, c, k in SITES])
def test_every_layer_raises_the_one_error_with_what_to_do(unscaled, call, keyword):
    with pytest.raises(MissingEncoderScaleError, match="needs the encoder scale") as info:
        call(unscaled)
    message = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "calibrate the model with the rotation in place" in message
    assert "lti_motion.calibration.calibrate" in message
    if keyword is not None:
        assert f"pass {keyword}" in message


def test_the_filter_takes_the_scale_the_message_offers(unscaled):
    """What the message tells a library user to do works: the same update with
    ``m_per_tick=`` fuses the counts."""
    from fusion.ekf.model_ekf import ModelEKF

    ekf = ModelEKF(unscaled, initial_ticks=(0, 0), m_per_tick=4.4e-4)
    ekf.predict((0.1, 0.1))
    assert ekf.update_encoders((3, 3)).nis >= 0.0
