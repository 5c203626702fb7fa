"""``lti-motion calibrate --log LOG.npz --reference FILE.tum``: the odometry intrinsics
(both wheels' scale and the wheel base) of a recorded drive against a pose reference; and
``lti-motion calibrate --reference SAMPLES``: the same from interval samples of a sensor's
own motion against the wheel angles (Censi et al.'s JSON lines,
:func:`lti_motion.recordings.read_motion_intervals`).

The log's encoder counts and frame times, and the reference's poses on the same clock
(motion capture, a scan matcher's or a smoother's trajectory) go to
:func:`lti_motion.calibration.calibrate_intrinsics`; the result is written
as ``intrinsics.json`` and summarised on the terminal. The log's simulator truth, if
it has any, is never read.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from lti_motion.calibration import IntrinsicsCalibration
    from lti_motion.intrinsics import OdometryIntrinsics
    from lti_motion.odometry_errors import OdometryErrors

__all__ = ["add_intrinsics_arguments", "is_interval_file", "run_intrinsics_calibration",
           "write_into_model"]


def add_intrinsics_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of the intrinsics calibration on ``lti-motion calibrate``.

    Their defaults are :func:`lti_motion.calibration.calibrate_intrinsics`'s: an option
    left out passes nothing, so the command line and the API agree.
    """
    parser.add_argument("--reference", metavar="FILE",
                        help="with --log: a TUM trajectory (t x y z qx qy qz qw) of the robot "
                             "or of a sensor on it, on the log's clock, or runs with a start and "
                             "an end pose each (a file starting '# lti-motion runs:'); alone: "
                             "interval samples "
                             "of a sensor's own motion against the wheel angles (Censi et al.'s "
                             "JSON lines: T, phi_l, phi_r, sm); calibrates both wheels' scale "
                             "and the wheel base (docs/intrinsics.md)")
    parser.add_argument("--reference-std", type=float, nargs=2, default=None,
                        metavar=("M", "DEG"),
                        help="noise of one reference pose: position [m] and heading [deg], the "
                             "first outlier round's weights (default the API's: 0.005 m, "
                             "0.573 deg = 0.01 rad); later rounds use the residuals' own noise")
    parser.add_argument("--sensor-pose", action="store_true",
                        help="the reference tracks a sensor off the axle centre: estimate its "
                             "pose on the robot too")
    parser.add_argument("--reference-offset", type=float, default=0.0, metavar="S",
                        help="seconds added to the reference's times (TUM or runs file) to put "
                             "them on the log's clock (default 0)")
    parser.add_argument("--outlier-rounds", type=int, default=None, metavar="N",
                        help="rounds of Censi et al.'s outlier rejection, gated by 3 robust "
                             "standard deviations (default 4; 0: none)")
    parser.add_argument("--outlier-fraction", type=float, default=None, metavar="F",
                        help="fraction of intervals each round rejects by their largest "
                             "rotation or translation residual (default 0.01)")
    parser.add_argument("--into-model", metavar="MODEL.json",
                        help="with --log --reference or --wall-run: also write a copy of this "
                             "model file carrying the intrinsics (model_intrinsics.json in "
                             "--out); --wall-run starts from its intrinsics")
    parser.add_argument("--encoders", choices=("commanded", "quadrature"), default=None,
                        help="encoder type: quadrature (they know the way the wheel turns; "
                             "default with --reference, as the API) or commanded (Roomba / "
                             "Create 2: they count in the commanded direction; default with "
                             "--bag)")


def is_interval_file(path: str | Path) -> bool:
    """Whether ``path`` holds interval samples (JSON objects) rather than a TUM trajectory:
    its first non-blank character is ``{``."""
    with open(path) as f:
        for line in f:
            if line.strip():
                return line.lstrip().startswith("{")
    return False


def _api_options(args: argparse.Namespace) -> dict:
    """The calibration's keyword arguments the user gave (the rest keep the API's)."""
    import numpy as np

    options = {"sensor_pose": args.sensor_pose}
    if args.reference_std is not None:
        pos_std, deg_std = args.reference_std
        options.update(position_std_m=pos_std, heading_std_rad=float(np.deg2rad(deg_std)))
    if args.outlier_rounds is not None:
        options["outlier_rounds"] = args.outlier_rounds
    if args.outlier_fraction is not None:
        options["outlier_fraction"] = args.outlier_fraction
    return options


def _option_words(message: str) -> str:
    """An API error's argument names in the command's options."""
    for api, cli in (("interval_s", "the interval"), ("position_std_m", "--reference-std M"),
                     ("heading_std_rad", "--reference-std DEG (in rad)"),
                     ("outlier_rounds", "--outlier-rounds"),
                     ("outlier_fraction", "--outlier-fraction")):
        if message.startswith(api + " "):
            return cli + message[len(api):]
    return message


def _summary(cal: IntrinsicsCalibration, *, radians: bool) -> list[str]:
    """Each parameter with its standard deviation, the sensor pose, the samples used and
    rejected (as Censi et al. report them); with counts in radians, the diameters."""
    import numpy as np

    k, std = cal.intrinsics, cal.std
    if radians:                      # metres per radian: the radius; the diameter is twice
        lines = [f"left wheel   diameter {2e3 * k.m_per_tick_left:.4f} mm +- {2e3 * std[0]:.4f}",
                 f"right wheel  diameter {2e3 * k.m_per_tick_right:.4f} mm +- "
                 f"{2e3 * std[1]:.4f}"]
    else:
        lines = [f"left wheel   {k.m_per_tick_left * 1e3:.5f} mm/tick +- {std[0] * 1e3:.5f}",
                 f"right wheel  {k.m_per_tick_right * 1e3:.5f} mm/tick +- {std[1] * 1e3:.5f}"]
    r = cal.report
    lines += [
        f"wheel base   {k.wheel_base_m * 1e3:.3f} mm +- {std[2] * 1e3:.3f}",
        f"left/right   {k.diameter_ratio:.5f}",
        f"drive: {r.turns_left} turns left, {r.turns_right} right ({r.arcs} arcs), "
        f"{r.straight_runs} straight runs in {r.windows} windows",
        f"intervals: {cal.n_intervals} used, {cal.n_rejected} rejected as outliers; residual "
        f"{cal.residual_rms[0] * 1e3:.2f} mm, {np.rad2deg(cal.residual_rms[1]):.3f} deg RMS",
    ]
    if len(std) == 6:
        x, y, th = cal.sensor_pose
        lines.append(f"sensor pose  x {x * 1e3:.2f} mm +- {std[3] * 1e3:.2f}, y {y * 1e3:.2f} mm "
                     f"+- {std[4] * 1e3:.2f}, {np.rad2deg(th):.3f} deg +- "
                     f"{np.rad2deg(std[5]):.3f}")
    lines += [f"weakly determined: {note}" for note in r.undetermined]
    return lines


def _result_json(cal: IntrinsicsCalibration, *, radians: bool, sources: dict) -> dict:
    """``intrinsics.json``: the numbers, their standard deviations and covariance, the
    sensor pose, the intervals used and rejected, the noise the residuals showed."""
    names = ["m_per_tick_left", "m_per_tick_right", "wheel_base_m", "sensor_x_m",
             "sensor_y_m", "sensor_theta_rad"][:len(cal.std)]
    out = {"intrinsics": cal.intrinsics.as_dict(), "std": cal.std.tolist(),
           "std_by_name": dict(zip(names, cal.std.tolist(), strict=True)),
           "sensor_pose": cal.sensor_pose.tolist(), "covariance": cal.covariance.tolist(),
           "intervals_used": cal.n_intervals, "intervals_rejected": cal.n_rejected,
           "reference_noise": None if cal.noise is None else cal.noise.tolist(),
           "odometry_errors": (None if cal.odometry_errors is None
                               else cal.odometry_errors.as_dict()),
           "undetermined": list(cal.report.undetermined), **sources}
    if radians:
        k = cal.intrinsics
        out["counts"] = "wheel radians: m_per_tick is the wheel radius"
        out["diameters_m"] = {"left": 2 * k.m_per_tick_left, "right": 2 * k.m_per_tick_right,
                              "left_std": 2 * float(cal.std[0]),
                              "right_std": 2 * float(cal.std[1])}
    return out


def write_into_model(model_path: str | Path, intrinsics: OdometryIntrinsics, out: Path, *,
                     odometry_errors: OdometryErrors | None = None) -> Path:
    """A copy of the model file carrying ``intrinsics``, as ``out/model_intrinsics.json``.

    The model's outputs move with the counts' new meaning, so that it predicts the same
    counts (:meth:`lti_motion.model.MotionModel.with_intrinsics`); a model without an
    encoder scale has none to move and just takes the intrinsics. ``odometry_errors``, the
    odometry error model the calibration measured, goes with them (None: not measured).

    Raises
    ------
    FileNotFoundError
        If there is no file ``model_path``.
    """
    from lti_motion.model import MotionModel

    if not Path(model_path).is_file():
        raise FileNotFoundError(f"no model file {model_path}")
    model = MotionModel.load(model_path)
    moved = (model.with_intrinsics(intrinsics, odometry_errors=odometry_errors)
             if model.encoder_intrinsics is not None
             else model.updated(intrinsics=intrinsics, m_per_tick=intrinsics.m_per_tick,
                                odometry_errors=odometry_errors))
    return moved.save(Path(out) / "model_intrinsics.json")


def _calibrate_runs(args: argparse.Namespace, options: dict) -> IntrinsicsCalibration:
    """``--log LOG --reference RUNS``: each run's counts cut from the log between its start
    and end time (:func:`lti_motion.calibration.calibrate_intrinsics_runs`)."""
    import numpy as np

    from lti_motion.calibration import calibrate_intrinsics_runs
    from lti_motion.recordings import load_log, read_end_pose_runs

    if not args.log:
        raise ValueError(f"{args.reference} holds runs with their times: it goes with --log "
                         "LOG.npz (the drive the runs are part of)")
    runs = read_end_pose_runs(args.reference)
    log = load_log(args.log)
    if np.ndim(log.t_s) != 1:
        raise ValueError(f"{args.log} holds {np.shape(log.t_s)[0]} robots; calibrate one "
                         "robot's log")
    t, ticks = log.t_s[log.valid], log.ticks[log.valid]
    cut = []
    for i, (t0, t1) in enumerate(runs.times_s + args.reference_offset):
        inside = (t >= t0) & (t <= t1)
        if inside.sum() < 2:
            raise ValueError(f"run {i} ({t0:.3f}..{t1:.3f} s) holds {int(inside.sum())} frames "
                             f"of {args.log} ({t[0]:.3f}..{t[-1]:.3f} s): is it on the log's "
                             "clock?")
        cut.append(ticks[inside])
    if args.encoders is not None:
        options["encoders"] = args.encoders
    if getattr(args, "m_per_tick", None) is not None:    # runs that close a loop (UMBmark)
        options["mean_m_per_tick"] = args.m_per_tick
    return calibrate_intrinsics_runs(cut, runs.start_poses, runs.end_poses,
                                     turns=runs.turns.tolist(), **options)


def run_intrinsics_calibration(args: argparse.Namespace) -> int:
    """Handler of ``lti-motion calibrate --log LOG --reference FILE`` and of
    ``lti-motion calibrate --reference SAMPLES``; returns the exit code.

    Raises
    ------
    ValueError
        Bad input (no reference, a log of several robots, a reference that does not fit);
        the CLI prints it as one line and exits with 2.
    OSError
        A file that cannot be read.
    """
    import numpy as np

    from lti_motion.calibration import calibrate_intrinsics, calibrate_intrinsics_intervals
    from lti_motion.recordings import (
        is_end_pose_runs,
        load_log,
        read_motion_intervals,
        read_tum,
    )

    if not args.reference:
        raise ValueError("--log needs --reference FILE.tum: the pose reference to calibrate "
                         "the wheels against")
    if not np.isfinite(args.reference_offset):
        raise ValueError(f"--reference-offset must be a finite number of seconds, got "
                         f"{args.reference_offset:g}")
    if not Path(args.reference).is_file():
        raise FileNotFoundError(f"no reference file {args.reference}")
    options = _api_options(args)
    radians = is_interval_file(args.reference)
    try:
        if is_end_pose_runs(args.reference):
            cal = _calibrate_runs(args, options)
            sources = {"log": str(args.log), "reference": str(args.reference)}
        elif radians:
            if args.log:
                raise ValueError(f"{args.reference} holds interval samples with their own "
                                 "wheel angles; give it without --log")
            samples = read_motion_intervals(args.reference)
            if args.encoders is not None:
                raise ValueError("--encoders is for --log's counts; interval samples hold "
                                 "wheel angles")
            cal = calibrate_intrinsics_intervals(samples.wheel_rad, samples.sensor_motion,
                                                 **options)
            sources = {"reference": str(args.reference)}
        else:
            if not args.log:
                raise ValueError(f"{args.reference} is a trajectory: it goes with --log LOG.npz "
                                 "(the recorded drive it refers to)")
            log = load_log(args.log)
            if np.ndim(log.t_s) != 1:
                raise ValueError(f"{args.log} holds {np.shape(log.t_s)[0]} robots; calibrate "
                                 "one robot's log")
            try:
                t_ref, poses = read_tum(args.reference)
            except ValueError as exc:
                raise ValueError(f"{args.reference} is not a TUM trajectory (t x y z qx qy qz "
                                 f"qw per line): {exc}") from None
            if args.encoders is not None:
                options["encoders"] = args.encoders
            keep = log.valid
            cal = calibrate_intrinsics(log.t_s[keep], log.ticks[keep],
                                       t_ref + args.reference_offset, poses, **options)
            sources = {"log": str(args.log), "reference": str(args.reference)}
    except ValueError as exc:
        raise type(exc)(_option_words(str(exc))) from None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "intrinsics.json"
    path.write_text(json.dumps(_result_json(cal, radians=radians, sources=sources),
                               indent=2) + "\n")
    written = [path]
    if args.into_model:
        written.append(write_into_model(args.into_model, cal.intrinsics, out,
                                        odometry_errors=cal.odometry_errors))
    for line in _summary(cal, radians=radians):
        print(line)
    print(f"wrote {', '.join(str(p) for p in written)}")
    return 0
