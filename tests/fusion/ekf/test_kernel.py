"""The compiled EKF step (fusion.ekf.kernel) against the numpy code it replaced.

The references below are the numpy implementations of ``predict_terms`` and of the
2-D gated update as they stood before the kernels (kept here, private, as the
reference). A filter whose predict and encoder update run the references is driven
side by side with the compiled one through a few thousand periods on several layouts
(FIR and ARX models, nz from 0, with and without a gyro, gated and NaN readings,
accumulated speeds): states and covariances must agree to rounding, i.e. within
``RTOL = 1e-12`` relative or ``ATOL = 1e-15`` absolute entry by entry. With a gyro the
filter itself amplifies rounding beyond that (the test measures how far one ulp of
noise on the reference's covariance moves it, and bounds the kernel by four times that).
"""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from synthetic_ekf_model import DT, M_PER_TICK, B, fitted_model, held_commands

from fusion.ekf import functions as ef
from fusion.ekf import kernel as kn
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.noise import GyroNoise, SlipNoise, inverse_covariance, nis
from lti_motion.kinematics import sinc_and_derivative
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel

RTOL, ATOL = 1e-12, 1e-15       # "to rounding", over the whole run
ROOT = Path(__file__).resolve().parents[3]


# -- the numpy references ------------------------------------------------------------------------
def _reference_predict_terms(x, cmd_m_s, fm, *, accumulate=False):
    """``predict_terms`` as numpy code (the implementation before the kernels)."""
    nz, n, dt, z0 = fm.nz, fm.n, fm.dt_s, fm.z0
    x_new = np.empty(n)
    tail = fm.ACD @ x[z0:z0 + nz]
    tail += fm.BD @ cmd_m_s
    tail[nz:] += fm.model.offset_speeds
    x_new[z0:] = tail
    v, w = tail[nz:].tolist()
    if accumulate:
        x_new[z0 + nz:] += x[z0 + nz:]
    if z0 != 6:
        x_new[6:z0] = x[6:z0]
    px, py, theta, k_v, k_w, kappa = x[:6].tolist()
    c_v, c_w = 1.0 + k_v, 1.0 + k_w
    vg, wg = c_v * v, c_w * w + kappa * v
    h = 0.5 * wg * dt
    sinc, dsinc = sinc_and_derivative(h)
    mid = theta + h
    cm, sm = math.cos(mid), math.sin(mid)
    chord = vg * dt * sinc
    x_new[:6] = (px + chord * cm, py + chord * sm, theta + 2.0 * h, k_v, k_w, kappa)
    k = 0.5 * vg * dt * dt
    a, b = dt * sinc * cm, k * (dsinc * cm - sinc * sm)
    c, d = dt * sinc * sm, k * (dsinc * sm + sinc * cm)
    g2 = np.array(fm.G_template)
    g2[:3] = ((a * c_v + b * kappa, b * c_w, a, b),
              (c * c_v + d * kappa, d * c_w, c, d),
              (dt * kappa, dt * c_w, 0.0, dt))
    F = np.array(fm.F_template)
    F[:3, :6] = ((1.0, 0.0, -chord * sm, a * v, b * w, b * v),
                 (0.0, 1.0, chord * cm, c * v, d * w, d * v),
                 (0.0, 0.0, 1.0, 0.0, dt * w, dt * v))
    F[:3, z0:z0 + nz] = g2[:3, :2] @ fm.model.C
    F[n - 2, n - 2] = F[n - 1, n - 1] = 1.0 if accumulate else 0.0
    sv, sw = fm.slip.stds(v, w)
    w4 = np.array(fm.W_template)
    w4[2, 2] = sv * sv
    w4[3, 3] = sw * sw
    Q = (g2 @ w4) @ g2.T + fm.Q_const
    return x_new, F, Q


def _reference_propagate(P, F, Q):
    out = F @ P @ F.T + Q
    return 0.5 * (out + out.T)


def _reference_predict_step(x, P, cmd_m_s, fm, *, accumulate=False, out_F, out_Q):
    x_new, F, Q = _reference_predict_terms(x, np.asarray(cmd_m_s, dtype=float), fm,
                                           accumulate=accumulate)
    out_F[...], out_Q[...] = F, Q
    return x_new, _reference_propagate(P, F, Q)


def _reference_selector_update(x, P, innovation, R, gate, force):
    """The 2-D gated update of the last two states, as numpy code (GatedUpdates._gated)."""
    n = len(x)
    PHt = P[:, n - 2:]
    S = PHt[-2:] + R
    SI = inverse_covariance(S)
    value = nis(innovation, SI)
    accepted = value <= gate or force
    if not accepted:
        return True, S, SI, value, False, np.zeros((n, 2)), x, P
    K = PHt @ SI
    H = np.zeros((2, n))
    H[:, n - 2:] = np.eye(2)
    return True, S, SI, value, True, K, x + K @ innovation, ef.joseph_covariance(P, K, H, R, PHt)


# -- layouts ---------------------------------------------------------------------------------------
def _fir_model(n_taps):
    """A FIR model with ``n_taps`` taps (nz = 2 (n_taps - 1)), with an affine offset."""
    taps = np.zeros((n_taps, 2, 2))
    taps[-1] = [[0.5, 0.5], [-1.0 / B, 1.0 / B]]
    fit = FirFit(taps=taps, residual_cov=np.diag([1e-4, 6e-3]), n_samples=100, source="steps")
    model = MotionModel.from_fir(fit, dt_s=DT, wheel_base_m=B, m_per_tick=M_PER_TICK,
                                 calibrated_at="2026-01-01T00:00:00+00:00")
    return model


def _static_model():
    """No model state (nz = 0): the speeds are ``D u + offset + e``."""
    return MotionModel(kind="fir", A=np.zeros((0, 0)), B=np.zeros((0, 2)), C=np.zeros((2, 0)),
                       D=np.array([[0.5, 0.5], [-1.0 / B, 1.0 / B]]), K=np.zeros((0, 2)),
                       Q=np.zeros((0, 0)), R=np.diag([1e-4, 6e-3]), dt_s=DT, wheel_base_m=B,
                       coefficients={}, orders={}, m_per_tick=M_PER_TICK,
                       calibrated_at="2026-01-01T00:00:00+00:00",
                       offset_speeds=np.array([0.001, -0.002]))


LAYOUTS = {
    "arx": dict(model="arx", gyro=False),
    "arx-gyro": dict(model="arx", gyro=True),
    "static-nz0": dict(model="static", gyro=False),
    "static-nz0-gyro": dict(model="static", gyro=True),
    "fir-nz4-gyro": dict(model="fir3", gyro=True),
}
NZ = {"arx": 4, "static": 0, "fir3": 4}


@pytest.fixture(scope="module")
def models():
    return {"arx": fitted_model(), "static": _static_model(), "fir3": _fir_model(3)}


def _drive(rng, n):
    """Commands, raw counts (spikes, a frozen right wheel, NaN frames) and gyro readings."""
    u = held_commands(rng, n)
    v = u.mean(axis=1) + 0.01 * rng.standard_normal(n)
    w = (u[:, 1] - u[:, 0]) / B + 0.05 * rng.standard_normal(n)
    wheel = np.stack([v - 0.5 * B * w, v + 0.5 * B * w], axis=1)
    counts = np.vstack([[0, 0], np.round(np.cumsum(wheel * DT / M_PER_TICK, 0))])
    ticks = (counts % 65536).astype(float)
    for k in rng.choice(np.arange(50, n), 15, replace=False):    # single-frame spikes
        ticks[k, rng.integers(2)] += 4000.0
    ticks[n // 2:n // 2 + 40, 1] = ticks[n // 2, 1]              # the right encoder frozen
    ticks[rng.choice(np.arange(50, n), 10, replace=False), 0] = np.nan
    gyro = w + 0.05 * rng.standard_normal(n)
    return u, ticks, gyro


def _run(model, u, ticks, gyro_rates, *, gyro):
    ekf = ModelEKF(model, initial_ticks=ticks[0].astype(np.int64),
                   options=EKFOptions(gyro=GyroNoise() if gyro else None,
                                      slip=SlipNoise(w_per_v_rad_m=0.07)))
    xs, Ps, reasons = [], [], []
    for k in range(len(u)):
        ekf.predict(u[k])
        reasons.append(ekf.update_encoders(ticks[k + 1]).reason)
        if gyro:
            reasons.append(ekf.update_gyro(gyro_rates[k]).reason)
        if k % 50 == 0:
            xs.append(ekf.x)
            Ps.append(ekf.P)
    xs.append(ekf.x)
    Ps.append(ekf.P)
    return np.array(xs), np.array(Ps), reasons, ekf


def _excess(got, want):
    """The largest difference of states and of covariances along the run, in units of
    ``ATOL + RTOL * scale``: a state component's scale is its largest magnitude over the
    run, a covariance entry's ``sqrt(P_ii P_jj)``."""
    (x1, P1), (x0, P0) = got[:2], want[:2]
    x_tol = ATOL + RTOL * np.abs(x0).max(axis=0)
    sd = np.sqrt(np.diagonal(P0, axis1=1, axis2=2))
    P_tol = ATOL + RTOL * sd[:, :, None] * sd[:, None, :]
    return float((np.abs(x1 - x0) / x_tol).max()), float((np.abs(P1 - P0) / P_tol).max())


def _ulp_noise_predict_step(rng):
    """The reference prediction with ``P`` perturbed by one ulp (random sign) per entry."""
    def step(x, P, cmd_m_s, fm, *, accumulate=False, out_F, out_Q):
        x_new, P_new = _reference_predict_step(x, P, cmd_m_s, fm, accumulate=accumulate,
                                               out_F=out_F, out_Q=out_Q)
        noise = 1.0 + np.finfo(float).eps * rng.choice([-1.0, 1.0], P_new.shape)
        return x_new, 0.5 * ((P_new * noise) + (P_new * noise).T)
    return step


@pytest.mark.parametrize("layout", LAYOUTS)
def test_the_compiled_filter_equals_the_numpy_one_over_thousands_of_steps(models, layout,
                                                                         monkeypatch):
    spec = LAYOUTS[layout]
    model = models[spec["model"]]
    u, ticks, gyro_rates = _drive(np.random.default_rng(11), 3000)
    compiled = _run(model, u, ticks, gyro_rates, gyro=spec["gyro"])
    with monkeypatch.context() as mp:
        mp.setattr("fusion.ekf.model_ekf.predict_step", _reference_predict_step)
        mp.setattr("fusion.ekf.updates.selector_update_kernel", _reference_selector_update)
        reference = _run(model, u, ticks, gyro_rates, gyro=spec["gyro"])
    assert compiled[2] == reference[2]                   # every reading ended the same way
    reasons = set(compiled[2])
    assert {"fused", "gated", "non_finite"} <= reasons   # the test exercises the gate
    if not spec["gyro"]:        # every entry to RTOL of itself
        for got, want in zip(compiled[:2], reference[:2], strict=True):
            np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
        assert max(_excess(compiled, reference)) <= 1.0
    else:
        # The gyro's innovation variance P_tt - 2 P_tc + P_cc (heading and its clone) cancels:
        # rounding differences of P grow through it, and the weakly observed bias and kappa
        # move by more than RTOL of their scale. Bound: what one ulp of noise on the
        # reference's own P does (measured 0.6-6 tolerances in x; the kernel 0.4-9).
        with monkeypatch.context() as mp:
            mp.setattr("fusion.ekf.model_ekf.predict_step",
                       _ulp_noise_predict_step(np.random.default_rng(0)))
            mp.setattr("fusion.ekf.updates.selector_update_kernel", _reference_selector_update)
            noisy = _run(model, u, ticks, gyro_rates, gyro=True)
        for ours, ulp in zip(_excess(compiled, reference), _excess(noisy, reference),
                             strict=True):
            assert ours <= max(1.0, 4.0 * ulp), (ours, ulp)
    ekf = compiled[3]
    assert ekf.fm.nz == NZ[spec["model"]]
    assert ekf.K.shape == (ekf.fm.n, ekf.K.shape[1]) and ekf.x_post is not None


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("accumulate", [False, True])
def test_predict_terms_equals_the_numpy_reference(models, layout, accumulate):
    spec = LAYOUTS[layout]
    fm = ef.FilterModel(models[spec["model"]], gyro=GyroNoise() if spec["gyro"] else None)
    rng = np.random.default_rng(5)
    for w in (0.0, 1e-9, 0.4, -2.5, 12.0):             # the series and the closed-form sinc
        x = ef.initial_state(fm, (1.0, 2.0, 0.7), z=0.05 * rng.standard_normal(fm.nz))
        x[ef.SCALES] = (0.004, -0.003, 0.03)
        x[fm.speed_slice] = (0.2, w)
        if fm.nz:
            x[fm.z0:fm.z0 + 2] = (0.2, w)
        u = rng.uniform(0.0, 0.4, 2)
        got = ef.predict_terms(x, u, fm, accumulate=accumulate)
        want = _reference_predict_terms(x, u, fm, accumulate=accumulate)
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL)
        P = ef.initial_covariance(fm)
        F, Q = np.array(fm.F_template), np.empty((fm.n, fm.n))
        x_next, P_next = ef.predict_step(x, P, u, fm, accumulate=accumulate, out_F=F, out_Q=Q)
        np.testing.assert_allclose(x_next, want[0], rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(P_next, _reference_propagate(P, want[1], want[2]),
                                   rtol=RTOL, atol=ATOL)
        assert np.array_equal(P_next, P_next.T)


def test_read_only_and_column_inputs_give_the_same_prediction(models):
    fm = ef.FilterModel(models["arx"])
    x = ef.initial_state(fm, (1.0, 2.0, 0.7))
    u = np.array([0.2, 0.3])
    want = ef.predict_terms(x, u, fm)
    frozen = x.copy()
    frozen.flags.writeable = False
    for variant in (frozen, x[:, None]):                # filterpy's column convention too
        for a, b in zip(ef.predict_terms(variant, u, fm), want, strict=True):
            np.testing.assert_array_equal(a, b)


def test_the_update_kernel_falls_back_on_a_singular_innovation_covariance():
    x, P = np.zeros(4), np.zeros((4, 4))
    ok, *_ = kn.selector_update_kernel(x, P, np.zeros(2), np.zeros((2, 2)), 13.8, False)
    assert not ok
    ok, S, SI, value, accepted, K, x_new, P_new = kn.selector_update_kernel(
        x, np.eye(4), np.array([0.1, 5.0]), np.eye(2), 10.0, False)    # NIS 12.5: gated
    assert ok and not accepted and value == pytest.approx(0.5 * (0.01 + 25.0))
    np.testing.assert_array_equal(S, 2 * np.eye(2))
    np.testing.assert_array_equal(SI, 0.5 * np.eye(2))
    assert x_new.size == P_new.size == 0 and not K.any()


def test_importing_the_ekf_compiles_nothing():
    code = ("import fusion.ekf, fusion.ekf.kernel as k\n"
            "print(sum(len(f.signatures) for f in (k.predict_kernel, k.predict_terms_kernel,"
            " k.selector_update_kernel)))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "0"


def test_a_slip_noise_with_its_own_law_is_refused_not_ignored(models):
    """The compiled step evaluates SlipNoise's law from its fields; a subclass overriding
    ``stds`` would be silently ignored, so the filter layout refuses it in one line."""
    from dataclasses import dataclass

    from fusion.exceptions import FilterOptionError

    @dataclass(frozen=True)
    class Quadratic(SlipNoise):
        def stds(self, v_m_s, w_rad_s):
            return (1e-3 + v_m_s * v_m_s, 1e-2)

    with pytest.raises(FilterOptionError, match=r"Quadratic overrides SlipNoise\.stds"):
        ef.FilterModel(models["arx"], slip=Quadratic())
    ef.FilterModel(models["arx"], slip=SlipNoise(v_frac=0.03))   # fields: fine
