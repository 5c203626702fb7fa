"""Fixtures shared by the EKF tests: the synthetic ARX model, fitted once a session."""

import pytest
from synthetic_ekf_model import fitted_model


@pytest.fixture(scope="session")
def model():
    """A fitted ARX model, q_scale 1.3 (so Q > K R K^T), D = 0, K != 0, nz = 4 (a module
    that needs another model defines its own ``model``)."""
    return fitted_model()
