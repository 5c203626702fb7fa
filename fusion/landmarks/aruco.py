"""ArUco markers in a camera image as range-bearing observations from the camera's mount.

Detection is OpenCV's (``cv2.aruco.ArucoDetector``, Garrido-Jurado et al.
2014, sub-pixel corner refinement); the marker pose in the camera frame comes
from ``cv2.solvePnP(..., flags=cv2.SOLVEPNP_IPPE_SQUARE)`` (Collins & Bartoli
2014), polished by ``cv2.solvePnPRefineLM`` to the least-squares pose. The
marker centre ``t`` (optical frame) goes to the camera's planar frame: origin
the projection centre's foot on the ground plane, x along the optical axis's
heading (the mount's yaw), y left, z up (:mod:`fusion.landmarks.camera`), by
the mount's pitch alone, ``p = Ry(pitch) R0 t`` (``robot_R_camera t`` turned
back by ``Rz(-yaw)``), and the observation is planar:

.. math::

    r = \\sqrt{p_x^2 + p_y^2}, \\qquad b = \\operatorname{atan2}(p_y, p_x)

(range from the camera in the ground plane [m], bearing counter-clockwise
from the camera's heading [rad]); the height ``p_z`` is dropped.
Detections come out as the package's one observation type,
:class:`fusion.range_bearing.RangeBearing`: one row per marker, its id, range,
bearing and covariance (eq. 2-3 below), ``index`` the frame the image belongs
to, and the camera's planar mount ``(x_m, y_m, yaw_rad)`` as its
``sensor_pose`` (:meth:`fusion.landmarks.CameraMount.sensor_pose`),
through which the EKFs, the factor graph and the scale test predict it
(:mod:`fusion.range_bearing`, eq. 1); they take it as it is.

Diagnostics
-----------
Two figures of a detection say how far to trust it beyond its covariance: the
marker's apparent size ``pixel_size`` [px] (the square root of its area in the
image; it sets the corner noise, :meth:`CornerNoise.at_size`) and its
obliquity [rad] (the angle between the marker's outward normal and the line
of sight; near 0, small markers may report the mirror pose, IPPE's two-fold
ambiguity, which changes the obliquity but hardly the range and bearing).
They are not part of the observation: :func:`detection_diagnostics` computes
them from the corners :meth:`MarkerDetector.detect_corners` returns, with the
same pose solution as :func:`observation_from_corners`.

Covariance
----------
The eight corner coordinates ``c`` are modelled (:class:`CornerNoise`) as the
true projections plus independent noise of standard deviation ``sigma_n``,
plus a common edge bias: every edge of the quadrilateral sits ``beta`` pixels
inside the true edge (the convex-corner bias of ``cv2.cornerSubPix`` under
blur), ``beta ~ N(beta_0, sigma_b^2)``; ``sigma_n`` and ``beta_0`` grow as the
marker's apparent size shrinks (:meth:`CornerNoise.at_size`). The mean
``beta_0`` is removed (:func:`correct_edge_bias`); what is left has covariance

.. math::

    \\Sigma_c = \\sigma_n^2 I_8 + \\sigma_b^2 \\, d d^T,            \\qquad (1)

with ``d`` the motion of the corners when all edges move out by one pixel.
With ``J`` (8 x 6) the derivative of the projected corners with respect to
``(rvec, tvec)`` at the least-squares pose (``cv2.projectPoints``), the pose
moves to first order by ``A dc`` with ``A = (J^T J)^{-1} J^T`` (Hartley &
Zisserman 2004, sec. 5.2.2, backward propagation of covariance), so

.. math::

    \\Sigma_\\text{pose} = A \\Sigma_c A^T
    = \\sigma_n^2 (J^T J)^{-1} + \\sigma_b^2 (A d)(A d)^T,         \\qquad (2)

and the range-bearing covariance is ``G Sigma_t G^T`` with ``Sigma_t`` the
translation block of (2) and

.. math::

    G = \\begin{bmatrix} p_x / r & p_y / r \\\\ -p_y / r^2 & p_x / r^2
    \\end{bmatrix} \\, [R_y(\\text{pitch}) R_0]_{1:2,\\,:}.   \\qquad (3)

It grows with range (the marker's apparent size fixes the depth and shrinks
as ``1 / r``), with obliquity (foreshortening) and for smaller markers, through
``J`` and through ``sigma_n``; the edge-bias term acts on the apparent size,
hence mostly on the range. The mount and the intrinsics are taken as exact: their errors are
biases that no per-image covariance describes.

The defaults of :class:`CornerNoise` were measured on the synthetic camera of
:mod:`fusion.landmarks.camera` (``docs/aruco.md``). For a real camera, measure them:
``sigma_n`` from the corner scatter of a static marker, ``beta_0`` from the
range error of markers at known distances, both at a few apparent sizes.

References
----------
S. Garrido-Jurado, R. Muñoz-Salinas, F. J. Madrid-Cuevas, M. J. Marín-Jiménez,
"Automatic generation and detection of highly reliable fiducial markers under
occlusion", Pattern Recognition 47(6), 2280-2292, 2014.

T. Collins, A. Bartoli, "Infinitesimal Plane-Based Pose Estimation",
International Journal of Computer Vision 109(3), 252-286, 2014.

R. Hartley, A. Zisserman, "Multiple View Geometry in Computer Vision", 2nd ed.,
Cambridge University Press, 2004: sec. 2.2.1 (points and lines) and sec. 5.2.2
(backward propagation of covariance).
"""

from __future__ import annotations

import logging
import math
from dataclasses import KW_ONLY, dataclass, field
from types import MappingProxyType
from typing import Literal, NamedTuple

import cv2
import numpy as np

from fusion.exceptions import (
    CameraOptionError,
    ImageDtypeError,
    ImageShapeError,
    MarkerPoseError,
)
from fusion.landmarks.camera import CameraIntrinsics, CameraMount, SyntheticCamera
from fusion.landmarks.marker_map import MarkerMap, dictionary_size
from fusion.range_bearing import RangeBearing

__all__ = [
    "CornerNoise",
    "MarkerDetector",
    "correct_edge_bias",
    "detect_markers",
    "detection_diagnostics",
    "edge_shift_directions",
    "marker_object_points",
    "observation_from_corners",
    "observations_from_pose",
]

_log = logging.getLogger(__name__)

#: Below this range [m] the bearing is undefined.
_MIN_RANGE_M = 1e-6
#: Detected corner index for each of the object points of :func:`marker_object_points`.
_IPPE_FROM_ARUCO = np.array([3, 2, 1, 0])
_IPPE_FROM_ARUCO.flags.writeable = False
_NEXT = np.array([1, 2, 3, 0])
_NEXT.flags.writeable = False
#: Translation within about 1e-5 m of the converged pose, at half the default's cost.
_LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 10, 1e-6)
#: Sub-pixel refinement window relative to the marker cell (OpenCV's default is 0.3).
_RELATIVE_REFINE_WINDOW = 0.5
_REFINEMENT = MappingProxyType({"none": cv2.aruco.CORNER_REFINE_NONE,
                                "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                                "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
                                "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG})










@dataclass(frozen=True)
class CornerNoise:
    """Corner error model of the covariance (module docstring, eq. 1), by apparent size.

    With ``s`` the marker's apparent size (the square root of its area in
    the image, :func:`detection_diagnostics`) [px], the independent noise and
    the mean inward edge offset are

    .. math::

        \\sigma_n(s) = \\sqrt{\\sigma_0^2 + (\\sigma_{20} (20 / s)^2)^2}, \\qquad
        \\beta_0(s) = \\beta_\\infty + \\beta_{20} \\, (20 / s).

    Both grow for small markers because OpenCV sizes the sub-pixel window
    from the marker's cell (``relativeCornerRefinmentWinSize``), and a small
    window on a blurred corner is noisier and more biased. The defaults are
    fits on the synthetic camera (blur 0.8 px, noise 2.5 grey levels,
    markers of 15-100 px; ``docs/aruco.md``), with ``sigma_0`` and
    ``sigma_b`` raised to cover blur from 0.5 to 1.2 px.

    Attributes
    ----------
    sigma_px : float
        ``sigma_0``: independent noise of each corner coordinate of a large marker [px].
    sigma_at_20px : float
        ``sigma_20``: the small-marker noise term at ``s = 20`` px [px].
    edge_bias_px : float
        ``beta_inf``: inward offset of the detected edges of a large marker [px].
    edge_bias_at_20px : float
        ``beta_20``: the small-marker offset term at ``s = 20`` px [px].
    edge_bias_sigma_px : float
        ``sigma_b``: uncertainty of the offset [px] (it scales with the blur).

    Raises
    ------
    CameraOptionError
        If ``sigma_px`` is not positive, or a value is negative, not finite or
        above 5 px.

    Examples
    --------
    >>> [round(v, 3) for v in CornerNoise().at_size(20.0)]
    [0.156, 0.29]
    """

    _: KW_ONLY
    sigma_px: float = 0.1
    sigma_at_20px: float = 0.12
    edge_bias_px: float = 0.08
    edge_bias_at_20px: float = 0.21
    edge_bias_sigma_px: float = 0.08

    def __post_init__(self) -> None:
        values = (self.sigma_px, self.sigma_at_20px, self.edge_bias_px, self.edge_bias_at_20px,
                  self.edge_bias_sigma_px)
        if not all(math.isfinite(v) and 0 <= v <= 5 for v in values) or self.sigma_px <= 0:
            raise CameraOptionError(f"CornerNoise needs 0 < sigma_px and 0 <= the others, all "
                                    f"at most 5 px; got {self}")

    def at_size(self, pixel_size: float) -> tuple[float, float]:
        """``(sigma_n, beta_0)`` [px] for a marker of apparent size ``pixel_size`` [px]."""
        ratio = 20.0 / max(float(pixel_size), 1.0)
        return (math.hypot(self.sigma_px, self.sigma_at_20px * ratio * ratio),
                self.edge_bias_px + self.edge_bias_at_20px * ratio)


def marker_object_points(marker_size_m: float) -> np.ndarray:
    """Corners of a marker in its pose frame, in the order ``SOLVEPNP_IPPE_SQUARE`` needs, (4, 3).

    The pose frame is the camera's for a marker seen head-on: ``x`` right,
    ``y`` down, ``z`` into the printed face, so the rotation of a marker facing
    the camera is near the identity (far from the rotation-vector singularity
    at ``pi``, where ``cv2.Rodrigues`` loses precision). The four points pair
    with the detected corners bottom-left, bottom-right, top-right, top-left
    (ArUco corners 3, 2, 1, 0).

    Examples
    --------
    >>> marker_object_points(0.2).tolist()[0]
    [-0.1, 0.1, 0.0]
    """
    h = 0.5 * float(marker_size_m)
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def edge_shift_directions(corners_px: np.ndarray) -> np.ndarray:
    """How each corner moves when every edge of a quadrilateral moves outward by 1 px, (4, 2).

    Edge ``i`` (corner ``i`` to ``i + 1``) is the line ``n_i . x = o_i`` with
    ``n_i`` its outward unit normal; moving it out by ``e`` adds ``e`` to
    ``o_i``. Corner ``i`` is where edges ``i - 1`` and ``i`` meet, the solution
    of ``[n_{i-1}; n_i] x = [o_{i-1}; o_i]``, so it moves by
    ``e [n_{i-1}; n_i]^{-1} (1, 1)^T`` (Hartley & Zisserman 2004, sec. 2.2.1:
    the meet of two lines). Zero for a degenerate quadrilateral.

    Parameters
    ----------
    corners_px : array_like, shape (4, 2)
        Corners [px] in order around a convex quadrilateral (either direction).

    Returns
    -------
    ndarray, shape (4, 2)
        Corner motion per pixel of outward edge motion [px/px].

    Examples
    --------
    >>> edge_shift_directions(np.array([[0, 0], [10, 0], [10, 10], [0, 10]])).tolist()
    [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
    """
    c = np.asarray(corners_px, dtype=float).tolist()   # four corners: plain floats are faster
    edges = [(c[(i + 1) % 4][0] - c[i][0], c[(i + 1) % 4][1] - c[i][1]) for i in range(4)]
    area2 = sum(c[i][0] * c[(i + 1) % 4][1] - c[(i + 1) % 4][0] * c[i][1] for i in range(4))
    lengths = [math.hypot(dx, dy) for dx, dy in edges]
    if min(lengths) < 1e-9 or abs(area2) < 1e-9:
        return np.zeros((4, 2))
    # Outward normal (d_y, -d_x) for a positive shoelace sum, its negative otherwise.
    sign = 1.0 if area2 > 0 else -1.0
    normals = [(sign * dy / n, -sign * dx / n) for (dx, dy), n in zip(edges, lengths, strict=True)]
    out = np.empty((4, 2))
    for i in range(4):
        (px, py), (nx, ny) = normals[i - 1], normals[i]   # edges i - 1 and i meet at corner i
        det = px * ny - py * nx
        if abs(det) < 1e-9:
            return np.zeros((4, 2))
        out[i] = ((ny - py) / det, (px - nx) / det)
    return out


def correct_edge_bias(corners_px: np.ndarray, edge_bias_px: float) -> np.ndarray:
    """Move each edge of a quadrilateral outward by ``edge_bias_px`` [px].

    Sub-pixel refinement (``cv2.cornerSubPix``) of a blurred convex corner is
    pulled inside the marker: each edge sits about ``edge_bias_px`` inside
    the true one, so the marker looks smaller and the range too long (by about
    ``2 edge_bias_px / pixel_size``). The edges are moved out along their
    normals and the corners re-intersected (:func:`edge_shift_directions`).

    Parameters
    ----------
    corners_px : array_like, shape (4, 2)
        Corners [px] in order around a convex quadrilateral.
    edge_bias_px : float
        Outward shift of every edge [px]; negative moves inward.

    Returns
    -------
    ndarray, shape (4, 2)
        Moved corners [px]; the input for a degenerate quadrilateral.

    Examples
    --------
    >>> correct_edge_bias(np.array([[0, 0], [10, 0], [10, 10], [0, 10]]), 0.5).tolist()
    [[-0.5, -0.5], [10.5, -0.5], [10.5, 10.5], [-0.5, 10.5]]
    """
    c = np.asarray(corners_px, dtype=float)
    return c + edge_bias_px * edge_shift_directions(c)


class _Measured(NamedTuple):
    """One detection solved: the observation row and its diagnostics."""

    range_m: float
    bearing_rad: float
    cov: np.ndarray
    pixel_size: float
    obliquity_rad: float


def _measure(marker_id: int, corners_px: np.ndarray, intrinsics: CameraIntrinsics, *,
             marker_size_m: float, mount: CameraMount, noise: CornerNoise | None) -> _Measured:
    """Range, bearing, covariance (module docstring, eq. 1-3), apparent size and obliquity."""
    noise = CornerNoise() if noise is None else noise
    raw = np.asarray(corners_px, dtype=np.float64)
    if raw.shape != (4, 2) or not np.all(np.isfinite(raw)):
        raise ImageShapeError(f"marker corners must be finite with shape (4, 2), got {raw.shape}")
    if not (math.isfinite(marker_size_m) and marker_size_m > 0):
        raise CameraOptionError(f"marker_size_m must be a positive length [m], got {marker_size_m}")
    x, y = raw[:, 0], raw[:, 1]
    pixel_size = math.sqrt(0.5 * abs(float(x @ y[_NEXT] - y @ x[_NEXT])))   # shoelace area
    sigma_n, beta_0 = noise.at_size(pixel_size)
    shift = edge_shift_directions(raw)
    corners = raw + beta_0 * shift
    obj = marker_object_points(marker_size_m)
    k, dist = intrinsics.camera_matrix, intrinsics.dist_coeffs
    image_pts = np.ascontiguousarray(corners[_IPPE_FROM_ARUCO])
    rvec, tvec = _solve_pose(obj, image_pts, k, dist)
    if rvec is None:
        raise MarkerPoseError(f"solvePnP found no pose for marker {marker_id} with corners "
                              f"{raw.tolist()}")
    _, jac = cv2.projectPoints(obj, rvec, tvec, k, dist)
    j = jac[:, :6]                              # d(u0, v0, ..., u3, v3) / d(rvec, tvec)
    eig, vec = np.linalg.eigh(j.T @ j)
    if not eig[0] > 1e-12 * eig[-1]:
        raise MarkerPoseError(f"marker {marker_id}: the corners {raw.tolist()} do not fix the pose")
    info_inv = (vec / eig) @ vec.T              # (J^T J)^-1
    d = shift[_IPPE_FROM_ARUCO].ravel()         # eq. 1 (corner motion per pixel of edge bias)
    a_d = info_inv @ (j.T @ d)
    cov_pose = sigma_n ** 2 * info_inv + noise.edge_bias_sigma_px ** 2 * np.outer(a_d, a_d)  # (2)
    level_r_cam = mount.level_R_camera()
    p = level_r_cam @ tvec[:, 0]                # the camera's planar frame (module docstring)
    q = p[0] * p[0] + p[1] * p[1]
    if q < _MIN_RANGE_M ** 2:
        raise MarkerPoseError(f"marker {marker_id} is right above the camera: no bearing")
    r = math.sqrt(q)
    g = np.array([[p[0] / r, p[1] / r], [-p[1] / q, p[0] / q]]) @ level_r_cam[:2, :]   # eq. 3
    cov = g @ cov_pose[3:, 3:] @ g.T
    cov = 0.5 * (cov + cov.T)
    # The outward normal is -z of the pose frame; the line of sight to the camera is -t.
    into_face = cv2.Rodrigues(rvec)[0][:, 2]
    cos_obl = float(into_face @ tvec[:, 0]) / float(np.linalg.norm(tvec))
    if cos_obl <= 0.0:
        raise MarkerPoseError(f"marker {marker_id}: the corners {raw.tolist()} are in mirror "
                              "order (the marker would be seen from behind)")
    return _Measured(r, math.atan2(p[1], p[0]), cov, pixel_size, math.acos(min(1.0, cos_obl)))


def observation_from_corners(marker_id: int, corners_px: np.ndarray,
                             intrinsics: CameraIntrinsics, *, marker_size_m: float,
                             mount: CameraMount, noise: CornerNoise | None = None,
                             index: int = 0) -> RangeBearing:
    """Range, bearing and covariance of a marker from its four detected image corners.

    Parameters
    ----------
    marker_id : int
        The marker's id (the row's landmark id).
    corners_px : array_like, shape (4, 2)
        Corners [px] as detected: top-left, top-right, bottom-right,
        bottom-left of the marker (the ArUco order), in the distorted image.
    intrinsics : CameraIntrinsics
        The camera.
    marker_size_m : float
        Side of the marker's black square [m].
    mount : CameraMount
        The camera's pose on the robot.
    noise : CornerNoise, optional
        Corner error model; its edge offset ``beta_0`` is removed first
        (default ``CornerNoise()``).
    index : int
        The row's index: the frame the image belongs to.

    Returns
    -------
    RangeBearing
        One row: ``range_m`` (ground-plane distance from the camera to the
        marker centre [m]), ``bearing_rad`` (``atan2(y, x)`` of the marker
        centre in the camera's planar frame, in ``(-pi, pi]``), ``cov``, the
        covariance of ``(range, bearing)`` (module docstring, eq. 2-3), and
        ``sensor_pose``, the camera's planar mount.

    Raises
    ------
    ImageShapeError
        If ``corners_px`` is not (4, 2) or not finite.
    CameraOptionError
        If ``marker_size_m`` is not a positive length.
    MarkerPoseError
        If the pose cannot be solved, is degenerate, or shows the marker's back.

    Examples
    --------
    >>> cam = CameraIntrinsics.pinhole(fx_px=500.0)
    >>> c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * 25.0 + [319.5, 239.5]
    >>> o = observation_from_corners(0, c, cam, marker_size_m=0.1, mount=CameraMount(z_m=0.0),
    ...                              noise=CornerNoise(edge_bias_px=0.0, edge_bias_at_20px=0.0))
    >>> round(float(o.range_m[0]), 6), round(float(o.bearing_rad[0]), 6) + 0.0, o.cov.shape
    (1.0, 0.0, (1, 2, 2))
    >>> o.sensor_pose                          # the camera, 0.1 m ahead of the axle
    SensorPose(x_m=0.1, y_m=0.0, yaw_rad=0.0)
    """
    m = _measure(marker_id, corners_px, intrinsics, marker_size_m=marker_size_m, mount=mount,
                 noise=noise)
    return RangeBearing(index, [int(marker_id)], [m.range_m], [m.bearing_rad], cov=[m.cov],
                        sensor_pose=mount.sensor_pose())


def detection_diagnostics(corners_px: np.ndarray, intrinsics: CameraIntrinsics, *,
                          marker_size_m: float, mount: CameraMount,
                          noise: CornerNoise | None = None) -> tuple[float, float]:
    """Apparent size and obliquity of a detected marker (module docstring, *Diagnostics*).

    The figures that say how far to trust a detection beyond its covariance,
    from the same pose solution as :func:`observation_from_corners` (same
    arguments); not part of the observation.

    Returns
    -------
    pixel_size : float
        Square root of the marker's area in the image [px] (its side when seen
        head-on); it sets the corner noise (:meth:`CornerNoise.at_size`).
    obliquity_rad : float
        Angle between the marker's outward normal and the line of sight to
        the camera [rad]; 0 when seen head-on. Small markers seen almost
        head-on may report the mirror pose (IPPE's two-fold ambiguity), which
        changes this angle but hardly the range and bearing.

    Raises
    ------
    ImageShapeError, CameraOptionError, MarkerPoseError
        As :func:`observation_from_corners`.

    Examples
    --------
    >>> cam = CameraIntrinsics.pinhole(fx_px=500.0)
    >>> c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * 25.0 + [319.5, 239.5]
    >>> size, obliquity = detection_diagnostics(c, cam, marker_size_m=0.1,
    ...                                         mount=CameraMount(z_m=0.0))
    >>> size, obliquity < 1e-6
    (50.0, True)
    """
    m = _measure(-1, corners_px, intrinsics, marker_size_m=marker_size_m, mount=mount,
                 noise=noise)
    return m.pixel_size, m.obliquity_rad


def _solve_pose(obj: np.ndarray, image_pts: np.ndarray, k: np.ndarray,
                dist: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Least-squares marker pose ``(rvec, tvec)`` (3, 1) each, or ``(None, None)``."""
    try:
        # IPPE_SQUARE returns NaN for an exactly symmetric view; general IPPE then does.
        for flag in (cv2.SOLVEPNP_IPPE_SQUARE, cv2.SOLVEPNP_IPPE):
            ok, rvec, tvec = cv2.solvePnP(obj, image_pts, k, dist, flags=flag)
            if ok and np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)):
                break
        else:
            return None, None
        # Polish to the least-squares pose, whose first-order covariance is eq. 2
        # (IPPE's closed form is also imprecise for a marker seen exactly head-on).
        rvec, tvec = cv2.solvePnPRefineLM(obj, image_pts, k, dist, rvec, tvec, _LM_CRITERIA)
    except cv2.error:
        return None, None
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))) or tvec[2, 0] <= 0:
        return None, None
    return rvec, tvec


def _grey(image: np.ndarray) -> np.ndarray:
    """Validated 8-bit grey image (H, W); BGR is converted."""
    if not isinstance(image, np.ndarray):
        raise ImageDtypeError(f"image must be a numpy uint8 array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ImageDtypeError(
            f"image must be uint8 (8-bit grey or BGR), got dtype {image.dtype}; scale and convert "
            "first, e.g. np.clip(img * 255, 0, 255).astype(np.uint8) for floats in [0, 1]")
    if image.ndim == 3 and image.shape[2] in (1, 3) and image.size == 0:
        return image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim != 2:
        raise ImageShapeError(f"image must have shape (H, W), (H, W, 1) or (H, W, 3) (BGR), "
                              f"got {image.shape}; convert BGRA or RGBA to BGR or grey first")
    return np.ascontiguousarray(image)


@dataclass(frozen=True)
class MarkerDetector:
    """ArUco detector plus pose, range-bearing and covariance (module docstring).

    Parameters
    ----------
    intrinsics : CameraIntrinsics
        The camera; images must have its size.
    marker_size_m : float
        Side of the markers' black square [m].
    mount : CameraMount
        The camera on the robot.
    dictionary : str
        ``cv2.aruco`` predefined dictionary name.
    noise : CornerNoise
        Corner error model (its defaults fit ``"subpix"`` on the synthetic camera).
    corner_refinement : {"subpix", "none", "contour", "apriltag"}
        OpenCV's corner refinement; ``"subpix"`` runs with a window of half a
        marker cell. The others need their own :class:`CornerNoise`
        (``"apriltag"`` is also about 50 times slower).

    Raises
    ------
    CameraOptionError
        If the size is not positive or the refinement is unknown.
    fusion.landmarks.marker_map.MarkerMapError
        If the dictionary is unknown.

    Examples
    --------
    >>> det = MarkerDetector(CameraIntrinsics.pinhole(fx_px=500.0), marker_size_m=0.15)
    >>> len(det.detect(np.full((480, 640), 128, np.uint8)))
    0
    """

    intrinsics: CameraIntrinsics
    marker_size_m: float
    _: KW_ONLY
    mount: CameraMount = field(default_factory=CameraMount)
    dictionary: str = "DICT_4X4_50"
    noise: CornerNoise = field(default_factory=CornerNoise)
    corner_refinement: Literal["subpix", "none", "contour", "apriltag"] = "subpix"
    _detector: cv2.aruco.ArucoDetector = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        size = float(self.marker_size_m)
        if not (math.isfinite(size) and size > 0):
            raise CameraOptionError(f"marker_size_m must be a positive length [m], got {size}")
        if self.corner_refinement not in _REFINEMENT:
            raise CameraOptionError(f"corner_refinement must be one of {sorted(_REFINEMENT)}, "
                                    f"got {self.corner_refinement!r}")
        dictionary_size(self.dictionary)
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = _REFINEMENT[self.corner_refinement]
        params.relativeCornerRefinmentWinSize = _RELATIVE_REFINE_WINDOW
        detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)), params)
        object.__setattr__(self, "_detector", detector)

    @property
    def aruco_detector(self) -> cv2.aruco.ArucoDetector:
        """The underlying ``cv2.aruco.ArucoDetector`` (its parameters are this detector's)."""
        return self._detector

    @classmethod
    def for_map(cls, intrinsics: CameraIntrinsics, marker_map: MarkerMap, *,
                mount: CameraMount | None = None,
                noise: CornerNoise | None = None) -> MarkerDetector:
        """A detector for the dictionary and marker size of a map."""
        return cls(intrinsics, marker_map.marker_size_m,
                   mount=CameraMount() if mount is None else mount,
                   dictionary=marker_map.dictionary,
                   noise=CornerNoise() if noise is None else noise)

    def detect_corners(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Marker ids and corners: OpenCV's detection only.

        Parameters
        ----------
        image : ndarray
            ``uint8``, shape (H, W), (H, W, 1) or (H, W, 3) (BGR), of the
            intrinsics' size; an image with no pixels gives no markers.

        Returns
        -------
        ids : ndarray of int, shape (n,)
        corners_px : ndarray, shape (n, 4, 2)
            Top-left, top-right, bottom-right, bottom-left [px], as detected.

        Raises
        ------
        ImageDtypeError, ImageShapeError
            For an image of the wrong dtype, layout or size.
        """
        grey = _grey(image)
        none = np.zeros(0, dtype=int), np.zeros((0, 4, 2))
        if grey.size == 0:
            return none
        expected = (self.intrinsics.height_px, self.intrinsics.width_px)
        if grey.shape != expected:
            raise ImageShapeError(f"image is {grey.shape} (H, W) but the intrinsics are for "
                                  f"{expected}; rescale K or the image")
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None or len(ids) == 0:
            return none
        return ids.ravel().astype(int), np.asarray(corners, dtype=float).reshape(-1, 4, 2)

    def detect(self, image: np.ndarray, *, index: int = 0) -> RangeBearing:
        """Detect markers: one range-bearing row with its covariance per marker.

        Parameters
        ----------
        image : ndarray
            As in :meth:`detect_corners`.
        index : int
            The rows' index: the frame the image belongs to.

        Returns
        -------
        RangeBearing
            The markers in OpenCV's order, ``cov`` set (module docstring,
            eq. 2-3), ``sensor_pose`` the camera's planar mount; ids the map
            may not hold (a misread code) included
            (:meth:`fusion.landmarks.MarkerMap.split_known` sorts them out).
            Markers whose pose is degenerate (:class:`MarkerPoseError`) are
            skipped and logged at debug level. Their apparent size and
            obliquity: :func:`detection_diagnostics` on :meth:`detect_corners`.

        Raises
        ------
        ImageDtypeError, ImageShapeError
            For an image of the wrong dtype, layout or size.
        """
        ids, corners = self.detect_corners(image)
        rows = []
        for marker_id, c in zip(ids.tolist(), corners, strict=True):
            try:
                rows.append((marker_id, _measure(marker_id, c, self.intrinsics,
                                                 marker_size_m=self.marker_size_m,
                                                 mount=self.mount, noise=self.noise)))
            except MarkerPoseError as exc:
                _log.debug("skipping a detection: %s", exc)
        if not rows:
            return RangeBearing.empty()
        return RangeBearing(index, [i for i, _ in rows], [m.range_m for _, m in rows],
                            [m.bearing_rad for _, m in rows], cov=[m.cov for _, m in rows],
                            sensor_pose=self.mount.sensor_pose())


def detect_markers(image: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray | None,
                   *, marker_size_m: float, mount: CameraMount | None = None,
                   dictionary: str = "DICT_4X4_50",
                   noise: CornerNoise | None = None, index: int = 0) -> RangeBearing:
    """Detect markers in one image (builds a :class:`MarkerDetector`; keep one for a stream).

    Parameters
    ----------
    image : ndarray
        ``uint8``, shape (H, W), (H, W, 1) or (H, W, 3) (BGR).
    camera_matrix : array_like, shape (3, 3)
        ``K`` [px] for this image size.
    dist_coeffs : array_like or None
        OpenCV distortion coefficients (``None``: no distortion).
    marker_size_m : float
        Side of the markers' black square [m].
    mount : CameraMount, optional
        The camera on the robot (default ``CameraMount()``).
    dictionary : str
        ``cv2.aruco`` predefined dictionary name.
    noise : CornerNoise, optional
        Corner error model (default ``CornerNoise()``).
    index : int
        The rows' index: the frame the image belongs to.

    Returns
    -------
    RangeBearing
        One row per marker (:meth:`MarkerDetector.detect`).

    Raises
    ------
    ImageDtypeError, ImageShapeError
        For an image of the wrong dtype or layout.
    fusion.exceptions.CameraShapeError, fusion.exceptions.CameraOptionError
        For intrinsics of the wrong shape or values.

    Examples
    --------
    >>> detect_markers(np.zeros((480, 640), np.uint8), np.eye(2), None, marker_size_m=0.15)
    Traceback (most recent call last):
    ...
    fusion.exceptions.CameraShapeError: camera matrix K must have shape (3, 3), got (2, 2)
    """
    grey = _grey(image)
    intrinsics = CameraIntrinsics(camera_matrix, max(grey.shape[1], 1), max(grey.shape[0], 1),
                                  dist_coeffs=dist_coeffs)
    if grey.size == 0:
        return RangeBearing.empty()
    detector = MarkerDetector(intrinsics, marker_size_m,
                              mount=CameraMount() if mount is None else mount,
                              dictionary=dictionary,
                              noise=CornerNoise() if noise is None else noise)
    return detector.detect(grey, index=index)


def observations_from_pose(camera: SyntheticCamera, marker_map: MarkerMap,
                           robot_pose: np.ndarray, rng: np.random.Generator, *,
                           detector: MarkerDetector | None = None,
                           index: int = 0) -> RangeBearing:
    """Render the map from a robot pose and detect its markers (simulation).

    Parameters
    ----------
    camera : SyntheticCamera
        The simulated camera and its mount.
    marker_map : MarkerMap
        The markers; detection uses its dictionary and size.
    robot_pose : array_like, shape (3,)
        True ``(x [m], y [m], theta [rad])``.
    rng : numpy.random.Generator
        Source of the image noise.
    detector : MarkerDetector, optional
        Reuse a detector (faster in a loop); default
        ``MarkerDetector.for_map(camera.intrinsics, marker_map, mount=camera.mount)``.
        Its intrinsics, mount and marker size are what the estimator believes;
        make them differ from the camera's to simulate calibration errors.
    index : int
        The rows' index: the frame the image belongs to.

    Returns
    -------
    RangeBearing
        One row per marker, with its covariance. May hold ids the map does not
        have (a misread code); sort them out with
        :meth:`fusion.landmarks.MarkerMap.split_known`.

    Examples
    --------
    >>> from fusion.landmarks.camera import CameraIntrinsics, SyntheticCamera
    >>> from fusion.landmarks.marker_map import MarkerLandmark, MarkerMap
    >>> mm = MarkerMap([MarkerLandmark(3, 2.0, 0.5, z_m=0.2, yaw_rad=math.pi)])
    >>> cam = SyntheticCamera(CameraIntrinsics.pinhole(fx_px=500.0))
    >>> [(marker_id, z, cov)] = observations_from_pose(cam, mm, np.zeros(3),
    ...                                                np.random.default_rng(1), index=7)
    >>> marker_id, round(float(z[0]), 2), round(math.degrees(z[1]), 1), cov.shape
    (3, 1.96, 14.7, (2, 2))
    """
    if detector is None:
        detector = MarkerDetector.for_map(camera.intrinsics, marker_map, mount=camera.mount)
    return detector.detect(camera.render(marker_map, robot_pose, rng), index=index)
