"""References by interval: samples of a sensor's own motion against the wheels (Censi et
al.'s format), and runs localised only at their start and end (:func:`read_end_pose_runs`).

One JSON object per line, one line per interval::

    { "T": 0.794, "phi_l": 0.1401, "phi_r": -0.1373, "sm": [0.00109, -0.00051, -0.02749] }

``T`` [s] the interval, ``phi_l``, ``phi_r`` [rad/s] the wheels' mean angular speeds over
it, ``sm`` = ``(x [m], y [m], theta [rad])`` the sensor's displacement over it in its own
frame at the interval's start (a scan matcher's, in Censi et al.'s data). Objects may
also follow each other on one line (the authors' files join their runs that way);
whitespace between them is skipped, further keys are ignored.

References
----------
A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry and
sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013; their supplemental
material (github.com/AndreaCensi/calibration, ``reference-output/*.tuple``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["RUNS_HEADER", "EndPoseRuns", "MotionIntervals", "is_end_pose_runs",
           "read_end_pose_runs", "read_motion_intervals"]


@dataclass(frozen=True)
class MotionIntervals:
    """Interval samples: wheel angles and the sensor's motion over each interval.

    Attributes
    ----------
    duration_s : ndarray, shape (K,)
        Length of each interval [s].
    wheel_rad : ndarray, shape (K, 2)
        Angle each wheel turned ``(left, right)`` over the interval [rad] (``T phi``).
    sensor_motion : ndarray, shape (K, 3)
        The sensor's displacement ``(x [m], y [m], theta [rad])`` in its start frame.
    """

    duration_s: np.ndarray
    wheel_rad: np.ndarray
    sensor_motion: np.ndarray


def read_motion_intervals(path: str | os.PathLike) -> MotionIntervals:
    """Read interval samples in Censi et al.'s JSON-lines format (module docstring).

    Parameters
    ----------
    path : str or path-like
        The file.

    Returns
    -------
    MotionIntervals

    Raises
    ------
    ValueError
        A line that is not such an object (the message names the line and the key), or
        a file without samples.
    OSError
        A file that cannot be read.

    Examples
    --------
    >>> import tempfile
    >>> line = '{"T": 0.5, "phi_l": 1.0, "phi_r": 2.0, "sm": [0.01, 0.0, 0.02]}'
    >>> with tempfile.NamedTemporaryFile("w", suffix=".tuple", delete=False) as f:
    ...     _ = f.write(line + "\\n")
    >>> read_motion_intervals(f.name).wheel_rad.tolist()
    [[0.5, 1.0]]
    """
    text = Path(path).read_text()
    decoder = json.JSONDecoder()
    rows, pos = [], 0
    while True:
        while pos < len(text) and text[pos].isspace():
            pos += 1
        if pos == len(text):
            break
        number = text.count("\n", 0, pos) + 1
        try:
            obj, pos = decoder.raw_decode(text, pos)
            row = [float(obj["T"]), float(obj["phi_l"]), float(obj["phi_r"]),
                   *(float(v) for v in obj["sm"])]
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path} line {number} is not an interval sample "
                             f'{{"T": s, "phi_l": rad/s, "phi_r": rad/s, "sm": [x, y, theta]}}: '
                             f"{type(exc).__name__} {exc}") from None
        if len(row) != 6 or not np.all(np.isfinite(row)) or row[0] <= 0:
            raise ValueError(f"{path} line {number}: expected a positive T and 3 finite sm "
                             f"values, got {row}")
        rows.append(row)
    if not rows:
        raise ValueError(f"{path} holds no interval samples")
    a = np.array(rows)
    return MotionIntervals(duration_s=a[:, 0], wheel_rad=a[:, :1] * a[:, 1:3],
                           sensor_motion=a[:, 3:6])


#: The first line of an end-pose runs file (:func:`read_end_pose_runs`).
RUNS_HEADER = ("# lti-motion runs: t_start_s t_end_s x0_m y0_m theta0_rad x1_m y1_m "
               "theta1_rad turns")


@dataclass(frozen=True)
class EndPoseRuns:
    """Runs localised only at their start and end.

    Attributes
    ----------
    times_s : ndarray, shape (R, 2)
        Each run's start and end time [s], on the encoder log's clock.
    start_poses, end_poses : ndarray, shape (R, 3)
        ``(x [m], y [m], theta [rad])`` at the start and the end.
    turns : ndarray of int, shape (R,)
        Whole turns counter-clockwise (negative: clockwise) beyond what the two headings
        show (a run that turns more than half a turn net).
    """

    times_s: np.ndarray
    start_poses: np.ndarray
    end_poses: np.ndarray
    turns: np.ndarray


def is_end_pose_runs(path: str | os.PathLike) -> bool:
    """Whether the file starts with :data:`RUNS_HEADER`'s ``# lti-motion runs:``."""
    with open(path) as f:
        for line in f:
            if line.strip():
                return line.strip().startswith("# lti-motion runs:")
    return False


def read_end_pose_runs(path: str | os.PathLike) -> EndPoseRuns:
    """Read runs with a start and an end pose each: :data:`RUNS_HEADER`, then one run a
    line, nine numbers separated by blanks (``turns`` an integer, usually 0).

    Raises
    ------
    ValueError
        A missing header, a line of another length, a run that ends before it starts,
        or non-finite values (the message names the line).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
    ...     _ = f.write(RUNS_HEADER + "\\n0 10 0 0 0 2 0.1 3.1 1\\n")
    >>> runs = read_end_pose_runs(f.name)
    >>> runs.times_s.tolist(), runs.turns.tolist()
    ([[0.0, 10.0]], [1])
    """
    if not is_end_pose_runs(path):
        raise ValueError(f"{path} does not start with the runs header '{RUNS_HEADER}'")
    rows = []
    for number, line in enumerate(Path(path).read_text().splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            row = [float(v) for v in line.split()]
        except ValueError:
            raise ValueError(f"{path} line {number}: expected 9 numbers, got {line.strip()!r}"
                             ) from None
        if len(row) != 9 or not np.all(np.isfinite(row)) or row[8] != round(row[8]):
            raise ValueError(f"{path} line {number}: expected 9 finite numbers (the last "
                             f"an integer), got {line.strip()!r}")
        if not row[1] > row[0]:
            raise ValueError(f"{path} line {number}: the run ends ({row[1]:g} s) before it "
                             f"starts ({row[0]:g} s)")
        rows.append(row)
    if not rows:
        raise ValueError(f"{path} holds no runs")
    a = np.array(rows)
    return EndPoseRuns(times_s=a[:, :2], start_poses=a[:, 2:5], end_poses=a[:, 5:8],
                       turns=a[:, 8].astype(int))
