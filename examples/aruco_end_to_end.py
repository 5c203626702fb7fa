"""End to end: simulated drive -> rendered camera images -> ArUco detection -> EKF and smoother.

1. Calibrate the ARX motion model on the simulator (``examples/ekf_plugin.py``).
2. Drive the EKF example's rounded square in a 5 m x 5 m room (:meth:`Room.box`) whose
   walls carry twelve 15 cm ArUco markers (``DICT_4X4_50``) at camera height, facing in.
3. At 5 Hz (every 13th or 14th 15 ms frame) render the camera image from the robot's
   *true* pose (:class:`fusion.landmarks.SyntheticCamera`, 640 x 480, fx 500 px, 0.1 m
   ahead of the axle: the physical world) and detect the markers in it
   (:class:`fusion.landmarks.MarkerDetector`): range and bearing from the camera and a
   per-detection covariance, as rows of a :class:`fusion.range_bearing.RangeBearing` whose
   ``index`` is the image's frame and whose ``sensor_pose`` is the camera's mount. Ids not
   in the map are dropped.
4. Fuse the same detections, with the commands and encoder counts, in
   :class:`fusion.ekf.ModelEKF` (causal) and :class:`fusion.graph.IncrementalSmoother`
   (iSAM2 over keyframes; every image is a keyframe, plus one every 33 frames).
5. Report position RMS errors and plot truth, EKF and smoother into ``OUT/aruco_end_to_end.png``.

Run::

    python examples/aruco_end_to_end.py --out out/aruco_end_to_end [--duration-s 300]
        [--seed 0] [--short]

Measurement noise: each detection's full 2 x 2 covariance ``C`` (``fusion.landmarks.aruco``,
eq. 2-3, range-bearing correlation included; median |rho| printed) enters both estimators;
``full_covariance=False`` gives them its diagonal instead (:func:`diagonal`). Both predict
the detections from the camera's mount on the robot (``RangeBearing.sensor_pose``).

Neither estimator reads the simulator's truth: they start from the known start pose
:data:`START_POSE` and see only commands, encoder counts and detections. The path
follower steers on the true pose, as in ``examples/ekf_plugin.py`` (a perfect localiser).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType

import numpy as np
from matplotlib.figure import Figure

from drivers.sim import Room, Simulator
from fusion.ekf import EKFOptions, ModelEKF
from fusion.graph import IncrementalSmoother, SmootherOptions, log_keyframes, preintegrate_model
from fusion.landmarks import (
    CameraIntrinsics,
    CameraMount,
    MarkerDetector,
    MarkerLandmark,
    MarkerMap,
    SyntheticCamera,
)
from fusion.range_bearing import RangeBearing
from lti_motion.calibration import speeds_from_log
from lti_motion.model import MotionModel
from lti_motion.recordings import FrameLog

__all__ = [
    "CAMERA_RATE_HZ",
    "KEYFRAME_EVERY",
    "ROOM_M",
    "SMOOTHER_OPTIONS",
    "START_POSE",
    "Detections",
    "EndToEndRun",
    "camera_frames",
    "detect_along",
    "diagonal",
    "load_ekf_example",
    "main",
    "make_camera",
    "plot_run",
    "run_ekf",
    "run_end_to_end",
    "run_smoother",
    "wall_markers",
]

ROOT = Path(__file__).resolve().parents[1]
ROOM_M = 5.0
#: Camera rate [Hz]: an image every 13 or 14 frames of 15 ms.
CAMERA_RATE_HZ = 5.0
#: Regular smoother keyframes between images [frames] (0.5 s), as in ``examples/factor_graph.py``.
KEYFRAME_EVERY = 33
#: The smoother's settings, like for like with :class:`fusion.ekf.ModelEKF`: motion from the
#: model's encoder-filtered speeds (``mode="filtered"``, the EKF's slip noise), a calibration
#: ``(s, g)`` of ground against encoder speeds with the EKF's scale-error prior (1%) and
#: random walk (1e-4 per sqrt(s)), a Huber kernel on the detections (the EKF gates them; the
#: threshold 1.0 is about 1.345, the usual 95%-efficiency one, times the measured spread of
#: the detections' normalised errors, 0.64-0.85, docs/aruco_end_to_end.md), and
#: relinearisation at 1 mm / 1 mrad at every update (the kernel's weights need it).
SMOOTHER_OPTIONS = SmootherOptions(calibration_prior_sigmas=(0.01, 0.01),
                                   calibration_walk_sigmas=(1e-4, 1e-4), landmark_huber_k=1.0,
                                   relinearize_threshold=1e-3, relinearize_skip=1)
CAMERA_HEIGHT_M = 0.2


def load_ekf_example() -> ModuleType:
    """``examples/ekf_plugin.py`` (route follower, calibration, start pose), loaded by path."""
    name = "ekf_plugin_example"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / "ekf_plugin.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


#: Start of the route (the EKF example's): middle of the square's bottom edge, heading +x.
START_POSE = (2.5, 1.3, 0.0)


def wall_markers(*, per_wall: int = 3, room_m: float = ROOM_M, size_m: float = 0.15,
                 z_m: float = CAMERA_HEIGHT_M, inset_m: float = 0.01) -> MarkerMap:
    """``4 * per_wall`` markers evenly along the four walls, centres at ``z_m``, facing in.

    Ids run counter-clockwise from the south wall (``y = 0``), 0 .. ``4 * per_wall - 1``.
    """
    along = (np.arange(per_wall) + 0.5) * room_m / per_wall
    markers = []
    walls = ((lambda s: (s, inset_m), math.pi / 2),                  # south, faces +y
             (lambda s: (room_m - inset_m, s), math.pi),              # east, faces -x
             (lambda s: (room_m - s, room_m - inset_m), -math.pi / 2),  # north, faces -y
             (lambda s: (inset_m, room_m - s), 0.0))                  # west, faces +x
    for where, yaw in walls:
        for s in along:
            x, y = where(float(s))
            markers.append(MarkerLandmark(len(markers), x, y, z_m=z_m, yaw_rad=yaw))
    return MarkerMap(markers, marker_size_m=size_m, dictionary="DICT_4X4_50")


def make_camera(*, fx_px: float = 500.0, ahead_m: float = 0.1) -> SyntheticCamera:
    """640 x 480 pinhole camera ``ahead_m`` ahead of the robot centre at 20 cm, looking ahead.

    Its detections carry the mount (``RangeBearing.sensor_pose``), which both estimators use.
    """
    return SyntheticCamera(CameraIntrinsics.pinhole(fx_px=fx_px, width_px=640, height_px=480),
                           mount=CameraMount(x_m=ahead_m, z_m=CAMERA_HEIGHT_M))


def camera_frames(n_frames: int, dt_s: float, *, rate_hz: float = CAMERA_RATE_HZ) -> np.ndarray:
    """Frame indices of the images: the frame nearest each ``j / rate_hz`` (from frame 1)."""
    t = np.arange(1, int((n_frames - 1) * dt_s * rate_hz) + 1) / rate_hz
    return np.unique(np.clip(np.rint(t / dt_s).astype(np.int64), 1, n_frames - 1))


@dataclass(frozen=True)
class Detections:
    """Markers detected in the images of one run.

    Attributes
    ----------
    frames : ndarray of int, shape (n_images,)
        Frame index of each image, increasing.
    sightings : RangeBearing
        Known-id detections of all images, ``index`` = the image's frame, each with its
        covariance.
    unknown_ids : tuple of int
        Misread ids (not in the map), dropped.
    seconds_per_image : float
        Rendering plus detection time per image [s].
    """

    frames: np.ndarray
    sightings: RangeBearing
    unknown_ids: tuple[int, ...]
    seconds_per_image: float

    @property
    def per_image(self) -> np.ndarray:
        """Number of detections in each image."""
        index = self.sightings.index
        return (np.searchsorted(index, self.frames, side="right")
                - np.searchsorted(index, self.frames, side="left"))

    def range_bearing_correlation(self) -> np.ndarray:
        """Correlation coefficient of range and bearing in each detection's covariance."""
        if not len(self.sightings):
            return np.zeros(0)
        c = self.sightings.cov
        return c[:, 0, 1] / np.sqrt(c[:, 0, 0] * c[:, 1, 1])


def detect_along(true_pose: np.ndarray, frames: np.ndarray, marker_map: MarkerMap,
                 camera: SyntheticCamera, rng: np.random.Generator) -> Detections:
    """Render an image at each frame's *true* pose (the world) and detect its markers."""
    detector = MarkerDetector.for_map(camera.intrinsics, marker_map, mount=camera.mount)
    parts, unknown = [], {}
    t0 = time.perf_counter()
    for k in frames:
        found = detector.detect(camera.render(marker_map, true_pose[k], rng), index=int(k))
        known, bad = marker_map.split_known(found)
        parts.append(known)
        unknown.update(dict.fromkeys(bad))
    elapsed = time.perf_counter() - t0
    return Detections(np.asarray(frames, np.int64), RangeBearing.concatenate(parts),
                      tuple(unknown), elapsed / max(1, len(frames)))


def diagonal(sightings: RangeBearing) -> RangeBearing:
    """The sightings with their covariances' diagonals only (range-bearing correlation dropped)."""
    if sightings.cov is None:
        return sightings
    return replace(sightings, cov=sightings.cov * np.eye(2))


@dataclass(frozen=True)
class EkfRun:
    poses: np.ndarray           # (n, 3), every frame
    fused: int
    gated: int
    diverged: int = 0           # resets of the filter's divergence watch (docs/ekf.md)


def run_ekf(model: MotionModel, log: FrameLog, detections: Detections, marker_map: MarkerMap,
            *, initial_pose: Sequence[float] = START_POSE,
            pose_std: tuple[float, float, float] = (0.005, 0.005, 0.005),
            full_covariance: bool = True) -> EkfRun:
    """:class:`ModelEKF` over one robot's frames and its detections (no truth read).

    ``full_covariance``: fuse each detection with its full covariance (range-bearing
    correlation kept; the default), else with its diagonal.
    """
    ekf = ModelEKF(model, initial_pose=initial_pose, pose_std=pose_std,
                   initial_ticks=log.ticks[0], landmarks=marker_map.to_landmark_map(),
                   options=EKFOptions(history=0))
    n = len(log.t_s)
    poses = np.empty((n, 3))
    poses[0] = ekf.x[:3]
    sightings = detections.sightings
    at = (sightings if full_covariance else diagonal(sightings)).by_index()
    none = RangeBearing.empty()
    cmd, ticks = log.cmd_m_s, log.ticks
    for k in range(1, n):
        ekf.predict(cmd[k])
        ekf.update_encoders(ticks[k])
        ekf.update_landmarks(at.get(k, none))
        poses[k] = ekf.x[:3]
    return EkfRun(poses, ekf.stats.count("landmark", "fused"),
                  ekf.stats.count("landmark", "gated"),
                  sum(r.cause == "diverged" for r in ekf.resets))


@dataclass(frozen=True)
class SmootherRun:
    keyframes: np.ndarray       # frame indices
    poses: np.ndarray           # (n_keyframes, 3)


def run_smoother(model: MotionModel, log: FrameLog, detections: Detections,
                 marker_map: MarkerMap, *, initial_pose: Sequence[float] = START_POSE,
                 keyframe_every: int = KEYFRAME_EVERY, mode: str = "filtered",
                 options: SmootherOptions = SMOOTHER_OPTIONS, full_covariance: bool = True
                 ) -> SmootherRun:
    """iSAM2 over keyframes (every image, plus every ``keyframe_every`` frames).

    Each detection is a range-bearing factor with its full covariance (with
    ``full_covariance=False`` its diagonal, :func:`diagonal`).
    """
    u, y = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    kf = log_keyframes(len(u), every=keyframe_every, extra=detections.frames)
    pre = preintegrate_model(model, u, keyframes=kf, mode=mode, measured_speeds=y)
    landmarks = marker_map.to_landmark_map()
    sightings = detections.sightings if full_covariance else diagonal(detections.sightings)
    at = sightings.with_index(np.searchsorted(kf, sightings.index)).by_index()
    sm = IncrementalSmoother(initial_pose=np.asarray(initial_pose, float), landmarks=landmarks,
                             options=options)
    for k in range(len(kf)):
        if k > 0:
            sm.add_motion(pre[k - 1])
        if k in at:
            sm.add_observations(at[k])
        sm.update()
    return SmootherRun(kf, sm.result(covariances=False).poses)


def _rms(truth_xy: np.ndarray, est_xy: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((truth_xy - est_xy) ** 2, axis=1))))


@dataclass(frozen=True)
class EndToEndRun:
    """One robot's run: log, detections, both estimates and their errors [m]."""

    log: FrameLog
    detections: Detections
    ekf: EkfRun
    smoother: SmootherRun
    ekf_rms_m: float                # over every frame
    ekf_rms_keyframes_m: float      # over the smoother's keyframes
    smoother_rms_m: float           # over the smoother's keyframes
    seconds: dict[str, float]


def run_end_to_end(model: MotionModel, *, n_runs: int, duration_s: float, seed: int,
                   marker_map: MarkerMap | None = None, camera: SyntheticCamera | None = None
                   ) -> list[EndToEndRun]:
    """Drive ``n_runs`` robots (one batch simulator, seed ``seed``), then per run render,
    detect (image noise seed ``1000 * seed + run``) and estimate."""
    ex = load_ekf_example()
    marker_map = wall_markers() if marker_map is None else marker_map
    camera = make_camera() if camera is None else camera
    t0 = time.perf_counter()
    sim = Simulator("create2", n_robots=n_runs, seed=seed, room=Room.box(ROOM_M, ROOM_M),
                    initial_pose=START_POSE)
    logs = ex.drive_route(sim, duration_s=duration_s, rng=np.random.default_rng(seed + 1))
    t_drive = (time.perf_counter() - t0) / n_runs
    if logs.bumps.any():
        raise RuntimeError("a robot bumped into a wall; the route must stay clear")
    runs = []
    for r in range(n_runs):
        log = logs.robot(r)
        frames = camera_frames(len(log.t_s), log.dt_s)
        det = detect_along(log.true_pose, frames, marker_map, camera,
                           np.random.default_rng(1000 * seed + r))
        t1 = time.perf_counter()
        ekf = run_ekf(model, log, det, marker_map)
        t2 = time.perf_counter()
        smo = run_smoother(model, log, det, marker_map)
        t3 = time.perf_counter()
        truth = log.true_pose
        runs.append(EndToEndRun(
            log, det, ekf, smo,
            ekf_rms_m=_rms(truth[:, :2], ekf.poses[:, :2]),
            ekf_rms_keyframes_m=_rms(truth[smo.keyframes, :2], ekf.poses[smo.keyframes, :2]),
            smoother_rms_m=_rms(truth[smo.keyframes, :2], smo.poses[:, :2]),
            seconds={"drive": t_drive, "images": det.seconds_per_image * len(frames),
                     "ekf": t2 - t1, "smoother": t3 - t2}))
    return runs


def plot_run(path: Path, run: EndToEndRun, marker_map: MarkerMap) -> Path:
    """Paths of truth, EKF and smoother, and their position errors, as a PNG."""
    truth, dt = run.log.true_pose, run.log.dt_s
    kf = run.smoother.keyframes
    fig = Figure(figsize=(12, 5.5))     # no pyplot: no GUI backend, no global state
    ax, ax_err = fig.subplots(1, 2)
    ax.plot(truth[:, 0], truth[:, 1], "k-", lw=1.0, label="truth")
    ax.plot(run.ekf.poses[:, 0], run.ekf.poses[:, 1], "C0-", lw=0.7, label="EKF")
    ax.plot(run.smoother.poses[:, 0], run.smoother.poses[:, 1], "C1-", lw=0.7, label="smoother")
    xy = np.array([m.position_xy_m for m in marker_map.markers])
    ax.plot(xy[:, 0], xy[:, 1], "ks", ms=5, label="ArUco markers")
    ax.plot([0, ROOM_M, ROOM_M, 0, 0], [0, 0, ROOM_M, ROOM_M, 0], "0.6", lw=1.0)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="paths")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=4, fontsize=8)
    ax_err.plot(np.arange(len(truth)) * dt, np.hypot(*(run.ekf.poses[:, :2] - truth[:, :2]).T),
                "C0-", lw=0.6, label=f"EKF (RMS {100 * run.ekf_rms_m:.1f} cm)")
    ax_err.plot(kf * dt, np.hypot(*(run.smoother.poses[:, :2] - truth[kf, :2]).T), "C1-",
                lw=0.6, label=f"smoother (RMS {100 * run.smoother_rms_m:.1f} cm)")
    ax_err.set(xlabel="time [s]", ylabel="position error [m]", title="position error")
    ax_err.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/aruco_end_to_end"))
    parser.add_argument("--duration-s", type=float, default=300.0)
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--short", action="store_true",
                        help="smoke test: 60 s of calibration excitation and a 30 s drive")
    args = parser.parse_args(argv)
    ex = load_ekf_example()
    model = ex.calibrate_model(excitation_s=60.0 if args.short else 180.0)
    duration = 30.0 if args.short else args.duration_s
    marker_map = wall_markers()
    runs = run_end_to_end(model, n_runs=args.runs, duration_s=duration, seed=args.seed,
                          marker_map=marker_map)
    for r, run in enumerate(runs):
        per = run.detections.per_image
        rho = run.detections.range_bearing_correlation()
        print(f"run {r} (seed {args.seed}): {duration:.0f} s, {len(per)} images, "
              f"{per.mean():.2f} detections per image ({np.mean(per == 0):.0%} with none), "
              f"misread ids {list(run.detections.unknown_ids)}, |range-bearing correlation| "
              f"median {np.median(np.abs(rho)) if rho.size else float('nan'):.2f}")
        print(f"  position RMS: EKF {1000 * run.ekf_rms_m:.3f} mm (all frames), "
              f"{1000 * run.ekf_rms_keyframes_m:.3f} mm (keyframes); smoother "
              f"{1000 * run.smoother_rms_m:.3f} mm (keyframes); EKF fused "
              f"{run.ekf.fused}, gated {run.ekf.gated}")
        print("  seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in run.seconds.items())
              + f" ({1000 * run.detections.seconds_per_image:.1f} ms per image)")
    png = plot_run(args.out / "aruco_end_to_end.png", runs[0], marker_map)
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
