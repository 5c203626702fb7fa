"""Benchmark ``sensorpose``: the landmark camera ahead of the axle, against a centred one.

Issue 16, item 6: the EKF with ArUco landmarks, its camera 0.15 m ahead of the axle, within
10% of the centred camera's closure error. The ArUco simulation of
``examples/aruco_end_to_end.py``: one ARX calibration (``examples/ekf_plugin.py``'s), then
``N_RUNS`` simulated Create 2 robots (simulator seed ``SEED``) drive the rounded square for
``DURATION_S`` in the 5 m x 5 m room with twelve wall markers; at 5 Hz an image is rendered
from each robot's *true* pose by a camera 0.2 m up, either at the axle (``x_m = 0``) or
0.15 m ahead, and detected (image noise seeded ``1000 * SEED + run``, the same for both
cameras). The drives are the same for both cameras (the follower steers on the truth). The
EKF (:class:`fusion.ekf.ModelEKF`, full 2 x 2 covariance per detection) fuses the
commands, the encoder counts and the detections, which carry the camera's mount, and never
reads the truth.

Figures (mean over the runs; each run's closure error is its EKF's position error at the
end of the drive, the RMS over every frame):

- ``sensorpose.closure_ahead_mm``: camera 0.15 m ahead; target 1.10 x the baseline, the
  centred camera's closure error in the same process (``ratio`` is the target's ratio).
- ``sensorpose.rms_ahead_mm``: the same runs' position RMS, same target on the centred RMS.
- ``sensorpose.closure_ignored_mm``: the 0.15 m camera's detections taken as from the axle
  centre (the mount dropped), against the same baseline; no target.
- ``sensorpose.gated_ignored_pct``: the share of those detections the EKF gates; no target.

The spread (standard deviation over the runs) is printed to stderr for the record in
``docs/benchmarks.md``.
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

from benchmarks.harness import Figure, benchmark, load_example
from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from fusion.sensor_pose import CENTRED

__all__ = ["AHEAD_M", "DURATION_S", "N_RUNS", "SEED", "bench_sensorpose", "mount_runs"]

N_RUNS, DURATION_S, SEED = 16, 30.0, 5
AHEAD_M = 0.15


def mount_runs(*, n_runs: int = N_RUNS, duration_s: float = DURATION_S, seed: int = SEED
               ) -> dict[str, np.ndarray]:
    """Per-run EKF closure error and RMS [m] and gated share, per camera variant.

    Keys ``"{variant}_{figure}"``, variants ``centred``, ``ahead`` and ``ignored`` (the
    ``ahead`` detections with their mount dropped), figures ``closure``, ``rms``, ``gated``.
    """
    ex = load_example("aruco_end_to_end")
    model = ex.load_ekf_example().calibrate_model()
    sim = Simulator("create2", n_robots=n_runs, seed=seed, room=Room.box(ex.ROOM_M, ex.ROOM_M),
                    initial_pose=ex.START_POSE)
    logs = ex.load_ekf_example().drive_route(sim, duration_s=duration_s,
                                              rng=np.random.default_rng(seed + 1))
    if logs.bumps.any():
        raise RuntimeError("a robot bumped into a wall; the route must stay clear")
    marker_map = ex.wall_markers()
    out: dict[str, list[float]] = {}
    for ahead_m in (0.0, AHEAD_M):
        camera = ex.make_camera(ahead_m=ahead_m)
        for r in range(n_runs):
            log = logs.robot(r)
            frames = ex.camera_frames(len(log.t_s), log.dt_s)
            det = ex.detect_along(log.true_pose, frames, marker_map, camera,
                                  np.random.default_rng(1000 * seed + r))
            variants = {"ahead": det} if ahead_m else {"centred": det}
            if ahead_m:
                variants["ignored"] = replace(det, sightings=replace(det.sightings,
                                                                     sensor_pose=CENTRED))
            for name, d in variants.items():
                run = ex.run_ekf(model, log, d, marker_map)
                err = np.hypot(*(run.poses[:, :2] - log.true_pose[:, :2]).T)
                out.setdefault(f"{name}_closure", []).append(float(err[-1]))
                out.setdefault(f"{name}_rms", []).append(float(np.sqrt(np.mean(err ** 2))))
                out.setdefault(f"{name}_gated", []).append(run.gated / max(1, len(d.sightings)))
    return {k: np.array(v) for k, v in out.items()}


@benchmark("sensorpose")
def bench_sensorpose() -> list[Figure]:
    """Closure error and RMS of the EKF, camera 0.15 m ahead against centred."""
    res = mount_runs()
    for key, v in sorted(res.items()):
        scale = 100.0 if key.endswith("gated") else 1000.0
        print(f"sensorpose {key}: mean {scale * v.mean():.4g}, sd {scale * v.std(ddof=1):.3g} "
              f"({'%' if scale == 100.0 else 'mm'}, {len(v)} runs, seed {SEED})",
              file=sys.stderr)
    centred_closure = 1000.0 * float(res["centred_closure"].mean())
    centred_rms = 1000.0 * float(res["centred_rms"].mean())
    return [
        Figure(name="sensorpose.closure_ahead_mm",
               value=1000.0 * float(res["ahead_closure"].mean()), unit="mm",
               target=1.10 * centred_closure, better="lower",
               baseline="centred camera's closure error", baseline_value=centred_closure),
        Figure(name="sensorpose.rms_ahead_mm", value=1000.0 * float(res["ahead_rms"].mean()),
               unit="mm", target=1.10 * centred_rms, better="lower",
               baseline="centred camera's position RMS", baseline_value=centred_rms),
        Figure(name="sensorpose.closure_ignored_mm",
               value=1000.0 * float(res["ignored_closure"].mean()), unit="mm", better="lower",
               baseline="centred camera's closure error", baseline_value=centred_closure),
        Figure(name="sensorpose.gated_ignored_pct",
               value=100.0 * float(res["ignored_gated"].mean()), unit="%", better="lower"),
    ]
