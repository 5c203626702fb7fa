"""Tests of lti_motion.model.motion_model: calibration end to end, prediction modes, noise,
persistence.

The synthetic plant is the one of test_arx.py (second-order wheels, 4-sample
delay, v = (vR + vL) / 2, w = (vR - vL) / 0.235, white noise on v and w).
"""

import dataclasses
import json
import os

import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, DT, NOISE, commands, plant, wheel_filters

from lti_motion.exceptions import (
    CalibrationError,
    ModelFileError,
    NonFiniteError,
    NotExcitedError,
    ShapeError,
    UnstableModelError,
)
from lti_motion.kinematics import integrate_poses
from lti_motion.metrics import fit_percent
from lti_motion.model.arx import arx_regression, arx_state_space
from lti_motion.model.excitation import random_held_normal, step_sequence
from lti_motion.model.motion_model import FORMAT, VERSION, MotionModel, fit_arx, fit_fir_from_steps
from lti_motion.model.state_space import simulate_state_space, simulate_state_space_loop
from lti_motion.persistence import write_document

WHEN = "2026-11-23T12:00:00+00:00"


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(21)
    return [(u, plant(u, rng)) for u in (commands(rng, 4000), commands(rng, 4000))]


@pytest.fixture(scope="module")
def arx_model(runs):
    return fit_arx(runs, dt_s=DT, wheel_base_m=BASE, floor="tiles", calibrated_at=WHEN)


@pytest.fixture(scope="module")
def fir_model(runs):
    rng = np.random.default_rng(22)
    seq = step_sequence(amplitude_m_s=0.3, hold_s=1.0, rest_s=1.0, dt_s=DT)
    y = plant(seq.cmd_m_s, rng)
    return fit_fir_from_steps(seq.cmd_m_s, y, phases=seq, dt_s=DT, wheel_base_m=BASE,
                              noise_runs=runs, calibrated_at=WHEN, m_per_tick=4.45e-4)


@pytest.fixture(scope="module")
def fresh():
    rng = np.random.default_rng(23)
    u = commands(rng, 5000)
    return u, plant(u, rng)


def test_arx_calibration_end_to_end(arx_model, fresh):
    m = arx_model
    assert m.kind == "arx" and m.orders["delay"] == DELAY
    assert m.orders["na"] == m.orders["nb"] == m.selection.order
    assert m.diagnostics["validation_fit_v"] >= 95 and m.diagnostics["validation_fit_w"] >= 95
    assert np.all(m.fit_percent([fresh]) >= 95.0)  # free run on data never seen
    assert np.all(m.fit_percent([fresh], mode="one_step") >= 95.0)
    assert m.floor == "tiles" and m.calibrated_at == WHEN and m.q_scale >= 1.0
    np.testing.assert_array_equal(m.coefficients["a"], m.selection.fit.a.shape and
                                  m.coefficients["a"])


def test_fir_calibration_from_steps_free_runs_above_90_percent(fir_model, fresh):
    m = fir_model
    assert m.kind == "fir" and 10 <= m.orders["n_taps"] <= 30
    u, y = fresh
    assert np.all(fit_percent(y, m.simulate(u)) >= 90.0)
    assert m.m_per_tick == 4.45e-4


@pytest.mark.parametrize("kind", ["arx", "fir"])
def test_simulate_equals_the_plain_state_space_recursion(kind, arx_model, fir_model, rng):
    m = arx_model if kind == "arx" else fir_model
    u = commands(rng, 1500)
    np.testing.assert_allclose(m.simulate(u), simulate_state_space_loop(
        m.A, m.B, m.C, m.D, u)[0], rtol=0, atol=1e-9)
    batch = np.stack([u[:700], u[700:1400]])
    z0 = rng.normal(size=(2, m.n_states)) * 0.01
    np.testing.assert_allclose(m.simulate(batch, z0=z0), simulate_state_space_loop(
        m.A, m.B, m.C, m.D, batch, z0=z0)[0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["arx", "fir"])
def test_noise_covariances_are_symmetric_positive_definite(kind, arx_model, fir_model):
    m = arx_model if kind == "arx" else fir_model
    for cov in (m.Q, m.R):
        np.testing.assert_array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() > 0
    if kind == "arx":  # one-step residuals: the measurement noise, slightly coloured
        np.testing.assert_allclose(np.sqrt(np.diag(m.R)), NOISE, rtol=0.25)
    else:  # the FIR's residuals also hold its own errors on random data
        assert np.all(np.sqrt(np.diag(m.R)) > NOISE)
    np.testing.assert_allclose(m.S, m.K @ m.R)
    assert np.abs(m.poles()).max() < 1


def test_one_step_prediction_is_the_arx_regression(arx_model, fresh):
    m = arx_model
    u, y = fresh
    phi, target = arx_regression([(u, y)], na=m.orders["na"], nb=m.orders["nb"],
                                 delay=m.orders["delay"])
    theta = np.concatenate([m.coefficients["b"].transpose(0, 2, 1).reshape(-1, 2),
                            m.coefficients["a"].transpose(0, 2, 1).reshape(-1, 2)])
    start = len(y) - len(target)
    np.testing.assert_allclose(m.predict_one_step(u, y)[start:], phi @ theta, atol=1e-9)


def test_state_from_data_continues_a_free_run(arx_model, fresh):
    m = arx_model
    u, y = fresh
    whole = m.simulate(u)
    _, z = m.propagate(u[:1234])
    np.testing.assert_allclose(m.simulate(u[1234:], z0=z), whole[1234:], atol=1e-12)
    # from measured data, the state is exact after n_states // 2 samples, whatever z0
    z1 = m.state_from_data(u[:300], y[:300])
    z2 = m.state_from_data(u[:300], y[:300], z0=np.ones(m.n_states))
    np.testing.assert_allclose(z1, z2, atol=1e-12)


@pytest.mark.parametrize("kind", ["arx", "fir"])
def test_predict_poses_integrates_the_simulated_speeds(kind, arx_model, fir_model, rng):
    m = arx_model if kind == "arx" else fir_model
    u = commands(rng, 600)
    start = np.array([1.0, -2.0, 0.3])
    np.testing.assert_allclose(m.predict_poses(u, initial_pose=start),
                               integrate_poses(m.simulate(u), DT, initial_pose=start))
    u_step = np.tile([0.2, 0.2 / 0.95], (400, 1))  # the right wheel's gain is 0.95
    truth = integrate_poses(plant(u_step), DT)  # 1.18 m, nearly straight
    poses = m.predict_poses(u_step)
    assert poses.shape == (401, 3)
    # the FIR's gains carry the noise of two steps; the ARX saw 8000 samples
    np.testing.assert_allclose(poses[-1], truth[-1], atol=0.01 if kind == "arx" else 0.1)


def test_free_run_error_growth_is_explained_by_q_and_r():
    """Data from an equation-error ARX: predicted and measured free-run covariances agree."""
    rng = np.random.default_rng(24)
    (bl, al), (br, ar) = wheel_filters()
    t = np.array([[0.5, 0.5], [-1 / BASE, 1 / BASE]])
    a = np.array([t @ np.diag([-al[k], -ar[k]]) @ np.linalg.inv(t) for k in (1, 2)])
    b = np.array([t @ np.diag([bl[j], br[j]]) for j in (0, 1)])
    ss = arx_state_space(a, b, delay=DELAY)
    chol = np.diag(NOISE)

    def generate(u):
        e = rng.normal(size=u.shape) @ chol
        return simulate_state_space(ss.A, np.hstack([ss.B, ss.K]), ss.C,
                                    np.hstack([ss.D, np.eye(2)]), np.concatenate([u, e], -1))[0]

    data = [(u, generate(u)) for u in (commands(rng, 4000), commands(rng, 4000))]
    m = fit_arx(data, dt_s=DT, wheel_base_m=BASE, orders=range(1, 5), delays=range(2, 7),
                calibrated_at=WHEN)
    u = np.stack([commands(rng, 300) for _ in range(300)])
    err = generate(u) - m.simulate(u)  # from rest: the state is known
    measured = np.einsum("rhc,rhc->hc", err, err) / len(u)
    predicted = np.diagonal(m.output_error_covariance(300), axis1=1, axis2=2)
    for h in (0, 1, 3, 10, 30, 100, 299):
        ratio = measured[h] / predicted[h]
        assert np.all((ratio > 0.7) & (ratio < 1.35)), (h, ratio)
    assert predicted[-1, 1] > 1.2 * predicted[0, 1]  # the error grows with the horizon


def test_saturation_and_dead_zone_still_give_a_stable_model():
    rng = np.random.default_rng(25)
    data = []
    for _ in range(2):
        u = random_held_normal(n=4000, dt_s=DT, rng=rng, std_m_s=0.35, max_m_s=0.6)
        data.append((u, plant(u, rng, saturation=0.5, dead_zone=0.03)))
    m = fit_arx(data, dt_s=DT, wheel_base_m=BASE, calibrated_at=WHEN)
    assert np.abs(m.poles()).max() < 1
    assert m.diagnostics["validation_fit_v"] > 85 and m.diagnostics["validation_fit_w"] > 85


def _same(a, b):
    for f in dataclasses.fields(MotionModel):
        if f.name == "selection":
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), f.name
        elif f.name == "coefficients":
            assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
        else:
            assert x == y, f.name


@pytest.mark.parametrize("kind", ["arx", "fir"])
def test_save_load_round_trip_is_exact_and_atomic(kind, arx_model, fir_model, tmp_path):
    m = arx_model if kind == "arx" else fir_model
    path = m.save(tmp_path / "model.json")
    assert os.listdir(tmp_path) == ["model.json"]  # no temporary file left
    loaded = MotionModel.load(path)
    _same(m, loaded)
    assert loaded.selection is None
    doc = json.loads(path.read_text())
    assert doc["format"] == FORMAT and doc["version"] == VERSION == 3


def test_failed_write_keeps_the_old_file(arx_model, fir_model, tmp_path, monkeypatch):
    path = arx_model.save(tmp_path / "model.json")
    before = path.read_bytes()

    def crash(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        fir_model.save(path)
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["model.json"]


def test_damaged_files_raise_model_file_error(arx_model, tmp_path):
    path = arx_model.save(tmp_path / "model.json")
    text = path.read_text()
    cases = {
        "truncated": (text[: len(text) // 2], "damaged or truncated"),
        "garbage": ("\x00\xff binary", "damaged or truncated"),
        "edited": (text.replace('"tiles"', '"carpet"'), "checksum"),
        "version": (text.replace(f'"version": {VERSION}', '"version": 99'), "version 99"),
        "format": (text.replace(FORMAT, "something-else"), "not a"),
        "list": ("[1, 2, 3]", "not a"),
    }
    for name, (content, match) in cases.items():
        bad = tmp_path / f"{name}.json"
        bad.write_bytes(content.encode("utf-8", "surrogateescape"))
        with pytest.raises(ModelFileError, match=match):
            MotionModel.load(bad)
    doc = json.loads(text)
    payload = {k: v for k, v in doc.items() if k not in ("format", "version", "sha256", "floor")}
    write_document(tmp_path / "missing.json", payload, fmt=FORMAT, version=VERSION)
    with pytest.raises(ModelFileError, match=r"lacks the keys \['floor'\]"):
        MotionModel.load(tmp_path / "missing.json")
    payload["floor"] = None
    payload["matrices"]["Q"]["data"][0] = -1.0  # checksum fine, model invalid
    write_document(tmp_path / "invalid.json", payload, fmt=FORMAT, version=VERSION)
    with pytest.raises(ModelFileError, match=r"invalid model.*Q must be symmetric positive"):
        MotionModel.load(tmp_path / "invalid.json")
    with pytest.raises(FileNotFoundError):
        MotionModel.load(tmp_path / "nothing-here.json")


def test_models_are_immutable_and_update_by_copy(arx_model):
    with pytest.raises(dataclasses.FrozenInstanceError):
        arx_model.dt_s = 0.02
    with pytest.raises(ValueError):
        arx_model.A[0, 0] = 1.0
    moved = arx_model.updated(m_per_tick=5e-4, floor="carpet")
    assert moved.m_per_tick == 5e-4 and moved.floor == "carpet" and arx_model.floor == "tiles"
    with pytest.raises(ShapeError, match=r"MotionModel\.B must have shape"):
        arx_model.updated(B=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="R must be symmetric positive definite"):
        arx_model.updated(R=np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(UnstableModelError, match="pole magnitudes"):
        arx_model.updated(A=np.eye(arx_model.n_states) * 1.01)
    with pytest.raises(ValueError, match=r"isoformat|Invalid"):
        arx_model.updated(calibrated_at="yesterday")


def test_bad_inputs_raise_clear_errors(runs, arx_model):
    u, y = runs[0]
    with pytest.raises(ShapeError, match=r"\(4000, 2\) but y has shape \(3000, 2\)"):
        fit_arx([(u, y[:3000])], dt_s=DT, wheel_base_m=BASE)
    y_bad = y.copy()
    y_bad[42, 1] = np.inf
    with pytest.raises(NonFiniteError, match=r"run 0: y\[42, 1\] \(w\) is inf"):
        fit_arx([(u, y_bad)], dt_s=DT, wheel_base_m=BASE)
    with pytest.raises(CalibrationError, match="at least"):
        fit_arx([(u[:60], y[:60])], dt_s=DT, wheel_base_m=BASE)
    with pytest.raises(NotExcitedError, match="condition number"):
        fit_arx([(np.column_stack([u[:, 0], u[:, 0]]), y)], dt_s=DT, wheel_base_m=BASE)
    growing = np.cumsum(np.abs(y), axis=0)  # a drifting output fits an unstable model
    with pytest.raises(UnstableModelError, match="pole magnitudes"):
        fit_arx([(u, growing)], dt_s=DT, wheel_base_m=BASE, orders=[1], delays=[0])
    with pytest.raises(NonFiniteError, match="u"):
        arx_model.simulate(np.full((10, 2), np.nan))
    with pytest.raises(ShapeError, match=r"\(\.\.\., n, 2\)"):
        arx_model.simulate(np.zeros((10, 3)))
    with pytest.raises(ShapeError, match="speeds has shape"):
        arx_model.predict_one_step(u, y[:-1])


def test_model_file_carries_the_intrinsics_and_reads_version_1(arx_model, tmp_path):
    from lti_motion.intrinsics import OdometryIntrinsics

    k = OdometryIntrinsics(4.49e-4, 4.4455e-4, 0.236)
    with_k = arx_model.updated(intrinsics=k, m_per_tick=k.m_per_tick)
    loaded = MotionModel.load(with_k.save(tmp_path / "v2.json"))
    assert loaded.intrinsics == k and loaded.encoder_intrinsics == k
    # a version-1 file (no "intrinsics" key) still loads, on its one scale
    doc = json.loads(arx_model.save(tmp_path / "x.json").read_text())
    payload = {key: v for key, v in doc.items()
               if key not in ("format", "version", "sha256", "intrinsics")}
    write_document(tmp_path / "v1.json", payload, fmt=FORMAT, version=1)
    old = MotionModel.load(tmp_path / "v1.json")
    assert old.intrinsics is None
    if old.m_per_tick is not None:
        assert old.encoder_intrinsics == OdometryIntrinsics.symmetric(
            m_per_tick=old.m_per_tick, wheel_base_m=old.wheel_base_m)
    # a version-2 file without the key, or with nonsense in it, is refused
    write_document(tmp_path / "v2bad.json", payload, fmt=FORMAT, version=2)
    with pytest.raises(ModelFileError, match=r"lacks the keys \['intrinsics'\]"):
        MotionModel.load(tmp_path / "v2bad.json")
    payload["intrinsics"] = {"m_per_tick_left": -1.0, "m_per_tick_right": 4e-4,
                             "wheel_base_m": 0.2}
    write_document(tmp_path / "v2neg.json", payload, fmt=FORMAT, version=2)
    with pytest.raises(ModelFileError, match="m_per_tick_left must be a positive"):
        MotionModel.load(tmp_path / "v2neg.json")


def test_model_file_carries_the_robot_and_reads_version_2(arx_model, tmp_path):
    from lti_motion.robot_description import RobotDescription

    robot = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287,
                             dt_s=arx_model.dt_s, encoders="quadrature", ticks_per_rad=651.9,
                             wheel_radius_m=(0.033, 0.0331), robot="turtlebot3_waffle",
                             sources={"wheel_radius_m": "--wheel-radius"})
    loaded = MotionModel.load(arx_model.updated(robot=robot).save(tmp_path / "v3.json"))
    assert loaded.robot == robot
    assert loaded.robot.m_per_tick == (0.033 / 651.9, 0.0331 / 651.9)
    assert loaded.robot.sources["wheel_radius_m"] == "--wheel-radius"
    # a version-2 file (no "robot" key) still loads, without a robot
    doc = json.loads(arx_model.updated(robot=robot).save(tmp_path / "x.json").read_text())
    payload = {k: v for k, v in doc.items() if k not in ("format", "version", "sha256", "robot")}
    write_document(tmp_path / "v2.json", payload, fmt=FORMAT, version=2)
    old = MotionModel.load(tmp_path / "v2.json")
    assert old.robot is None
    np.testing.assert_array_equal(old.A, arx_model.A)
    # a version-3 file without the key, or with a nonsense robot, is refused
    write_document(tmp_path / "v3bad.json", payload, fmt=FORMAT, version=3)
    with pytest.raises(ModelFileError, match=r"lacks the keys \['robot'\]"):
        MotionModel.load(tmp_path / "v3bad.json")
    payload["robot"] = {**robot.as_dict(), "wheel_base_m": -0.287}
    write_document(tmp_path / "v3neg.json", payload, fmt=FORMAT, version=3)
    with pytest.raises(ModelFileError, match="wheel_base_m must be positive"):
        MotionModel.load(tmp_path / "v3neg.json")


def test_version_1_files_read_with_a_zero_offset(arx_model, tmp_path):
    doc = json.loads(arx_model.save(tmp_path / "v2.json").read_text())
    payload = {k: v for k, v in doc.items()
               if k not in ("format", "version", "sha256", "offset_speeds")}
    write_document(tmp_path / "v1.json", payload, fmt=FORMAT, version=1)
    old = MotionModel.load(tmp_path / "v1.json")
    assert old.offset_speeds.tolist() == [0.0, 0.0]
    np.testing.assert_array_equal(old.A, arx_model.A)


def test_the_offset_is_added_to_every_prediction_and_saved(arx_model, fresh, tmp_path):
    u, y = fresh
    c = np.array([0.01, -0.05])
    shifted = arx_model.updated(offset_speeds=c)
    np.testing.assert_allclose(shifted.simulate(u), arx_model.simulate(u) + c, atol=1e-12)
    # one-step: the linear part runs on y - c, so data shifted by c predicts shifted by c
    np.testing.assert_allclose(shifted.predict_one_step(u, y + c),
                               arx_model.predict_one_step(u, y) + c, atol=1e-12)
    np.testing.assert_allclose(shifted.fit_percent([(u, y + c)]), arx_model.fit_percent([(u, y)]),
                               atol=1e-9)
    assert MotionModel.load(shifted.save(tmp_path / "m.json")).offset_speeds.tolist() == c.tolist()
    with pytest.raises(ValueError, match="offset_speeds must be 2 finite"):
        arx_model.updated(offset_speeds=[np.nan, 0.0])
