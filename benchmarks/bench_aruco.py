"""Benchmark ``aruco``: marker detection plus range-bearing and covariance, on one core.

Input: 24 seeded 640 x 480 images from :class:`fusion.landmarks.SyntheticCamera`
(fx = fy = 500 px, mounted 0.1 m forward and 0.2 m up), each with three 15 cm
``DICT_4X4_50`` markers 1-3 m away, up to 25 degrees off the heading and up
to 50 degrees oblique. OpenCV runs on one thread (``cv2.setNumThreads(1)``,
restored afterwards).

- ``aruco.images_per_s``: :meth:`fusion.landmarks.MarkerDetector.detect` over the
  images (input checks, ``detectMarkers`` with sub-pixel refinement, then per
  marker the edge-bias correction, ``solvePnP`` IPPE_SQUARE, LM refinement,
  the covariance and the robot-frame range and bearing). Target 100 images/s.
  Baseline in the same process: ``cv2.aruco.ArucoDetector.detectMarkers``
  alone with the same parameters, so the ratio is what the pose and
  covariance cost.
- ``aruco.observation_us``: :func:`fusion.landmarks.observation_from_corners` on
  one marker's detected corners (no target).
- ``aruco.render_ms``: one :meth:`fusion.landmarks.SyntheticCamera.render` of a
  three-marker scene, for simulator budgets (no target).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from benchmarks.harness import Figure, benchmark, median_seconds
from fusion.landmarks.aruco import MarkerDetector, observation_from_corners
from fusion.landmarks.camera import CameraIntrinsics, CameraMount, SyntheticCamera
from fusion.landmarks.marker_map import MarkerLandmark, MarkerMap

__all__ = ["bench_aruco", "make_scenes"]

_SEED = 20261123
_N_IMAGES = 24
_SIZE_M = 0.15


def make_scenes(n_images: int, *, seed: int = _SEED) -> list[tuple[np.ndarray, MarkerMap]]:
    """Seeded robot poses, each with three markers in view (left, ahead, right)."""
    rng = np.random.default_rng(seed)
    scenes = []
    for _ in range(n_images):
        pose = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi)])
        markers = []
        for k, (lo, hi) in enumerate([(-25.0, -14.0), (-4.0, 4.0), (14.0, 25.0)]):
            r, b = rng.uniform(1.0, 3.0), math.radians(rng.uniform(lo, hi))
            x, y = pose[0] + r * math.cos(pose[2] + b), pose[1] + r * math.sin(pose[2] + b)
            yaw = math.atan2(pose[1] - y, pose[0] - x) + math.radians(rng.uniform(-50, 50))
            markers.append(MarkerLandmark(10 * k + int(rng.integers(0, 10)), x, y,
                                          z_m=rng.uniform(0.1, 0.35), yaw_rad=yaw))
        scenes.append((pose, MarkerMap(markers, marker_size_m=_SIZE_M)))
    return scenes


@benchmark("aruco")
def bench_aruco() -> list[Figure]:
    """Detection throughput against OpenCV's detection alone, one thread."""
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return _run()
    finally:
        cv2.setNumThreads(threads)


def _run() -> list[Figure]:
    intrinsics = CameraIntrinsics.pinhole(fx_px=500.0)
    mount = CameraMount(x_m=0.1, z_m=0.2)
    camera = SyntheticCamera(intrinsics, mount=mount)
    rng = np.random.default_rng(_SEED)
    scenes = make_scenes(_N_IMAGES)
    images = [camera.render(mm, pose, rng) for pose, mm in scenes]
    detector = MarkerDetector(intrinsics, _SIZE_M, mount=mount)
    opencv = detector.aruco_detector     # the same cv2.aruco.ArucoDetector and parameters

    def ours() -> None:
        for image in images:
            detector.detect(image)

    def baseline() -> None:
        for image in images:
            opencv.detectMarkers(image)

    # Interleave so both see the same machine load.
    t_ours, t_base = [], []
    for _ in range(5):
        t_ours.append(median_seconds(ours, repeat=3))
        t_base.append(median_seconds(baseline, repeat=3))
    ours_per_s = _N_IMAGES / float(np.median(t_ours))
    base_per_s = _N_IMAGES / float(np.median(t_base))

    ids, corners = detector.detect_corners(images[0])
    one = corners[0]
    t_obs = median_seconds(lambda: [observation_from_corners(
        int(ids[0]), one, intrinsics, marker_size_m=_SIZE_M, mount=mount) for _ in range(200)],
        repeat=7) / 200
    pose, mm = scenes[0]
    t_render = median_seconds(lambda: camera.render(mm, pose, rng), repeat=7)
    return [
        Figure(name="aruco.images_per_s", value=ours_per_s, unit="images/s", target=100.0,
               better="higher", baseline="cv2.aruco.ArucoDetector.detectMarkers alone",
               baseline_value=base_per_s),
        Figure(name="aruco.observation_us", value=t_obs * 1e6, unit="us", better="lower"),
        Figure(name="aruco.render_ms", value=t_render * 1e3, unit="ms", better="lower"),
    ]
