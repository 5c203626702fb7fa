"""Fixtures shared by the monitor tests: one calibration and one nominal null per session."""

import pytest

from benchmarks.bench_monitor import fit_route_null


@pytest.fixture(scope="session")
def route_model(ekf_example_model):
    """The monitor benchmarks' ARX model (``examples/ekf_plugin.py``'s calibration, seed 1):
    :func:`benchmarks.bench_monitor.calibrated_model` is the same calibration, so the
    session's one of the example serves (``test_route_model_is_the_benchmarks_calibration``)."""
    return ekf_example_model


@pytest.fixture(scope="session")
def route_null(route_model):
    """The dynamics null of ``route_model``, fitted on 30 nominal route drives."""
    return fit_route_null(route_model)
