"""Shared fixtures: seeded randomness, and the real recorded data."""

import importlib.util
import os
import sys
from pathlib import Path

# One OpenBLAS thread unless the caller chose (before numpy is imported): the tests' matrices
# are small, and on two cores the second thread only spins and takes the core another process
# needs. Measured: tests/lti_motion/calibration/test_calibration_sim.py 23.6 -> 8.2 s CPU and
# 44 -> 16 s wall on a loaded 2-core machine, outputs bit-identical.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator; tests never use unseeded randomness."""
    return np.random.default_rng(20261123)


def data_dir() -> Path | None:
    """Real robot data (docs/mrclam.md): ``LTI_MOTION_DATA`` (the Makefile sets it), else the
    data folder beside the checkout, where the Makefile looks too; ``None`` if neither."""
    env = os.environ.get("LTI_MOTION_DATA")
    path = Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"
    return path if path.is_dir() else None


@pytest.fixture(scope="session")
def mrclam_path() -> Path:
    """The MRCLAM set 6 folder. Absent data fails under CI and skips elsewhere."""
    base = data_dir()
    path = None if base is None else base / "mrclam" / "MRCLAM_Dataset6"
    if path is None or not path.is_dir():
        if os.environ.get("CI"):
            pytest.fail("MRCLAM data not found: set LTI_MOTION_DATA to the shared data folder")
        pytest.skip("MRCLAM data not found (set LTI_MOTION_DATA)")
    return path


@pytest.fixture(scope="session")
def censi_path() -> Path:
    """Censi et al.'s (2013) Khepera interval samples and results (data/README.md,
    ``real/censi2013``). Absent data fails under CI and skips elsewhere."""
    base = data_dir()
    path = None if base is None else base / "real" / "censi2013"
    if path is None or not path.is_dir():
        if os.environ.get("CI"):
            pytest.fail("Censi 2013 data not found: set LTI_MOTION_DATA to the shared data folder")
        pytest.skip("Censi 2013 data not found (set LTI_MOTION_DATA)")
    return path


ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def load_example():
    """Load ``examples/NAME.py`` as a module (once per session), to share its helpers."""
    cache = {}

    def load(name: str):
        if name not in cache:
            spec = importlib.util.spec_from_file_location(f"{name}_example",
                                                          ROOT / "examples" / f"{name}.py")
            module = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = module
            spec.loader.exec_module(module)
            cache[name] = module
        return cache[name]

    return load


@pytest.fixture(scope="session")
def ekf_example_model(load_example):
    """``examples/ekf_plugin.py``'s calibrated model, calibrated once per session (the
    calibration is deterministic and a ``MotionModel`` is frozen)."""
    return load_example("ekf_plugin").calibrate_model()


@pytest.fixture(scope="session")
def short_arx_model():
    """``short_arx_model(seed)``: the ARX model of a create2 calibration on the simulator with
    40 s of excitation (simulator and plan seeded ``seed``), calibrated once per seed and
    session (deterministic; a ``MotionModel`` is frozen)."""
    from drivers.sim.calibration import calibrate_simulator
    from lti_motion.calibration.manoeuvres import CalibrationPlan

    cache = {}

    def model(seed: int):
        if seed not in cache:
            cache[seed] = calibrate_simulator(
                "create2", seed=seed, plan=CalibrationPlan(seed=seed, excitation_s=40.0)).arx
        return cache[seed]

    return model
