"""Planar trajectories in the TUM text format, which ``evo`` and most SLAM tools read.

One pose a line, space separated: ``timestamp tx ty tz qx qy qz qw``
(seconds; metres; a unit quaternion, scalar last). A planar pose
``(x [m], y [m], theta [rad])`` becomes ``tz = 0`` and the rotation about
``z`` by ``theta``: ``q = (0, 0, sin(theta / 2), cos(theta / 2))``. Lines
starting with ``#`` are comments.

References
----------
J. Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems",
IROS 2012 (the file format of the TUM RGB-D benchmark).
M. Grupp, evo: Python package for the evaluation of odometry and SLAM,
https://github.com/MichaelGrupp/evo (``evo_ape tum ...`` reads these files).

Examples
--------
>>> rows = tum_rows(np.array([0.0, 0.1]), np.array([[0.0, 0.0, 0.0], [1.0, 2.0, np.pi]]))
>>> (rows[1].round(6) + 0.0).tolist()
[0.1, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0]
>>> poses_from_tum(rows)[1].round(6).tolist()
[1.0, 2.0, 3.141593]
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.persistence import atomic_write

__all__ = ["TUM_HEADER", "poses_from_tum", "read_tum", "tum_rows", "write_tum"]

#: The comment line written at the top of every file.
TUM_HEADER = "timestamp tx ty tz qx qy qz qw"


def tum_rows(t_s: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Planar poses as TUM rows.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Timestamps [s], strictly increasing.
    poses : array_like, shape (n, 3)
        ``(x [m], y [m], theta [rad])``.

    Returns
    -------
    ndarray, shape (n, 8)
        ``timestamp tx ty tz qx qy qz qw`` per row.

    Raises
    ------
    ShapeError
        If the shapes are not ``(n,)`` and ``(n, 3)``.
    NonFiniteError
        If a value is NaN or infinite.
    ValueError
        If the timestamps do not increase.
    """
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(poses, dtype=float)
    if t.ndim != 1 or p.shape != (t.size, 3):
        raise ShapeError(f"expected t_s (n,) and poses (n, 3), got {t.shape} and {p.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise NonFiniteError("t_s and poses must be finite to write a TUM trajectory")
    if np.any(np.diff(t) <= 0):
        k = int(np.argmin(np.diff(t)))
        raise ValueError(f"TUM timestamps must increase; t_s[{k + 1}] = {t[k + 1]} follows "
                         f"t_s[{k}] = {t[k]}")
    half = 0.5 * p[:, 2]                          # rotation about z by theta
    zeros = np.zeros_like(t)
    return np.column_stack([t, p[:, 0], p[:, 1], zeros, zeros, zeros, np.sin(half),
                            np.cos(half)])


def poses_from_tum(rows: np.ndarray) -> np.ndarray:
    """Planar poses ``(n, 3)`` from TUM rows ``(n, 8)``: ``theta = atan2(2 qw qz, 1 - 2 qz^2)``.

    Only the rotation about ``z`` is kept (the yaw of a quaternion with
    ``qx = qy = 0``); headings are unwrapped along the trajectory.

    Raises
    ------
    ShapeError
        If ``rows`` is not ``(n, 8)``.
    """
    r = np.asarray(rows, dtype=float)
    if r.ndim != 2 or r.shape[1] != 8:
        raise ShapeError(f"expected TUM rows of shape (n, 8), got {r.shape}")
    qx, qy, qz, qw = r[:, 4], r[:, 5], r[:, 6], r[:, 7]
    # yaw of a unit quaternion (x, y, z, w), the z-y-x convention
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return np.column_stack([r[:, 1], r[:, 2], np.unwrap(yaw)])


def write_tum(path: str | os.PathLike, t_s: np.ndarray, poses: np.ndarray) -> Path:
    """Write a planar trajectory as a TUM file (``#`` header line, then one pose a line).

    Parameters
    ----------
    path : str or path-like
        Target file (customarily ``.tum`` or ``.txt``); folders are created.
    t_s, poses
        As for :func:`tum_rows`.

    Returns
    -------
    Path
        The file written, whole or not at all (:func:`~lti_motion.persistence.atomic_write`:
        a failed write, a full disk or Ctrl-C, leaves the previous file, if any, and no
        truncated one).

    Raises
    ------
    OSError
        If the file cannot be written.
    """
    rows = tum_rows(t_s, poses)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, text=True) as f:
        np.savetxt(f, rows, fmt=["%.6f"] + ["%.9g"] * 7, header=TUM_HEADER, comments="# ")
    return path


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file: timestamps ``(n,)`` [s] and planar poses ``(n, 3)``.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ShapeError
        If the rows do not have 8 columns.
    """
    rows = np.loadtxt(path, comments="#", ndmin=2)
    return rows[:, 0], poses_from_tum(rows)
