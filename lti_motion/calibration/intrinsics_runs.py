"""Odometry intrinsics from runs localised only at their start and end.

Where a robot is localised only now and then (placed on a marked spot, measured with a
tape, seen by a camera at the ends of its runs), each run is one interval: the wheel
counts all the way through it and the reference's motion from its start pose to its end
pose. The runs together are interval samples with many encoder sub-steps each, solved
exactly as :func:`lti_motion.calibration.calibrate_intrinsics_intervals` solves one-step
samples (Censi et al. 2013, sec. V; the chord form integrates every sub-step).

The runs must differ in how they turn: a run's total rotation is linear in its total
counts (sec. V-A), so runs that all turn the wheels in one proportion cannot separate
them. Long runs with several turns in both directions and straight stretches (UMBmark's
squares driven both ways, Borenstein & Feng 1996) are what this needs.

References
----------
A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry and
sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V.
J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in
mobile robots", IEEE T-RA 12(6):869-880, 1996.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lti_motion.calibration.intrinsics_fit import (
    IntrinsicsCalibration,
    _causes,
    _check_identifiable,
    _check_options,
    _Encoders,
    _report,
    _solve,
)
from lti_motion.calibration.intrinsics_solver import Intervals
from lti_motion.exceptions import PoseReferenceError, UnidentifiableError
from lti_motion.recordings.ticks import tick_deltas, unfold_commanded_direction

__all__ = ["calibrate_intrinsics_runs"]

#: Windows per run for the identifiability report (the runs' count increments in chunks).
_WINDOWS_PER_RUN = 20


def _relative_motion(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``start^-1 (+) end`` per row: the motion in the start pose's frame."""
    c, s = np.cos(start[:, 2]), np.sin(start[:, 2])
    d = end[:, :2] - start[:, :2]
    dth = np.angle(np.exp(1j * (end[:, 2] - start[:, 2])))
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], dth], axis=1)


def calibrate_intrinsics_runs(
    ticks: Sequence[np.ndarray],
    start_poses: np.ndarray,
    end_poses: np.ndarray,
    *,
    sensor_pose: bool = False,
    encoders: _Encoders = "quadrature",
    position_std_m: float = 0.005,
    heading_std_rad: float = 0.01,
    outlier_rounds: int = 4,
    outlier_fraction: float = 0.01,
    turns: Sequence[int] | None = None,
    mean_m_per_tick: float | None = None,
) -> IntrinsicsCalibration:
    """Both wheels' scale and the wheel base from runs with a start and an end pose each.

    Parameters
    ----------
    ticks : sequence of ndarray of int, each shape (n_i, 2)
        Each run's raw 16-bit counts ``(left, right)`` from its start pose to its end pose
        (first row at the start, last at the end), any count unit.
    start_poses, end_poses : ndarray, shape (R, 3)
        Each run's start and end pose ``(x [m], y [m], theta [rad])`` in any world frame
        (one frame per run is enough).
    sensor_pose : bool
        Estimate the pose of the localised frame on the robot (needs runs that turn
        about varied amounts); ``False`` (default) when the poses are the axle centre's.
    encoders : {"quadrature", "commanded"}
        As :func:`lti_motion.calibration.calibrate_intrinsics`.
    position_std_m, heading_std_rad : float
        Noise of one pose [m], [rad]: the first outlier round's weights; the covariance
        uses the noise the kept residuals show.
    outlier_rounds, outlier_fraction
        As :func:`lti_motion.calibration.calibrate_intrinsics` (with fewer than about 100
        runs the 1% rule rejects none).
    turns : sequence of int, optional
        Whole turns counter-clockwise (negative: clockwise) to add to each run's heading
        change, for runs that turn more than half a turn net: the poses give the heading
        only modulo a full turn. Default: all zero (net turns within +-pi).
    mean_m_per_tick : float, optional
        The wheels' mean scale [m/tick], known (a robot description's): for runs that end
        where they started (UMBmark's squares), whose travel cannot give the scale; the
        fit then gives the diameter ratio and the wheel base (UMBmark's type B and type A
        errors). Only with ``sensor_pose=False``.

    Returns
    -------
    IntrinsicsCalibration
        ``n_intervals`` counts the runs kept.

    Raises
    ------
    ValueError
        An option out of range, or runs and poses of different numbers.
    PoseReferenceError
        Wrong shapes, non-finite poses, or end poses that do not follow the counts.
    UnidentifiableError
        Runs that cannot determine the intrinsics (too few, no turns, one proportion).

    References
    ----------
    A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry
    and sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V.
    """
    _check_options(interval_s=1.0, overlap=1, position_std_m=position_std_m,
                   heading_std_rad=heading_std_rad, encoders=encoders,
                   outlier_rounds=outlier_rounds, outlier_fraction=outlier_fraction)
    p0 = np.asarray(start_poses, float)
    p1 = np.asarray(end_poses, float)
    runs = [np.asarray(t) for t in ticks]
    if p0.shape != (len(runs), 3) or p1.shape != (len(runs), 3):
        raise PoseReferenceError(f"expected start and end poses of shape ({len(runs)}, 3), one "
                                 f"per run, got {p0.shape} and {p1.shape}")
    if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
        raise PoseReferenceError("the start or end poses hold NaN or infinite values")
    for i, run in enumerate(runs):
        if run.ndim != 2 or run.shape[1] != 2 or len(run) < 2:
            raise PoseReferenceError(f"run {i}: expected counts of shape (n >= 2, 2), got "
                                     f"{run.shape}")
    if mean_m_per_tick is not None:
        if not (np.isfinite(mean_m_per_tick) and mean_m_per_tick > 0):
            raise ValueError(f"mean_m_per_tick must be a positive finite number, got "
                             f"{mean_m_per_tick!r}")
        if sensor_pose:
            raise ValueError("mean_m_per_tick fixes the scale of runs about the axle centre; "
                             "give sensor_pose=False")
    n_params = 6 if sensor_pose else 3
    if 3 * len(runs) < n_params + 3:
        raise UnidentifiableError(f"{len(runs)} runs give {3 * len(runs)} equations for "
                                  f"{n_params} unknowns; drive at least "
                                  f"{-(-(n_params + 3) // 3)} runs")
    steps = []
    for run in runs:
        d = tick_deltas(run.astype(np.int64), axis=0)
        steps.append((unfold_commanded_direction(d) if encoders == "commanded" else d)
                     .astype(float))
    lengths = np.array([len(d) for d in steps])
    dn = np.concatenate(steps)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    seg = np.repeat(np.arange(len(runs)), lengths)
    motion = _relative_motion(p0, p1)
    if turns is not None:
        if len(turns) != len(runs):
            raise ValueError(f"turns must give one integer per run ({len(runs)}), got "
                             f"{len(turns)}")
        motion[:, 2] += 2 * np.pi * np.asarray(turns, float)
    iv = Intervals(dn=dn, seg=seg, starts=starts, ref_motion=motion,
                   dn_total=np.add.reduceat(dn, starts, axis=0))
    if not np.any(dn):
        raise UnidentifiableError("the encoders did not move: nothing to calibrate")
    chunks = [c.sum(axis=0) for d in steps
              for c in np.array_split(d, min(_WINDOWS_PER_RUN, len(d))) if len(c)]
    dn_w = np.array(chunks)
    turn_w = dn_w[:, 1] - dn_w[:, 0]                      # direction from the counts alone
    rot_w = np.where(turn_w > 0, np.inf, np.where(turn_w < 0, -np.inf, 0.0))
    report = _report(dn_w, rot_w, iv)
    _check_identifiable(report, dn_w, iv, interval_hint="over the runs ")
    sigma = np.array([position_std_m, position_std_m, heading_std_rad]) * np.sqrt(2.0)
    return _solve(iv, report, sensor_pose=sensor_pose, sigma0=sigma, rounds=outlier_rounds,
                  fraction=outlier_fraction, mean_scale=mean_m_per_tick, pose_reference=True,
                  causes=_causes(sensor_pose=sensor_pose, encoders=encoders))
