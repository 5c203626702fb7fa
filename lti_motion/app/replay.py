"""``lti-motion replay``: the estimators on a recorded log or a data set robot.

A *source* is what a robot reported, frame by frame: the wheel commands of
each sensor period, the raw encoder counts (logs only), landmark sightings
where there are any, and ground truth where it exists (the simulator's pose
in a simulated log, Vicon in MRCLAM). Two kinds are read:

- an ``lti-motion-log`` NPZ file (:mod:`lti_motion.recordings.logfile`, ``docs/log_format.md``),
  written by :class:`drivers.logs.Recorder`, ``lti-motion monitor --record`` or
  ``lti-motion calibrate``; landmark sightings, if any, in its ``meta``
  (``"landmarks"``: ``[[id, x, y], ...]``, ``"observations"``:
  ``[[frame, id, range, bearing], ...]``);
- an MRCLAM data set folder (:func:`drivers.datasets.load_mrclam`), one robot,
  put on the model's sample grid (commands held, ground truth interpolated and
  blanked across Vicon gaps longer than 0.25 s).

Estimators (:data:`ESTIMATORS`) read the commands, counts and sightings only.
They start at ``initial_pose``: by default the first ground-truth pose when
there is one (the only thing of the truth they see), else the origin. Metrics
(:mod:`lti_motion.metrics`) compare them with the truth afterwards.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from fusion.ekf import EKFOptions, ModelEKF
from fusion.noise import GyroNoise
from fusion.range_bearing import RangeBearing
from lti_motion.app.replay_sources import (
    ESTIMATORS,
    MRCLAM_LANDMARK_NOISE,
    ReplaySource,
    fit_mrclam_model,
    load_source,
    source_from_log,
    source_from_mrclam,
)
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import body_from_wheel, integrate_poses, wheel_from_body
from lti_motion.metrics import ate_stats, rpe
from lti_motion.model import MotionModel
from lti_motion.persistence import atomic_write
from lti_motion.recordings import tick_deltas, write_tum

__all__ = [
    "ESTIMATORS",
    "MRCLAM_LANDMARK_NOISE",
    "OUTPUT_NAMES",
    "ReplayResult",
    "ReplaySource",
    "estimate",
    "evaluate",
    "fit_mrclam_model",
    "gyro_noise",
    "load_source",
    "run_replay",
    "source_from_log",
    "source_from_mrclam",
    "twist_counts",
    "write_outputs",
]


# -- estimators -----------------------------------------------------------------------------
def _expand(src: ReplaySource) -> tuple[np.ndarray, np.ndarray]:
    """Commands of every sensor period (n_periods, 2), and the period index of each frame."""
    u = np.repeat(src.cmd_m_s[1:], src.periods[1:], axis=0)
    return u, np.cumsum(src.periods)


def _odometry(src: ReplaySource, model: MotionModel, pose0: np.ndarray) -> np.ndarray:
    if src.ticks is None:                    # the robot's own odometry twist, integrated
        speeds = np.repeat(src.body_speeds[1:], src.periods[1:], axis=0)
        return integrate_poses(speeds, src.dt_s, initial_pose=pose0)[np.cumsum(src.periods)]
    k = model.encoder_intrinsics             # each wheel's scale, else the one m_per_tick
    if k is None:
        raise MissingEncoderScaleError.needed_by("encoder odometry")
    rows = np.flatnonzero(src.valid)
    d = k.wheel_travel_m(tick_deltas(src.ticks[rows], axis=0,        # wheel travel [m]
                                     counter_bits=src.counter_bits))
    # displacement and turn over each interval, integrated with unit steps (paper eq. 11)
    moves = body_from_wheel(d, wheel_base_m=k.wheel_base_m)
    at_valid = integrate_poses(moves, 1.0, initial_pose=pose0)
    # frames whose readings were lost keep the last pose
    return at_valid[np.maximum(np.searchsorted(rows, np.arange(len(src)), side="right") - 1, 0)]


def _commands(src: ReplaySource, model: MotionModel, pose0: np.ndarray) -> np.ndarray:
    u, at = _expand(src)
    speeds = body_from_wheel(u, wheel_base_m=model.wheel_base_m)
    return integrate_poses(speeds, src.dt_s, initial_pose=pose0)[at]


def _sensorless(src: ReplaySource, model: MotionModel, pose0: np.ndarray) -> np.ndarray:
    u, at = _expand(src)
    return model.predict_poses(u, initial_pose=pose0)[at]


def twist_counts(src: ReplaySource, intrinsics: OdometryIntrinsics) -> np.ndarray:
    """The counts an encoder of ``intrinsics`` would have read under a source's odometry
    twist, shape (n, 2), int64, never wrapping.

    The twist's body travel over each period (``body_speeds`` times the periods times
    ``dt_s``), turned into wheel travel through ``intrinsics.wheel_base_m`` and summed, is
    rounded to whole ticks of each wheel's scale: the cumulative travel to half a tick,
    the resolution the EKF's encoder noise assumes (``docs/ekf.md``). Fused as counts, a
    reading the gate rejects keeps its motion (the next counts span it), which a per-period
    speed update loses.
    """
    body = src.body_speeds * (src.periods * src.dt_s)[:, None]
    body[0] = 0.0                                   # frame 0 closes no period
    wheel = np.cumsum(wheel_from_body(body, wheel_base_m=intrinsics.wheel_base_m), axis=0)
    scale = np.array([intrinsics.m_per_tick_left, intrinsics.m_per_tick_right])
    return np.rint(wheel / scale).astype(np.int64)


def _ekf(src: ReplaySource, model: MotionModel, pose0: np.ndarray, *,
         landmarks: bool) -> tuple[np.ndarray, dict, np.ndarray, np.ndarray]:
    """The model EKF over the source: poses (n, 3), counts, pose covariances (n, 3, 3) and
    the filter's body speeds of each frame's last period (n, 2; zeros at the first)."""
    ticks, bits, twist = src.ticks, src.counter_bits, None
    if ticks is None and src.body_speeds is not None:   # the robot's own odometry twist
        if model.encoder_intrinsics is not None:        # as the counts it stands for
            ticks, bits = twist_counts(src, model.encoder_intrinsics), 64
        else:                                           # as speeds, one period at a time
            twist = src.body_speeds
    encoders = ticks is not None
    first = int(np.argmax(src.valid)) if encoders else 0
    gyro = src.yaw_rate_rad_s           # a gyro's readings: fused (fusion.ekf.gyro)
    ekf = ModelEKF(model, initial_pose=pose0, pose_std=(0.005, 0.005, 0.005),
                   initial_ticks=ticks[first] if encoders else None,
                   landmarks=src.landmarks if landmarks else None,
                   options=EKFOptions(landmark_noise=src.landmark_noise, history=0,
                                      counter_bits=bits,
                                      gyro=None if gyro is None else gyro_noise(src)))
    poses = np.empty((len(src), 3))
    covs = np.empty((len(src), 3, 3))
    speeds = np.zeros((len(src), 2))
    poses[0], covs[0] = ekf.pose, ekf.P[:3, :3]
    sightings = src.sightings.by_index() if landmarks else {}
    none = RangeBearing.empty()
    for k in range(1, len(src)):
        for _ in range(int(src.periods[k])):
            ekf.predict(src.cmd_m_s[k])
        if encoders and src.valid[k] and k > first:
            ekf.update_encoders(ticks[k])
        elif twist is not None and src.valid[k] and src.periods[k] == 1:
            ekf.update_speeds(twist[k])           # NaN: skipped by the filter
        if gyro is not None:
            ekf.update_gyro(gyro[k])    # NaN (a lost frame) starts a new window
        ekf.update_landmarks(sightings.get(k, none))
        poses[k], covs[k], speeds[k] = ekf.x[:3], ekf.P[:3, :3], ekf.speeds
    stats = ekf.stats
    causes = [r.cause for r in ekf.resets]
    counts = {"encoders_gated": stats.count("encoders", "gated"),
              "landmarks_fused": stats.count("landmark", "fused"),
              "landmarks_gated": stats.count("landmark", "gated"),
              "filter_resets": ekf.n_resets,
              "resets_scale_implausible": causes.count("scale_implausible"),
              "resets_diverged": causes.count("diverged")}
    if gyro is not None:
        counts.update(gyro_windows_fused=stats.count("gyro", "fused"),
                      gyro_windows_gated=stats.count("gyro", "gated"))
    return poses, counts, covs, speeds


def estimate(src: ReplaySource, model: MotionModel, names: Sequence[str], *,
             initial_pose: Sequence[float] | None = None
             ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Run the estimators ``names`` over a source.

    Parameters
    ----------
    src : ReplaySource
    model : MotionModel
        The calibrated model (its ``m_per_tick`` scales the encoders).
    names : sequence of str
        Keys of :data:`ESTIMATORS`, each in ``src.available()``.
    initial_pose : sequence of 3 float, optional
        Start pose (x [m], y [m], theta [rad]); default the first ground-truth
        pose if the first frame has one, else the origin.

    Returns
    -------
    poses : dict of str to ndarray, shape (n, 3)
        Each estimator's pose at every frame.
    extra : dict of str to dict
        Filter counts (gated readings, landmarks fused, the filter's resets by
        cause: ``filter_resets``, ``resets_scale_implausible``,
        ``resets_diverged``; with a gyro in the source, its windows
        ``gyro_windows_fused`` and ``gyro_windows_gated``) per EKF estimator.

    Raises
    ------
    ValueError
        For an unknown estimator or one the source cannot feed.
    """
    poses, extra, _, _ = _estimate(src, model, names, initial_pose=initial_pose)
    return poses, extra


def _estimate(src: ReplaySource, model: MotionModel, names: Sequence[str], *,
              initial_pose: Sequence[float] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, dict], dict[str, np.ndarray],
                         dict[str, np.ndarray]]:
    """:func:`estimate`, and each EKF estimator's pose covariances (n, 3, 3) and body speeds
    (n, 2)."""
    if not math.isclose(model.dt_s, src.dt_s, rel_tol=1e-6):
        raise ValueError(f"the model was calibrated at {model.dt_s:g} s but {src.name} has a "
                         f"{src.dt_s:g} s sensor period; use a model of this robot")
    for name in names:
        if name not in ESTIMATORS:
            raise ValueError(f"unknown estimator {name!r}; known: {', '.join(ESTIMATORS)}")
        if name not in src.available():
            why = ("encoder counts or an odometry twist" if name in ("odometry", "ekf")
                   else "landmark sightings")
            raise ValueError(f"estimator {name!r} needs {why}, which {src.name} does not have; "
                             f"available: {', '.join(src.available())}")
    if initial_pose is not None:
        pose0 = np.asarray(initial_pose, float)
    elif src.truth is not None and np.all(np.isfinite(src.truth[0])):
        pose0 = src.truth[0].copy()
    else:
        pose0 = np.zeros(3)
    out: dict[str, np.ndarray] = {}
    extra: dict[str, dict] = {}
    covs: dict[str, np.ndarray] = {}
    speeds: dict[str, np.ndarray] = {}
    for name in names:
        if name == "odometry":
            out[name] = _odometry(src, model, pose0)
        elif name == "commands":
            out[name] = _commands(src, model, pose0)
        elif name == "sensorless":
            out[name] = _sensorless(src, model, pose0)
        else:
            out[name], extra[name], covs[name], speeds[name] = _ekf(
                src, model, pose0, landmarks=name == "ekf_landmarks")
    return out, extra, covs, speeds


# -- metrics --------------------------------------------------------------------------------
def _runs(mask: np.ndarray) -> list[slice]:
    """Contiguous stretches of ``True``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def evaluate(src: ReplaySource, poses: np.ndarray, *, rpe_s: float = 1.0) -> dict[str, float]:
    """Figures of one estimate: path length, and ATE / RPE where there is ground truth.

    Parameters
    ----------
    src : ReplaySource
    poses : ndarray, shape (n, 3)
        The estimate at every frame.
    rpe_s : float
        RPE step [s] (rounded to whole frames).

    Returns
    -------
    dict
        ``path_m`` and ``closure_m`` (distance from the first to the last
        estimated position) always; with truth also ``ate_rmse_m``,
        ``ate_max_m`` (Sturm et al. 2012, eq. 5, no alignment: both start at
        the same pose), ``rpe_m``, ``rpe_deg`` (eq. 1-2, over ``rpe_s``,
        within stretches of truth only), ``final_error_m`` (at the last frame
        with truth) and ``n_truth``.
    """
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    out = {"path_m": float(steps.sum()),
           "closure_m": float(np.hypot(*(poses[-1, :2] - poses[0, :2])))}
    if not src.has_truth:
        return out
    ok = np.all(np.isfinite(src.truth), axis=1)
    err = ate_stats(src.truth[ok], poses[ok])
    frame_s = float(np.median(np.diff(src.t_s)))
    delta = max(1, round(rpe_s / frame_s))
    sq_t = sq_r = n = 0.0
    for run in _runs(ok):
        if run.stop - run.start > delta:
            r = rpe(src.truth[run], poses[run], delta=delta)
            sq_t += r.trans_rmse_m ** 2 * r.n_pairs
            sq_r += r.rot_rmse_rad ** 2 * r.n_pairs
            n += r.n_pairs
    last = int(np.flatnonzero(ok)[-1])
    out.update(ate_rmse_m=float(err.rmse_m), ate_max_m=float(err.max_m),
               rpe_m=math.sqrt(sq_t / n) if n else math.nan,
               rpe_deg=math.degrees(math.sqrt(sq_r / n)) if n else math.nan,
               final_error_m=float(np.hypot(*(poses[last, :2] - src.truth[last, :2]))),
               n_truth=int(ok.sum()))
    return out


# -- the command ----------------------------------------------------------------------------
@dataclass(frozen=True)
class ReplayResult:
    """What :func:`run_replay` computed and wrote.

    Attributes
    ----------
    source : ReplaySource
    poses : dict of str to ndarray, shape (n, 3)
    metrics : dict of str to dict
        :func:`evaluate` per estimator, plus the filter counts.
    files : list of Path
        TUM trajectories, ``metrics.json`` and plots, in the order written.
    pose_covs : dict of str to ndarray, shape (n, 3, 3)
        Each EKF estimator's pose covariance at every frame [m^2, m rad, rad^2].
    speeds : dict of str to ndarray, shape (n, 2)
        Each EKF estimator's body speeds ``(v [m/s], w [rad/s])`` at every frame.
    """

    source: ReplaySource
    poses: dict[str, np.ndarray]
    metrics: dict[str, dict]
    files: list[Path]
    pose_covs: dict[str, np.ndarray] = field(default_factory=dict)
    speeds: dict[str, np.ndarray] = field(default_factory=dict)


def _table(src: ReplaySource, metrics: dict[str, dict]) -> list[str]:
    if src.has_truth:
        head = ("estimator", "ATE rmse [m]", "ATE max [m]", "RPE [m]", "RPE [deg]",
                "final err [m]", "path [m]")
        keys = ("ate_rmse_m", "ate_max_m", "rpe_m", "rpe_deg", "final_error_m", "path_m")
    else:
        head = ("estimator", "path [m]", "start-to-end [m]")
        keys = ("path_m", "closure_m")
    rows = [[src.label(name)] + [f"{m[k]:.3f}" for k in keys] for name, m in metrics.items()]
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    fmt = "  ".join(f"{{:<{w}}}" if i == 0 else f"{{:>{w}}}" for i, w in enumerate(widths))
    return [fmt.format(*head), fmt.format(*("-" * w for w in widths))] + [
        fmt.format(*r) for r in rows]


def gyro_noise(src: ReplaySource) -> GyroNoise:
    """The EKF's gyro noise: the density the recording states (a bag Imu's covariance),
    else :class:`~fusion.noise.GyroNoise`'s default."""
    density = src.gyro_density_rad_s_sqrt_hz
    return GyroNoise() if density is None else GyroNoise(noise_density_rad_s_sqrt_hz=density)


def run_replay(source_path: str | os.PathLike | ReplaySource, model: MotionModel,
               out_dir: str | os.PathLike,
               *, estimators: Sequence[str] | None = None, robot: int | None = None,
               start_s: float = 0.0, duration_s: float | None = None,
               initial_pose: Sequence[float] | None = None, rpe_s: float = 1.0,
               gyro: bool = False, print_fn: Callable[[str], object] = print) -> ReplayResult:
    """Replay a log or data set robot: estimate, print the table, write TUM files and plots.

    Writes ``OUT/<estimator>.tum`` per estimator, ``OUT/groundtruth.tum``
    (frames with truth only) when there is truth, ``OUT/metrics.json``,
    ``OUT/trajectories.png`` and, with truth, ``OUT/errors.png``.

    Parameters
    ----------
    source_path : str, path-like or ReplaySource
        An ``.npz`` log or an MRCLAM folder (:func:`load_source`), or a source
        already read (a ROS bag's, :mod:`lti_motion.app.bag_commands`).
    model : MotionModel
        The calibrated model.
    out_dir : str or path-like
        Output folder (created).
    estimators : sequence of str, optional
        Default: every estimator the source can feed.
    robot, start_s, duration_s
        As for :func:`load_source`.
    initial_pose, rpe_s
        As for :func:`estimate` and :func:`evaluate`.
    gyro : bool
        Fuse the source's gyro readings in the EKFs (``--gyro``); without it they are
        left out, and a line says the recording has them (opt-in: on a hard floor with
        the default scale priors a gyro can cost accuracy, ``docs/ekf.md``).
    print_fn : callable
        Where the lines a person reads go.
    """
    from lti_motion.app.replay_plots import plot_errors, plot_trajectories

    src = (source_path if isinstance(source_path, ReplaySource) else
           load_source(source_path, model, robot=robot, start_s=start_s, duration_s=duration_s))
    if src.yaw_rate_rad_s is not None and not gyro:
        print_fn("the recording has gyro readings; --gyro fuses them")
        src = replace(src, yaw_rate_rad_s=None)
    names = list(estimators) if estimators else src.available()
    n_sight = len(src.sightings)
    print_fn(f"replaying {src.name}: {len(src)} frames, {src.t_s[-1] - src.t_s[0]:.1f} s, "
             f"{src.wheel_readings or 'no encoders'}, "
             f"{n_sight} landmark sightings, "
             f"{('reference: ' + src.truth_label) if src.has_truth else 'no reference poses'}")
    if src.yaw_rate_rad_s is not None:
        noise = gyro_noise(src).noise_density_rad_s_sqrt_hz
        print_fn(f"gyro noise density {noise:.3g} rad/s/sqrt(Hz), "
                 + ("the recording's" if src.gyro_density_rad_s_sqrt_hz is not None
                    else "the default (the recording states none)"))
    started = (f"the first pose of {src.truth_label}" if initial_pose is None
               and src.has_truth and np.all(np.isfinite(src.truth[0])) else "the given pose"
               if initial_pose is not None else "the origin")
    print_fn(f"estimators start at {started}; they never read the reference after that")
    poses, extra, covs, speeds = _estimate(src, model, names, initial_pose=initial_pose)
    metrics = {name: {**evaluate(src, p, rpe_s=rpe_s), **extra.get(name, {})}
               for name, p in poses.items()}
    for line in _table(src, metrics):
        print_fn("  " + line)
    if src.has_truth:
        print_fn(f"  (ATE and RPE against {src.truth_label}, without alignment; RPE over "
                 f"{rpe_s:g} s; Sturm et al. 2012)")
    else:
        print_fn("  no reference poses in this recording: no ATE or RPE. Start-to-end distance "
                 "is the closure offset if the drive ended where it began")
    for name, counts in extra.items():
        enc = (f"{counts['encoders_gated']} {'encoder' if src.ticks is not None else 'twist'}"
               f" readings gated, " if src.wheel_readings else "")
        gyro = (f"; gyro: {counts['gyro_windows_fused']} windows fused, "
                f"{counts['gyro_windows_gated']} gated" if "gyro_windows_fused" in counts
                else "")
        print_fn(f"  {src.label(name)}: {enc}{counts['landmarks_fused']} sightings fused, "
                 f"{counts['landmarks_gated']} gated{gyro}")
        if counts["filter_resets"]:
            print_fn(f"  {src.label(name)}: the filter reset itself {counts['filter_resets']} "
                     f"times ({counts['resets_scale_implausible']} implausible scale errors, "
                     f"{counts['resets_diverged']} divergences: landmarks gated in a row); "
                     f"see docs/ekf.md, Bounds and resets")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"source": src.name, "frames": len(src), "dt_s": src.dt_s,
           "has_truth": src.has_truth, "metrics": metrics}
    writers: dict[str, Callable[[Path], object]] = {
        f"{name}.tum": (lambda path, p=p: write_tum(path, src.t_s, p))
        for name, p in poses.items()}
    if src.has_truth:
        ok = np.all(np.isfinite(src.truth), axis=1)
        writers["groundtruth.tum"] = lambda path: write_tum(path, src.t_s[ok], src.truth[ok])
    writers["metrics.json"] = lambda path: _write_text(path, json.dumps(_plain(doc), indent=2)
                                                       + "\n")
    writers["trajectories.png"] = lambda path: plot_trajectories(path, src, poses)
    if src.has_truth:
        writers["errors.png"] = lambda path: plot_errors(path, src, poses)
    files = write_outputs(out, writers)
    print_fn(f"wrote {len(files)} files to {out}/: " + ", ".join(f.name for f in files))
    if files and src.has_truth:
        print_fn(f"compare with evo: evo_ape tum {out / 'groundtruth.tum'} "
                 f"{out / names[-1]}.tum --plot")
    return ReplayResult(source=src, poses=poses, metrics=metrics, files=files, pose_covs=covs,
                        speeds=speeds)


#: Every file name ``replay`` writes into its output folder: a previous run's are removed
#: before a run writes its own, so the folder holds only this run's (``docs/replay.md``).
OUTPUT_NAMES = (*(f"{name}.tum" for name in ESTIMATORS), "groundtruth.tum", "metrics.json",
                "trajectories.png", "errors.png")


def write_outputs(out: Path, writers: Mapping[str, Callable[[Path], object]]) -> list[Path]:
    """Write one run's files into ``out``: all of them, or none and the folder cleared.

    First every file of :data:`OUTPUT_NAMES` a previous run left is removed (another
    source's ``ekf_landmarks.tum`` would otherwise sit beside this run's files and be read
    by ``evo_traj tum out/*.tum``); then each writer writes its file, atomically
    (:func:`~lti_motion.persistence.atomic_write`). If one fails (a full disk, Ctrl-C),
    the files written so far are removed too: a run leaves all its files or none, and
    never a truncated one.

    Parameters
    ----------
    out : Path
        The output folder (exists).
    writers : mapping of str to callable
        File name (one of :data:`OUTPUT_NAMES`) -> a function writing that file,
        atomically, given its path.

    Returns
    -------
    list of Path
        The files written, in the writers' order.

    Raises
    ------
    OSError
        Naming the file that could not be written, and why.
    """
    for name in OUTPUT_NAMES:
        (out / name).unlink(missing_ok=True)
    written: list[Path] = []
    try:
        for name, write in writers.items():
            path = out / name
            try:
                write(path)
            except OSError as exc:
                raise OSError(f"could not write {path}: {exc.strerror or exc}; nothing of "
                              f"this run was kept in {out}") from exc
            written.append(path)
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise
    return written


def _write_text(path: Path, text: str) -> Path:
    with atomic_write(path, text=True) as f:
        f.write(text)
    return path


def _plain(value: object) -> object:
    """JSON without NaN: undefined figures become ``null``."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
