"""``lti-motion calibrate --log LOG.npz --reference FILE.tum``: the odometry intrinsics
(both wheels' scale and the wheel base) of a recorded drive against a pose reference.

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

__all__ = ["add_intrinsics_arguments", "run_intrinsics_calibration", "write_into_model"]


def add_intrinsics_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of the intrinsics calibration on ``lti-motion calibrate``."""
    parser.add_argument("--reference", metavar="FILE",
                        help="with --log: a TUM trajectory (t x y z qx qy qz qw) of the robot "
                             "or of a sensor on it, on the log's clock; calibrates both wheels' "
                             "scale and the wheel base (docs/intrinsics.md)")
    parser.add_argument("--reference-std", type=float, nargs=2, default=(0.005, 0.5),
                        metavar=("M", "DEG"),
                        help="noise of one reference pose: position [m] and heading [deg] "
                             "(default 0.005 0.5)")
    parser.add_argument("--sensor-pose", action="store_true",
                        help="the reference tracks a sensor off the axle centre: estimate its "
                             "pose on the robot too")
    parser.add_argument("--into-model", metavar="MODEL.json",
                        help="with --log --reference or --wall-run: also write a copy of this "
                             "model file carrying the intrinsics (model_intrinsics.json in "
                             "--out); --wall-run starts from its intrinsics")
    parser.add_argument("--encoders", choices=("commanded", "quadrature"), default="commanded",
                        help="encoder type: commanded (Roomba / Create 2, default) or quadrature")


def _summary(cal: IntrinsicsCalibration) -> list[str]:
    import numpy as np

    k, std = cal.intrinsics, cal.std
    lines = [
        f"left wheel   {k.m_per_tick_left * 1e3:.5f} mm/tick +- {std[0] * 1e3:.5f}",
        f"right wheel  {k.m_per_tick_right * 1e3:.5f} mm/tick +- {std[1] * 1e3:.5f}",
        f"wheel base   {k.wheel_base_m * 1e3:.2f} mm +- {std[2] * 1e3:.2f}",
        f"left/right   {k.diameter_ratio:.5f}",
        f"drive: {cal.report.turns_left} turns left, {cal.report.turns_right} right, "
        f"{cal.report.straight_runs} straight runs in {cal.n_intervals} intervals; residual "
        f"{cal.residual_rms[0] * 1e3:.1f} mm, {np.rad2deg(cal.residual_rms[1]):.2f} deg RMS",
    ]
    if len(std) == 6:
        x, y, th = cal.sensor_pose
        lines.append(f"sensor pose  x {x:.3f} m, y {y:.3f} m, {np.rad2deg(th):.2f} deg")
    lines += [f"weakly determined: {note}" for note in cal.report.undetermined]
    return lines


def write_into_model(model_path: str | Path, intrinsics: OdometryIntrinsics, out: Path
                     ) -> Path:
    """A copy of the model file carrying ``intrinsics``, as ``out/model_intrinsics.json``.

    The model's outputs move with the counts' new meaning, so that it predicts the same
    counts (:meth:`lti_motion.model.MotionModel.with_intrinsics`); a model without an
    encoder scale has none to move and just takes the intrinsics.

    Raises
    ------
    FileNotFoundError
        If there is no file ``model_path``.
    """
    from lti_motion.model import MotionModel

    if not Path(model_path).is_file():
        raise FileNotFoundError(f"no model file {model_path}")
    model = MotionModel.load(model_path)
    moved = (model.with_intrinsics(intrinsics) if model.encoder_intrinsics is not None
             else model.updated(intrinsics=intrinsics, m_per_tick=intrinsics.m_per_tick))
    return moved.save(Path(out) / "model_intrinsics.json")


def run_intrinsics_calibration(args: argparse.Namespace) -> int:
    """Handler of ``lti-motion calibrate --log LOG --reference FILE``; returns the exit code.

    Raises
    ------
    ValueError
        Bad input (no reference, a log of several robots, a reference that does not fit);
        the CLI prints it as one line and exits with 2.
    OSError
        A file that cannot be read.
    """
    import numpy as np

    from lti_motion.calibration import calibrate_intrinsics
    from lti_motion.recordings import load_log, read_tum

    if not args.reference:
        raise ValueError("--log needs --reference FILE.tum: the pose reference to calibrate "
                         "the wheels against")
    log = load_log(args.log)
    if np.ndim(log.t_s) != 1:
        raise ValueError(f"{args.log} holds {np.shape(log.t_s)[0]} robots; calibrate one "
                         "robot's log")
    try:
        t_ref, poses = read_tum(args.reference)
    except ValueError as exc:
        raise ValueError(f"{args.reference} is not a TUM trajectory (t x y z qx qy qz qw per "
                         f"line): {exc}") from None
    keep = log.valid
    pos_std, deg_std = args.reference_std
    cal = calibrate_intrinsics(log.t_s[keep], log.ticks[keep], t_ref, poses,
                               sensor_pose=args.sensor_pose, encoders=args.encoders,
                               position_std_m=pos_std, heading_std_rad=np.deg2rad(deg_std))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "intrinsics.json"
    path.write_text(json.dumps({
        "intrinsics": cal.intrinsics.as_dict(), "std": cal.std.tolist(),
        "sensor_pose": cal.sensor_pose.tolist(), "covariance": cal.covariance.tolist(),
        "undetermined": list(cal.report.undetermined), "log": str(args.log),
        "reference": str(args.reference)}, indent=2) + "\n")
    written = [path]
    if args.into_model:
        written.append(write_into_model(args.into_model, cal.intrinsics, out))
    for line in _summary(cal):
        print(line)
    print(f"wrote {', '.join(str(p) for p in written)}")
    return 0
