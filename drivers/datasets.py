"""Readers for public robot datasets: UTIAS MRCLAM (Leung et al., IJRR 30(8), 2011).

MRCLAM: five iRobot Create robots drove to random waypoints for about 15
minutes in a 15 m x 8 m room with 15 landmark tubes, watched by Vicon. Per
robot the files hold the *commanded* speeds (``RobotN_Odometry.dat``: time,
v [m/s], w [rad/s], about 67 Hz, irregular), Vicon ground truth
(``RobotN_Groundtruth.dat``: time, x, y, heading, about 64 Hz, irregular,
with gaps) and camera sightings (``RobotN_Measurement.dat``: time, barcode,
range [m], bearing [rad]); ``Barcodes.dat`` maps barcodes to subjects (1-5
robots, 6-20 landmarks) and ``Landmark_Groundtruth.dat`` gives landmark
positions. Files start with ``#`` comment lines and use CRLF line ends.

:func:`load_mrclam` reads a folder as published; :func:`resample_robot` puts a
robot on a uniform time grid, split at ground-truth gaps, with body speeds
differentiated from the ground truth.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.exceptions import DatasetError

__all__ = [
    "CREATE1_WHEEL_BASE_M",
    "MrclamDataset",
    "MrclamRobot",
    "MrclamSegment",
    "load_mrclam",
    "resample_robot",
]

#: Wheel base of the iRobot Create (1) the dataset used [m] (spec §7.1, :mod:`drivers.roomba.oi`).
CREATE1_WHEEL_BASE_M = 0.258




@dataclass(frozen=True)
class MrclamRobot:
    """One robot's files.

    Attributes
    ----------
    robot : int
        Robot number, 1-5.
    commands : ndarray, shape (n, 3)
        Time [s], commanded v [m/s], commanded w [rad/s].
    groundtruth : ndarray, shape (m, 4)
        Time [s], x [m], y [m], heading [rad] (wrapped, as published).
    sightings : ndarray, shape (k, 4)
        Time [s], landmark subject (6-20), range [m], bearing [rad]; sightings
        of other robots and of unknown barcodes are dropped.
    """

    robot: int
    commands: np.ndarray
    groundtruth: np.ndarray
    sightings: np.ndarray


@dataclass(frozen=True)
class MrclamDataset:
    """A whole MRCLAM data set.

    Attributes
    ----------
    path : Path
    robots : dict of int to MrclamRobot
    landmarks : dict of int to ndarray, shape (4,)
        Subject -> (x [m], y [m], x std [m], y std [m]).
    """

    path: Path
    robots: dict[int, MrclamRobot]
    landmarks: dict[int, np.ndarray]


@dataclass(frozen=True)
class MrclamSegment:
    """A stretch of one robot on a uniform grid, without ground-truth gaps.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Grid times [s].
    commands_vw : ndarray, shape (n, 2)
        Commanded (v [m/s], w [rad/s]) in force at each time (zero-order hold).
    pose : ndarray, shape (n, 3)
        True (x [m], y [m], heading [rad]), heading unwrapped.
    speeds_vw : ndarray, shape (n, 2)
        True body speeds (v [m/s], w [rad/s]) by central differences of the
        pose over one grid step either side.
    """

    t_s: np.ndarray
    commands_vw: np.ndarray
    pose: np.ndarray
    speeds_vw: np.ndarray


def _read(path: Path, columns: int) -> np.ndarray:
    if not path.is_file():
        raise DatasetError(f"missing dataset file {path}")
    try:
        data = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as exc:
        raise DatasetError(f"{path} is malformed: {exc}") from exc
    if data.shape[1] != columns:
        raise DatasetError(f"{path} has {data.shape[1]} columns, expected {columns}")
    return data


def load_mrclam(path: str | os.PathLike) -> MrclamDataset:
    """Read an MRCLAM data set folder (e.g. ``MRCLAM_Dataset6``) as published.

    Raises
    ------
    DatasetError
        If a file is missing or malformed; the message names it.
    """
    path = Path(path)
    barcodes = _read(path / "Barcodes.dat", 2).astype(int)
    to_subject = {int(code): int(subject) for subject, code in barcodes}
    marks = _read(path / "Landmark_Groundtruth.dat", 5)
    landmarks = {int(row[0]): row[1:].copy() for row in marks}
    robots = {}
    for robot in range(1, 6):
        sight = _read(path / f"Robot{robot}_Measurement.dat", 4)
        subject = np.array([to_subject.get(int(code), -1) for code in sight[:, 1]])
        keep = np.isin(subject, list(landmarks))
        sight = np.column_stack([sight[keep, 0], subject[keep], sight[keep, 2:]])
        robots[robot] = MrclamRobot(
            robot=robot,
            commands=_read(path / f"Robot{robot}_Odometry.dat", 3),
            groundtruth=_read(path / f"Robot{robot}_Groundtruth.dat", 4),
            sightings=sight,
        )
    return MrclamDataset(path=path, robots=robots, landmarks=landmarks)


def resample_robot(robot: MrclamRobot, *, dt_s: float = 0.1,
                   max_gap_s: float = 0.25, min_length_s: float = 10.0) -> list[MrclamSegment]:
    """Put a robot on a uniform grid, split where the ground truth has gaps.

    Parameters
    ----------
    robot : MrclamRobot
    dt_s : float
        Grid step [s]. Vicon positions are noisy at the millimetre level, so
        speeds differentiated over 0.1 s either side are far less noisy than
        at the native 16 ms (the robots move at most 8.6 cm/s).
    max_gap_s : float
        Ground-truth gaps longer than this split the record [s].
    min_length_s : float
        Shorter stretches are dropped [s].

    Returns
    -------
    list of MrclamSegment
        In time order; only where commands and ground truth overlap.
    """
    cmd, gt = robot.commands, robot.groundtruth
    t0 = max(cmd[0, 0], gt[0, 0])
    t1 = min(cmd[-1, 0], gt[-1, 0])
    breaks = np.flatnonzero(np.diff(gt[:, 0]) > max_gap_s)
    starts = np.concatenate([[gt[0, 0]], gt[breaks + 1, 0]])
    ends = np.concatenate([gt[breaks, 0], [gt[-1, 0]]])
    heading = np.unwrap(gt[:, 3])
    segments = []
    for a, b in zip(np.maximum(starts, t0), np.minimum(ends, t1), strict=True):
        t = np.arange(a, b, dt_s)
        if len(t) * dt_s < min_length_s:
            continue
        idx = np.clip(np.searchsorted(cmd[:, 0], t, side="right") - 1, 0, len(cmd) - 1)
        pose = np.column_stack([np.interp(t, gt[:, 0], gt[:, 1]),
                                np.interp(t, gt[:, 0], gt[:, 2]),
                                np.interp(t, gt[:, 0], heading)])
        d = np.gradient(pose, dt_s, axis=0)          # central differences inside
        v = d[:, 0] * np.cos(pose[:, 2]) + d[:, 1] * np.sin(pose[:, 2])
        segments.append(MrclamSegment(t_s=t, commands_vw=cmd[idx, 1:].copy(), pose=pose,
                                      speeds_vw=np.column_stack([v, d[:, 2]])))
    return segments
