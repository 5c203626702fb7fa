"""The moving-average (FIR) model from the paper's step manoeuvre (paper section II.B, eq. 2-10).

One motor at a time is switched on and off (:func:`~lti_motion.model.step_sequence`);
each normalised step response, differenced, is one column of the 2x2 matrix of impulse
responses (:func:`fir_from_steps`).

The steady-state gain of such a FIR is its step response at the last tap. The paper
takes it from one sample of one quantised response; :func:`fir_from_steps` can instead
hold the response, from where it has settled, at the mean of its settled part
(``dc_gain="settled"``), or at the wheel servos' gain ``c M`` nearest that mean
(``dc_gain="wheel_servo"``, :func:`lti_motion.model.nearest_servo_gain`): for a
robot that servoes each wheel on the encoders measuring ``y``, straight commands then give
no yaw rate in steady state, exactly (docs/route.md).

References
----------
The paper: ``docs/architecture.md``, "The paper".
Greene, W. H. (2012). Econometric Analysis, 7th ed., section 5.5.1, eq. 5-23
(restricted least squares).
Franklin, G. F., Powell, J. D. & Emami-Naeini, A. (2015). Feedback Control of
Dynamic Systems, 7th ed., section 3.4 (settling time).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Literal

import numpy as np

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.model.arx_structure import nearest_servo_gain
from lti_motion.model.excitation import StepSequence, check_runs
from lti_motion.model.fir import FirFit, fir_state_space
from lti_motion.model.state_space import simulate_state_space

__all__ = ["fir_from_steps"]

_log = logging.getLogger(__name__)

_DC_GAINS = ("free", "settled", "wheel_servo")


def _edge_response(
    u: np.ndarray, y: np.ndarray, start: int, length: int, wheel: int, baseline: int
) -> np.ndarray:
    """Normalised step response ``(y[start + i] - y_before) / step`` for one edge."""
    before = slice(max(start - baseline, 0), start)
    u0 = u[before, wheel].mean() if start > 0 else 0.0  # the robot stands still at the start
    y0 = y[before].mean(axis=0) if start > 0 else np.zeros(2)
    step = u[start, wheel] - u0
    window = u[start : start + length]
    if abs(step) < 1e-9:
        raise CalibrationError(f"no step of wheel {'LR'[wheel]} at sample {start}: "
                               "the phases do not match the commands")
    if np.ptp(window[:, wheel]) > 1e-9 or np.ptp(window[:, 1 - wheel]) > 1e-9:
        raise CalibrationError(f"the commands change inside the phase starting at sample {start}; "
                               "a step calibration holds them constant, one motor at a time")
    return (y[start : start + length] - y0) / step


def _step_responses(
    u: np.ndarray, y: np.ndarray, slices: Sequence[slice], length: int, *,
    edges: str, baseline: int,
) -> np.ndarray:
    """Step responses ``s[i, out, in]`` (length, 2, 2), edges averaged if ``edges="both"``."""
    responses = np.empty((length, 2, 2))
    for wheel in range(2):
        on, off = slices[2 * wheel], slices[2 * wheel + 1]
        s = _edge_response(u, y, on.start, length, wheel, baseline)
        if edges == "both":
            s = 0.5 * (s + _edge_response(u, y, off.start, length, wheel, baseline))
        responses[:, :, wheel] = s
    return responses


def _settled_length(s: np.ndarray, *, rel_threshold: float, noise_factor: float) -> int:
    """Samples until the step response ``s`` (k,) stays inside its settling band."""
    tail = s[-max(len(s) // 3, 3) :]
    final = np.median(tail)
    noise = 1.4826 * np.median(np.abs(tail - final))  # robust standard deviation (MAD)
    if noise == 0.0:  # quantised counts: most of the tail on one level, the MAD is zero
        noise = float(np.std(tail))
    band = max(rel_threshold * np.abs(s).max(), noise_factor * noise)
    outside = np.flatnonzero(np.abs(s - final) > band)
    return int(outside[-1]) + 1 if outside.size else 1


def fir_from_steps(
    u: np.ndarray,
    y: np.ndarray,
    *,
    phases: StepSequence | Sequence[slice],
    edges: Literal["both", "rising"] = "both",
    dc_gain: Literal["free", "settled", "wheel_servo"] = "free",
    wheel_base_m: float | None = None,
    rel_threshold: float = 0.05,
    noise_factor: float = 5.0,
    margin_taps: int = 2,
    max_taps: int | None = None,
    baseline_samples: int = 5,
) -> FirFit:
    """The moving-average model from a step calibration (paper section II.B, eq. 2-10).

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Commands actually sent [m/s] (for example ``sequence.cmd_m_s``).
    y : ndarray, shape (n, 2)
        Measured body speeds ``(v, w)`` [m/s, rad/s].
    phases : StepSequence or four slices
        Left on, left off, right on, right off (:func:`~lti_motion.model.step_sequence`).
    edges : {"both", "rising"}
        Average the responses to the rising and falling edges (halves the
        noise; the PID loops make them near-symmetric, paper section III.B), or use the
        rising edges only.
    dc_gain : {"free", "settled", "wheel_servo"}
        The FIR's steady-state gain (sum of its taps).
        ``"free"`` (the paper): the step response at the last tap, one sample.
        ``"settled"``: each step response is held, from where it has settled,
        at the mean of its settled part (from twice the settling length to the
        end of the phase), each edge measured from the mean of the same part
        of the phase before it.
        ``"wheel_servo"``: as ``"settled"``, then the 2x2 level is replaced by
        the nearest wheel-servo gain ``c M``
        (:func:`~lti_motion.model.nearest_servo_gain`); needs
        ``wheel_base_m``. Right for a robot that servoes each wheel's speed on
        the encoders ``y`` comes from (Roomba, Create 2).
    wheel_base_m : float, optional
        Wheel base used to compute ``y`` [m]; required for ``"wheel_servo"``.
    rel_threshold, noise_factor : float
        A step response has settled once it stays within a band around its
        final value (median of its last third): ``rel_threshold`` times its
        peak, or ``noise_factor`` times its noise level (robust standard
        deviation of the last third; its standard deviation when the robust
        one is zero, as on quantised counts), whichever is larger.
    margin_taps : int
        Taps kept after the last of the four responses has settled.
    max_taps : int, optional
        Upper limit of the FIR length.
    baseline_samples : int
        Samples before each edge averaged as its starting level (at least;
        ``"settled"`` and ``"wheel_servo"`` use the settled part of the phase
        before the edge).

    Returns
    -------
    FirFit
        ``source="steps"``; the residual covariance is that of the FIR's free
        run on the step data itself; ``step_responses`` are the measured ones.

    Raises
    ------
    ShapeError, NonFiniteError
        For malformed ``u``/``y``.
    CalibrationError
        If a phase holds no step, the commands change inside a phase, a phase
        lies outside the data, or (``"settled"``, ``"wheel_servo"``) the
        responses have not settled inside the phases.
    ValueError
        For an unknown ``edges`` or ``dc_gain``, or ``"wheel_servo"`` without
        a positive ``wheel_base_m``.

    Notes
    -----
    For a step of size ``a`` applied at ``n0`` the response is
    ``y[n0 + i] - y[n0 - 1] = a sum_{j <= i} h[j]``, so the impulse response
    is the normalised step response, differenced (paper eq. 6-7). One motor
    at a time gives one column of the transfer matrix (eq. 8-9). The length
    is the settling time ``k`` of the slowest of the four step responses (the
    control-engineering definition with a band around the final value,
    e.g. Franklin, Powell & Emami-Naeini 2015, section 3.4), judged on the
    step responses because differencing doubles their noise; paper section III.B
    finds about 15 taps on a Roomba. A warning is logged when the responses
    have not settled inside the recorded window.

    With ``"settled"`` and ``"wheel_servo"`` the step response is a set of
    parameters, one per sample before ``k`` (seen by one sample of each edge)
    and one level ``S`` (2x2) for all samples from ``k`` on. Their least-squares
    estimates are the measured samples and the mean of the settled part, taken
    from ``min(2 k, (k + L) / 2)`` to the end ``L`` of the phase: inside the
    band the transient is still up to ``rel_threshold`` of the peak, at ``2 k``
    an exponential one is down to its square. The
    restriction ``S = c M`` involves only ``S``, and the information matrix is
    block diagonal, so restricted least squares (Greene 2012, eq. 5-23) leaves
    the transient samples as measured and projects ``S`` alone. The encoders
    count each wheel separately, so the projection is made in wheel
    coordinates, ``c = trace(M^-1 S) / 2``. The taps are the differences of
    this step response, and ``sum(taps) = S`` exactly.

    Examples
    --------
    >>> from lti_motion.model.excitation import step_sequence
    >>> seq = step_sequence(amplitude_m_s=0.2, hold_s=0.3, rest_s=0.3, dt_s=0.015)
    >>> u = seq.cmd_m_s
    >>> y = np.zeros_like(u)
    >>> y[3:, 0] = 0.5 * (u[:-3, 0] + u[:-3, 1]); y[3:, 1] = (u[:-3, 1] - u[:-3, 0]) / 0.235
    >>> fit = fir_from_steps(u, y, phases=seq)
    >>> fit.n_taps, np.round(fit.taps[3], 3).tolist()
    (5, [[0.5, 0.5], [-4.255, 4.255]])
    >>> y[:, 1] *= 1.01                          # a yaw-rate scale error of 1 %
    >>> servo = fir_from_steps(u, y, phases=seq, dc_gain="wheel_servo", wheel_base_m=0.235)
    >>> (np.round(servo.taps.sum(axis=0) @ [1.0, 1.0], 12) + 0.0).tolist()  # straight: no yaw
    [1.005, 0.0]
    """
    ((u, y),) = check_runs([(u, y)])
    slices = phases.phases if isinstance(phases, StepSequence) else tuple(phases)
    if len(slices) != 4 or not all(isinstance(s, slice) for s in slices):
        raise ShapeError(f"phases must be a StepSequence or four slices, got {phases!r}")
    if edges not in ("both", "rising"):
        raise ValueError(f"edges must be 'both' or 'rising', got {edges!r}")
    if dc_gain not in _DC_GAINS:
        raise ValueError(f"dc_gain must be one of {_DC_GAINS}, got {dc_gain!r}")
    if dc_gain == "wheel_servo" and wheel_base_m is None:
        raise ValueError("dc_gain='wheel_servo' needs wheel_base_m, the wheel base [m] "
                         "the body speeds y were computed with")
    n = len(u)
    if any(s.start is None or s.stop is None or s.start < 0 or s.stop > n for s in slices) \
            or min(s.stop - s.start for s in slices) < 2:
        raise CalibrationError(f"the phases {slices} do not fit in {n} samples of data")
    length = min(s.stop - s.start for s in slices)
    responses = _step_responses(u, y, slices, length, edges=edges, baseline=baseline_samples)
    settled = max(_settled_length(responses[:, o, i], rel_threshold=rel_threshold,
                                  noise_factor=noise_factor) for o in range(2) for i in range(2))
    m = settled + int(margin_taps)
    if m > length:
        _log.warning("the step responses have not settled within %d samples; record longer "
                     "hold_s and rest_s", length)
    m = max(min(m, length, max_taps or length), 1)
    shaped = responses
    if dc_gain != "free":
        if settled >= length:
            raise CalibrationError(
                f"the step responses have not settled within the {length} samples of a phase, "
                f"so their steady-state level cannot be measured; record longer hold_s and "
                f"rest_s, or use dc_gain='free'")
        # the level from twice the settling length on, where an exponential transient has
        # decayed to the square of the band, keeping at least half the settled part
        first = min(2 * settled, (settled + length) // 2)
        # each edge from the same part of the phase before it (a constant shift of each
        # edge's response, so the settling length is unchanged)
        responses = _step_responses(u, y, slices, length, edges=edges,
                                    baseline=max(int(baseline_samples), length - first))
        level = responses[first:].mean(axis=0)          # least-squares level of the settled part
        if dc_gain == "wheel_servo":
            level, c = nearest_servo_gain(level, wheel_base_m=wheel_base_m)  # Greene eq. 5-23
            _log.debug("FIR from steps: wheel-servo DC gain scale c = %.5f", c)
        shaped = responses.copy()
        shaped[min(settled, m - 1):] = level             # sum(taps) = level, exactly
    taps = np.diff(shaped[:m], axis=0, prepend=0.0)      # paper eq. 7: h = ds/dn
    ss = fir_state_space(taps)
    resid = y - simulate_state_space(ss.A, ss.B, ss.C, ss.D, u)[0]
    return FirFit(taps=taps, residual_cov=resid.T @ resid / n, n_samples=n, source="steps",
                  step_responses=responses)
