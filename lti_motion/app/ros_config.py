"""The calibration as ROS parameters: ``diff_drive_controller``, robot_localization, fuse.

``lti-motion export --model M --to TARGET`` (``docs/guide_ros_config.md``). Each target is
a list of :class:`Parameter` (name, value, the comment that says where the number came
from) rendered as a YAML parameter file by :func:`render_yaml`, written by hand (YAML 1.1
plain scalars as ``yaml-cpp`` / ``rcl_yaml_param_parser`` and ``rosparam`` resolve them:
every double has a ``.``, an exponent a sign; the project has no YAML dependency).

**diff_drive_controller** (:func:`diff_drive_parameters`). The controller turns each
wheel's joint angle [rad] into travel with ``wheel_radius * {left,right}_wheel_radius_
multiplier`` and divides the wheels' difference by ``wheel_separation *
wheel_separation_multiplier`` (ros2_controllers, ``diff_drive_controller.cpp``; ROS 1
ros_controllers likewise). The model's intrinsics give each wheel's ground travel per
encoder tick ``k`` [m/tick]; the hardware interface gives angles in ticks over ``ticks per
radian``, so the calibrated radius is ``r = k * ticks_per_rev / (2 pi)`` and the multiplier
``r / r_nominal``; the separation multiplier is ``b / b_nominal``. Without a nominal
radius the radius is the wheels' mean and the multipliers say how each wheel differs
from it; without a nominal separation it is the calibrated wheel base.

The covariance diagonals (``[x, y, z, roll, pitch, yaw]``, the twist's
``[vx, vy, vz, wx, wy, wz]``): the twist's ``(vx, wz)`` are the model's output noise ``R``
averaged over the publish period ``T`` (``R dt / T``, :mod:`lti_motion.odometry_noise`
eq. 1); the pose's ``(x, y, yaw)`` are what that twist noise adds to the pose over one
publish period (``T^2`` times the twist's; the controller publishes one constant diagonal
on a dead-reckoned pose, which can only say how much each message adds: use the pose
differentially or not at all). What a planar model does not estimate gets
:data:`UNESTIMATED_VARIANCE` (z, roll, pitch, vy, vz, wx, wy), as the project's bags do.

**robot_localization** (:func:`robot_localization_parameters`): ``process_noise_covariance``
(15 x 15, state order ``x, y, z, roll, pitch, yaw, vx, vy, vz, vroll, vpitch, vyaw, ax, ay,
az``, ``filter_common.hpp``). Its EKF adds ``delta * Q`` per prediction (``ekf.cpp``,
predict; robot_localization 3.6.0 on ROS 2, 3.5.2 on Humble, 2.7.5 on Noetic), so ``Q`` is
per second: with the filter period ``T_f`` and the model's speed error ``S`` over one
period from a known state (:func:`lti_motion.odometry_noise.speed_error_over`), the
velocities get ``S / T_f`` (``(vx, vyaw)`` with their cross term) and the pose what that
speed error adds over a period, ``S T_f`` (``x`` and ``y`` both the travel's, ``yaw`` the
turn's). The model has no counterpart for z, roll, pitch, vy, vz, vroll, vpitch and the
accelerations: :data:`NO_COUNTERPART_VARIANCE` (``two_d_mode`` then drops the 3-D ones).

**fuse** (:func:`fuse_parameters`): ``Unicycle2D``'s ``process_noise_diagonal`` (order ``x,
y, yaw, x_vel, y_vel, yaw_vel, x_acc, y_acc``), multiplied by the time between states in
``unicycle_2d.cpp`` (fuse_models 0.10.0 for ROS 1, 1.2.1 for ROS 2), so per second like
robot_localization's, the same numbers.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal

import numpy as np

from lti_motion.model import MotionModel
from lti_motion.odometry_noise import averaged_covariance, speed_error_over

__all__ = [
    "CREATE2_TICKS_PER_REV",
    "DDC_DEFAULT_PUBLISH_RATE_HZ",
    "DDC_ROS1_TYPES",
    "DDC_ROS2_TYPES",
    "FUSE_STATE",
    "NO_COUNTERPART_VARIANCE",
    "RL_DEFAULT_FREQUENCY_HZ",
    "RL_STATE",
    "TARGETS",
    "UNESTIMATED_VARIANCE",
    "Nominal",
    "Parameter",
    "diff_drive_parameters",
    "export_text",
    "fuse_parameters",
    "render_yaml",
    "robot_localization_parameters",
]

Target = Literal["diff_drive_controller", "diff_drive_controller_ros1", "robot_localization",
                 "fuse"]
#: What ``--to`` takes.
TARGETS: tuple[str, ...] = ("diff_drive_controller", "diff_drive_controller_ros1",
                            "robot_localization", "fuse")

#: Names and types of the parameters the export writes, as the controller's own parameter
#: definition spells them: ros2_controllers, diff_drive_controller
#: ``src/diff_drive_controller_parameter.yaml``, branch ``jazzy`` (package 4.42.1; branch
#: ``humble``, 2.54.0, defines these the same). Type words are generate_parameter_library's.
DDC_ROS2_TYPES: Mapping[str, str] = MappingProxyType({
    "left_wheel_names": "string_array",
    "right_wheel_names": "string_array",
    "wheel_separation": "double",
    "wheel_radius": "double",
    "wheel_separation_multiplier": "double",
    "left_wheel_radius_multiplier": "double",
    "right_wheel_radius_multiplier": "double",
    "pose_covariance_diagonal": "double_array",
    "twist_covariance_diagonal": "double_array",
    "publish_rate": "double",
})
#: The same for ROS 1: ros_controllers 0.21.2 (Noetic), ``diff_drive_controller.cpp``
#: (``controller_nh.param<double>`` / ``getParam``; the covariance lists are asserted to
#: hold six ``TypeDouble`` values; a wheel is a string or a list of strings).
DDC_ROS1_TYPES: Mapping[str, str] = MappingProxyType({
    "left_wheel": "string_array",
    "right_wheel": "string_array",
    "wheel_separation": "double",
    "wheel_radius": "double",
    "wheel_separation_multiplier": "double",
    "left_wheel_radius_multiplier": "double",
    "right_wheel_radius_multiplier": "double",
    "pose_covariance_diagonal": "double_array",
    "twist_covariance_diagonal": "double_array",
    "publish_rate": "double",
})
#: ``publish_rate``'s default in both definitions [Hz].
DDC_DEFAULT_PUBLISH_RATE_HZ = 50.0
#: robot_localization's default ``frequency`` [Hz] (``ros_filter.cpp``, 3.6.0).
RL_DEFAULT_FREQUENCY_HZ = 30.0
#: The Create 2's encoder counts per wheel revolution (Open Interface spec), the default of
#: ``calibrate --bag`` (``drivers.bags.CREATE2_TICKS_PER_RAD`` times 2 pi).
CREATE2_TICKS_PER_REV = 508.8
#: Variance of what a planar model does not estimate [m^2, rad^2, (m/s)^2, (rad/s)^2]:
#: "unknown", as robot_localization reads it (``drivers.bags.writer`` writes the same).
UNESTIMATED_VARIANCE = 1e6
#: Process noise per second of robot_localization's and fuse's states the model has no
#: counterpart for (z, roll, pitch, lateral speed, the 3-D rates, accelerations): small,
#: never zero, so they stay where they start (a planar robot, no lateral slip modelled).
NO_COUNTERPART_VARIANCE = 1e-9
#: robot_localization's 15 states, in its order (``filter_common.h``).
RL_STATE = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "vroll", "vpitch",
            "vyaw", "ax", "ay", "az")
#: fuse ``Unicycle2D``'s 8 states, in its order (``unicycle_2d.h``).
FUSE_STATE = ("x", "y", "yaw", "x_vel", "y_vel", "yaw_vel", "x_acc", "y_acc")


@dataclass(frozen=True)
class Parameter:
    """One parameter of an exported file: its name, value and where the value came from."""

    name: str
    value: float | int | bool | str | tuple
    comment: str = ""


@dataclass(frozen=True)
class Nominal:
    """The robot's nominal geometry, against which the multipliers are given.

    Attributes
    ----------
    wheel_radius_m, wheel_separation_m : float or None
        Nominal radius and separation [m]; None: export absolute values.
    ticks_per_rev : float
        Encoder counts per wheel revolution the hardware interface divides by to give
        the joint angle (with the counts the model was calibrated on).
    left_joint, right_joint : str or None
        The wheel joints' names, when known.
    source, ticks_source : str
        Where the geometry and the encoder resolution came from (for the comments).
    """

    wheel_radius_m: float | None = None
    wheel_separation_m: float | None = None
    ticks_per_rev: float = CREATE2_TICKS_PER_REV
    left_joint: str | None = None
    right_joint: str | None = None
    source: str = "none given"
    ticks_source: str = f"{CREATE2_TICKS_PER_REV:g}, the Create 2's (default)"

    def __post_init__(self) -> None:
        for name in ("wheel_radius_m", "wheel_separation_m", "ticks_per_rev"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"the nominal {name} must be a positive number, got {value:g}")


def _model_intrinsics(model: MotionModel, model_name: str):
    if model.intrinsics is None:
        raise ValueError(
            f"the model {model_name} has no odometry intrinsics (each wheel's scale and the "
            "wheel base); calibrate them with 'lti-motion calibrate --log LOG --reference "
            "REF.tum --into-model MODEL' or 'lti-motion calibrate --wall-run --into-model "
            "MODEL' (docs/intrinsics.md) and export the model_intrinsics.json it writes")
    return model.intrinsics


def _odometry_error_line(model: MotionModel) -> str:
    """Where the odometry's pose error comes from: measured, or said not to be."""
    e = model.odometry_errors
    if e is None:
        return ("odometry pose error: NOT MEASURED (the model carries no odometry error "
                "model; calibrate its intrinsics against a pose reference to measure it): the "
                "pose covariances stand on the model's output noise R, an upper bound")
    return (f"odometry pose error: measured, a random walk of {_g(e.wheel_variance_per_m)} "
            f"m^2 per metre each wheel rolls (+- {_g(e.wheel_variance_std)}) and the "
            f"intrinsics' covariance, by the {e.source}")


def _check_rate(value: float, option: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{option} must be a positive number [Hz], got {value:g}")
    return float(value)


def _g(x: float) -> str:
    return f"{x:.6g}"


def diff_drive_parameters(model: MotionModel, nominal: Nominal, *,
                          publish_rate_hz: float = DDC_DEFAULT_PUBLISH_RATE_HZ,
                          model_name: str = "", ros1: bool = False) -> list[Parameter]:
    """``diff_drive_controller``'s wheel and covariance parameters (module docstring).

    Parameters
    ----------
    model : MotionModel
        A model with :attr:`~lti_motion.model.MotionModel.intrinsics`.
    nominal : Nominal
        The geometry the multipliers are against.
    publish_rate_hz : float
        The controller's ``publish_rate`` [Hz]: the covariances are for its period.
    model_name : str
        For messages and comments.
    ros1 : bool
        ROS 1 names (``left_wheel`` / ``right_wheel``) instead of ROS 2's.

    Returns
    -------
    list of Parameter

    Raises
    ------
    ValueError
        A model without intrinsics (the message says how to calibrate them), a
        non-positive rate.
    """
    k = _model_intrinsics(model, model_name)
    rate = _check_rate(publish_rate_hz, "--publish-rate")
    period = 1.0 / rate
    ticks_per_rad = nominal.ticks_per_rev / (2.0 * math.pi)
    r_left, r_right = k.m_per_tick_left * ticks_per_rad, k.m_per_tick_right * ticks_per_rad
    out = []
    if nominal.left_joint and nominal.right_joint:
        names = ("left_wheel", "right_wheel") if ros1 else ("left_wheel_names",
                                                           "right_wheel_names")
        out += [Parameter(names[0], (nominal.left_joint,), f"from {nominal.source}"),
                Parameter(names[1], (nominal.right_joint,), f"from {nominal.source}")]
    how = (f"calibrated travel per tick {k.m_per_tick_left * 1e3:.6g} / "
           f"{k.m_per_tick_right * 1e3:.6g} mm (left / right) times {nominal.ticks_source} "
           f"ticks per revolution over 2 pi: radii {_g(r_left)} / {_g(r_right)} m")
    if nominal.wheel_radius_m is not None:
        radius = nominal.wheel_radius_m
        out.append(Parameter("wheel_radius", radius, f"nominal, from {nominal.source}"))
        radius_note = f"{how}, over the nominal radius"
    else:
        radius = 0.5 * (r_left + r_right)
        out.append(Parameter("wheel_radius", radius,
                             f"no nominal radius given: the calibrated wheels' mean ({how})"))
        radius_note = "each calibrated radius over their mean"
    out += [Parameter("left_wheel_radius_multiplier", r_left / radius, radius_note),
            Parameter("right_wheel_radius_multiplier", r_right / radius,
                      "the same for the right wheel")]
    if nominal.wheel_separation_m is not None:
        out += [Parameter("wheel_separation", nominal.wheel_separation_m,
                          f"nominal, from {nominal.source}"),
                Parameter("wheel_separation_multiplier",
                          k.wheel_base_m / nominal.wheel_separation_m,
                          f"calibrated wheel base {_g(k.wheel_base_m)} m over the nominal")]
    else:
        out += [Parameter("wheel_separation", k.wheel_base_m,
                          "no nominal separation given: the calibrated wheel base"),
                Parameter("wheel_separation_multiplier", 1.0,
                          "1: the separation above is the calibrated one")]
    twist = averaged_covariance(model.R, dt_s=model.dt_s, period_s=period)
    u = UNESTIMATED_VARIANCE
    out += [
        Parameter("publish_rate", rate, "the covariances below are for this rate's period"),
        Parameter("pose_covariance_diagonal",
                  (twist[0, 0] * period**2, twist[0, 0] * period**2, u, u, u,
                   twist[1, 1] * period**2),
                  f"[x, y, z, roll, pitch, yaw]: what the twist's noise adds to the pose in one "
                  f"publish period ({period * 1e3:g} ms; the pose is dead reckoning and grows "
                  f"without bound: fuse it differentially); {u:g}: not estimated"),
        Parameter("twist_covariance_diagonal", (twist[0, 0], u, u, u, u, twist[1, 1]),
                  f"[vx, vy, vz, wx, wy, wz]: the model's output noise R at its "
                  f"{model.dt_s * 1e3:g} ms period averaged over {period * 1e3:g} ms "
                  f"(R dt / T); {u:g}: not estimated"),
    ]
    return out


def _process_noise(model: MotionModel, frequency_hz: float) -> dict[str, float]:
    """The per-second process noise of the planar states (module docstring)."""
    period = 1.0 / _check_rate(frequency_hz, "--frequency")
    s = speed_error_over(model, period)
    return {"x": s[0, 0] * period, "y": s[0, 0] * period, "yaw": s[1, 1] * period,
            "vx": s[0, 0] / period, "vyaw": s[1, 1] / period, "vx_vyaw": s[0, 1] / period}


def robot_localization_parameters(model: MotionModel, *,
                                  frequency_hz: float = RL_DEFAULT_FREQUENCY_HZ,
                                  publish_rate_hz: float = DDC_DEFAULT_PUBLISH_RATE_HZ
                                  ) -> list[Parameter]:
    """robot_localization's ``frequency``, ``two_d_mode``, ``process_noise_covariance`` and
    the odometry input ``odom0_config`` (module docstring).

    Parameters
    ----------
    model : MotionModel
        Any calibrated model (its ``A, C, Q, R`` and period).
    frequency_hz : float
        The filter's ``frequency`` [Hz]; the process noise is for its period.
    publish_rate_hz : float
        The odometry's rate [Hz]: the covariances its twist should carry (the
        ``diff_drive_controller`` export's) are given in a comment, since
        robot_localization reads them from each message.

    Returns
    -------
    list of Parameter
        ``process_noise_covariance`` 15 x 15 row-major, per second [m^2/s, rad^2/s,
        (m/s)^2/s, (rad/s)^2/s], in :data:`RL_STATE` order.

    Raises
    ------
    ValueError
        A non-positive rate.

    References
    ----------
    robot_localization 3.6.0 (ROS 2), ``src/ekf.cpp`` (predict: ``P += delta Q``) and
    ``include/robot_localization/filter_common.hpp`` (the state order).
    """
    q = _process_noise(model, frequency_hz)
    index = {name: i for i, name in enumerate(RL_STATE)}
    matrix = np.diag(np.full(len(RL_STATE), NO_COUNTERPART_VARIANCE))
    for name in ("x", "y", "yaw", "vx", "vyaw"):
        matrix[index[name], index[name]] = q[name]
    matrix[index["vx"], index["vyaw"]] = matrix[index["vyaw"], index["vx"]] = q["vx_vyaw"]
    rate = _check_rate(publish_rate_hz, "--publish-rate")
    twist = averaged_covariance(model.R, dt_s=model.dt_s, period_s=1.0 / rate)
    fused = tuple(name in ("vx", "vyaw") for name in RL_STATE)
    return [
        Parameter("frequency", float(frequency_hz), "the filter's rate; the process noise is "
                  "for its period"),
        Parameter("two_d_mode", True, "a planar robot"),
        Parameter("odom0_config", fused,
                  f"fuse the odometry's vx and vyaw; its twist should carry the variances "
                  f"{_g(twist[0, 0])} (m/s)^2 and {_g(twist[1, 1])} (rad/s)^2 at "
                  f"{rate:g} Hz (lti-motion export --to diff_drive_controller)"),
        Parameter("process_noise_covariance", tuple(matrix.ravel()),
                  f"15 x 15, row-major, per second ({', '.join(RL_STATE)}): x, y, yaw, vx, "
                  f"vyaw from the model's speed error over one filter period; "
                  f"{NO_COUNTERPART_VARIANCE:g}: no counterpart in the model"),
    ]


def fuse_parameters(model: MotionModel, *, frequency_hz: float = RL_DEFAULT_FREQUENCY_HZ
                    ) -> list[Parameter]:
    """fuse ``Unicycle2D``'s ``process_noise_diagonal`` (module docstring).

    Parameters
    ----------
    model : MotionModel
        Any calibrated model.
    frequency_hz : float
        One over the time between two states [Hz].

    Returns
    -------
    list of Parameter
        The 8 per-second variances in :data:`FUSE_STATE` order.

    References
    ----------
    fuse_models 1.2.1 (ROS 2) / 0.10.0 (ROS 1), ``src/unicycle_2d.cpp`` (the process noise
    times the time between states) and ``unicycle_2d.h`` (the order).
    """
    q = _process_noise(model, frequency_hz)
    values = tuple(q.get(name, NO_COUNTERPART_VARIANCE) for name in
                   ("x", "y", "yaw", "vx", "vy", "vyaw", "ax", "ay"))
    return [Parameter("process_noise_diagonal", values,
                      f"per second ({', '.join(FUSE_STATE)}), for states "
                      f"{1e3 / frequency_hz:g} ms apart: the model's speed error over that "
                      f"time; {NO_COUNTERPART_VARIANCE:g}: no counterpart in the model")]


def _scalar(value: object) -> str:
    """A YAML 1.1 plain scalar that resolves to the value's own type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"a parameter value is {value}; nothing exported")
        text = f"{value:.7g}"           # 7 digits: what a run reproduces, to 1e-6
        mantissa, _, exponent = text.partition("e")
        if "." not in mantissa:
            mantissa += ".0"
        if exponent:
            sign = "-" if exponent.startswith("-") else "+"
            return f"{mantissa}e{sign}{int(exponent.lstrip('+-')):02d}"
        return mantissa
    if isinstance(value, str):
        return json.dumps(value)
    raise TypeError(f"no YAML form for {type(value).__name__}")


def _value(value: object, indent: str) -> str:
    """A scalar, or a flow sequence; a square matrix's (15 x 15) one row per line."""
    if not isinstance(value, tuple):
        return _scalar(value)
    items = [_scalar(v) for v in value]
    side = math.isqrt(len(items))
    if side < 4 or side * side != len(items):
        return "[" + ", ".join(items) + "]"
    rows = [", ".join(items[i:i + side]) for i in range(0, len(items), side)]
    return "[" + f",\n{indent}  ".join(rows) + "]"


def render_yaml(parameters: Sequence[Parameter], *, path: Sequence[str],
                header: Sequence[str] = ()) -> str:
    """A parameter file: ``header`` as comments, then ``parameters`` nested under ``path``.

    Examples
    --------
    >>> print(render_yaml([Parameter("wheel_radius", 0.036, "nominal")],
    ...                   path=("ddc", "ros__parameters")), end="")
    ddc:
      ros__parameters:
        # nominal
        wheel_radius: 0.036
    """
    lines = [f"# {line}".rstrip() for line in header]
    for depth, key in enumerate(path):
        lines.append("  " * depth + f"{key}:")
    indent = "  " * len(path)
    for p in parameters:
        if p.comment:
            lines.append(f"{indent}# {p.comment}")
        lines.append(f"{indent}{p.name}: {_value(p.value, indent)}")
    return "\n".join(lines) + "\n"


def export_text(model: MotionModel, target: Target, *, nominal: Nominal | None = None,
                publish_rate_hz: float = DDC_DEFAULT_PUBLISH_RATE_HZ,
                frequency_hz: float = RL_DEFAULT_FREQUENCY_HZ, model_name: str = "",
                node: str | None = None) -> str:
    """The parameter file of ``target`` (one of :data:`TARGETS`) for ``model``.

    Raises
    ------
    ValueError
        An unknown target; the errors of the parameter functions.
    """
    if target not in TARGETS:
        raise ValueError(f"unknown --to {target!r}; give one of {', '.join(TARGETS)}")
    header = [f"lti-motion export --to {target}, from the model {model_name or '(in memory)'}",
              f"calibrated {model.calibrated_at}, period {model.dt_s * 1e3:g} ms, "
              f"floor {model.floor or 'not recorded'}", _odometry_error_line(model)]
    if target.startswith("diff_drive_controller"):
        ros1 = target.endswith("_ros1")
        nominal = nominal or Nominal()
        params = diff_drive_parameters(model, nominal, publish_rate_hz=publish_rate_hz,
                                       model_name=model_name, ros1=ros1)
        header += [f"nominal geometry: {nominal.source}",
                   "names and types: ros2_controllers diff_drive_controller "
                   "src/diff_drive_controller_parameter.yaml (jazzy 4.42.1, humble 2.54.0)"
                   if not ros1 else "names and types: ros_controllers 0.21.2 (Noetic) "
                   "diff_drive_controller.cpp"]
        if not (nominal.left_joint and nominal.right_joint):
            header.append("left/right wheel joint names not known here: add "
                          + ("left_wheel / right_wheel" if ros1 else
                             "left_wheel_names / right_wheel_names") + " (or give --urdf)")
        if ros1:
            params = [Parameter("type", "diff_drive_controller/DiffDriveController"), *params]
            return render_yaml(params, path=(node or "diff_drive_controller",), header=header)
        return render_yaml(params, path=(node or "diff_drive_controller", "ros__parameters"),
                           header=header)
    if target == "robot_localization":
        params = robot_localization_parameters(model, frequency_hz=frequency_hz,
                                               publish_rate_hz=publish_rate_hz)
        header.append("robot_localization ekf_node parameters (ROS 2; for ROS 1 drop the "
                      "ros__parameters level)")
        return render_yaml(params, path=(node or "ekf_filter_node", "ros__parameters"),
                           header=header)
    params = fuse_parameters(model, frequency_hz=frequency_hz)
    header.append("fuse_models::Unicycle2D motion model parameters: put them under your "
                  "motion model's name in the optimizer node (ROS 1: no ros__parameters)")
    return render_yaml(params, path=(node or "state_estimator", "ros__parameters",
                                     "unicycle_motion_model"), header=header)
