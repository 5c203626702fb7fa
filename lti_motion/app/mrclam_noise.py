"""MRCLAM motion noise, measured one way for every motion on the first half of a run.

The landmark EKFs (:mod:`lti_motion.app.mrclam_filters`) and the factor
graphs (:mod:`lti_motion.app.mrclam_graph`) compare two motions: the
speeds the ARX model of the first half predicts from the commands alone (free
run; MRCLAM's robots report no encoders), and the commands taken at face value.
Both take each motion's speed noise from :func:`speed_covariances`: the
Newey-West long-run covariance of the speeds differentiated from Vicon minus the
predicted speeds, on the first half. Used as the covariance of a white per-sample
speed error, it makes ``N Phi`` the covariance of ``N`` summed samples' error,
so slow drift, which sets dead-reckoning error between sightings, is counted.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drivers.datasets import CREATE1_WHEEL_BASE_M, MrclamSegment
from fusion.graph import DEFAULT_BANDWIDTH_S, long_run_covariance
from lti_motion.kinematics import wheel_from_body
from lti_motion.model import MotionModel

__all__ = ["VARIANTS", "predicted_speeds", "speed_covariances"]

#: The two motions compared: the ARX model's free run and the raw commands.
VARIANTS = ("model", "raw")


def predicted_speeds(arx: MotionModel, seg: MrclamSegment, warmup: int) -> dict[str, np.ndarray]:
    """Body speeds (v [m/s], w [rad/s]) after the warm-up: the model's free run and the commands.

    The model's state is set from the warm-up samples' commands and true speeds
    (:meth:`~lti_motion.model.MotionModel.state_from_data`), as the landmark EKFs
    and the factor graphs set theirs.

    Returns
    -------
    dict of str to ndarray, shape (len(seg.t_s) - warmup, 2)
        ``"model"`` and ``"raw"``.
    """
    u = wheel_from_body(seg.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M)
    z0 = arx.state_from_data(u[:warmup], seg.speeds_vw[:warmup])
    return {"model": arx.simulate(u[warmup:], z0=z0), "raw": seg.commands_vw[warmup:]}


def speed_covariances(arx: MotionModel, segments: Sequence[MrclamSegment], *,
                      warmup: int, bandwidth_s: float = DEFAULT_BANDWIDTH_S
                      ) -> dict[str, np.ndarray]:
    """Per-sample long-run covariance of each motion's speed error, on (training) segments.

    Parameters
    ----------
    arx : MotionModel
        The ARX model (its ``dt_s`` is the segments' grid step).
    segments : sequence of MrclamSegment
        The first half of a robot's run.
    warmup : int
        Leading samples per segment that only set the model's state.
    bandwidth_s : float
        Newey-West bandwidth [s].

    Returns
    -------
    dict of str to ndarray, shape (2, 2)
        ``"model"`` and ``"raw"``: ``Phi`` of (true speeds - predicted speeds)
        [(m/s)^2, (rad/s)^2] (Newey & West 1987, eq. 2; not demeaned, so a
        mean error counts as drift), exactly symmetric.

    Raises
    ------
    ValueError
        If no segment is longer than ``warmup`` or ``bandwidth_s`` is not positive.

    References
    ----------
    W. K. Newey, K. D. West, "A simple, positive semi-definite, heteroskedasticity
    and autocorrelation consistent covariance matrix", Econometrica 55(3), 1987, eq. 2.
    """
    if not (np.isfinite(bandwidth_s) and bandwidth_s > 0):
        raise ValueError(f"bandwidth_s must be positive, got {bandwidth_s}")
    usable = [s for s in segments if len(s.t_s) > warmup]
    if not usable:
        raise ValueError(f"need a segment longer than the {warmup}-sample warm-up, got "
                         f"lengths {[len(s.t_s) for s in segments]}")
    errors: dict[str, list[np.ndarray]] = {name: [] for name in VARIANTS}
    for seg in usable:
        for name, pred in predicted_speeds(arx, seg, warmup).items():
            errors[name].append(seg.speeds_vw[warmup:] - pred)
    lag = round(bandwidth_s / arx.dt_s)
    covs = {name: long_run_covariance(e, bandwidth=lag) for name, e in errors.items()}
    return {name: 0.5 * (c + c.T) for name, c in covs.items()}
