"""Fixtures of the command-line tests."""

import numpy as np
import pytest

from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel


@pytest.fixture(scope="module")
def tiny_model() -> MotionModel:
    """A two-tap FIR model with an encoder scale: what a model file must hold, not a good fit."""
    fit = FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
                 residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps")
    return MotionModel.from_fir(fit, dt_s=0.015, wheel_base_m=0.235, m_per_tick=4.4e-4,
                                calibrated_at="2026-01-01T00:00:00+00:00")
