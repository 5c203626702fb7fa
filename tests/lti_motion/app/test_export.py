"""``lti-motion export``: the parameter files load as the targets' parameters, the numbers
are the calibration's, bad input is one line and exit 2."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from lti_motion.app.cli import main
from lti_motion.app.ros_config import (
    DDC_ROS1_TYPES,
    DDC_ROS2_TYPES,
    FUSE_STATE,
    RL_STATE,
    Nominal,
    export_text,
)
from lti_motion.intrinsics import OdometryIntrinsics

#: A copy, written down by hand, of the top-level parameters (name: type) of ros2_controllers'
#: diff_drive_controller ``src/diff_drive_controller_parameter.yaml``, branch jazzy, package
#: version 4.42.1 (generate_parameter_library type words). The exporter's own table
#: (``DDC_ROS2_TYPES``) is checked against it, and the exported text against both.
DDC_JAZZY_DEFINITION = {
    "left_wheel_names": "string_array", "right_wheel_names": "string_array",
    "wheel_separation": "double", "wheel_radius": "double",
    "wheel_separation_multiplier": "double", "left_wheel_radius_multiplier": "double",
    "right_wheel_radius_multiplier": "double", "tf_frame_prefix_enable": "bool",
    "tf_frame_prefix": "string", "odom_frame_id": "string", "base_frame_id": "string",
    "pose_covariance_diagonal": "double_array", "twist_covariance_diagonal": "double_array",
    "open_loop": "bool", "position_feedback": "bool", "enable_odom_tf": "bool",
    "cmd_vel_timeout": "double", "publish_limited_velocity": "bool",
    "velocity_rolling_window_size": "int", "publish_rate": "double",
}
#: The same from ROS 1 ros_controllers 0.21.2 (Noetic), ``diff_drive_controller.cpp``: the
#: parameters it reads with ``param<double>`` / ``getParam`` (the covariance lists must hold
#: six doubles; a wheel is a string or a list of strings), those the exporter can write.
DDC_NOETIC_DEFINITION = {
    "left_wheel": "string_array", "right_wheel": "string_array", "publish_rate": "double",
    "wheel_separation_multiplier": "double", "left_wheel_radius_multiplier": "double",
    "right_wheel_radius_multiplier": "double", "wheel_separation": "double",
    "wheel_radius": "double", "pose_covariance_diagonal": "double_array",
    "twist_covariance_diagonal": "double_array", "base_frame_id": "string",
    "odom_frame_id": "string", "enable_odom_tf": "bool", "cmd_vel_timeout": "double",
    "open_loop": "bool", "velocity_rolling_window_size": "int",
}

# -- a reader of the YAML the exporter writes, resolving plain scalars as YAML 1.1 does ----
# (yaml-cpp in rcl_yaml_param_parser, PyYAML in rosparam): a float needs a '.', an int none
_FLOAT = re.compile(r"^[-+]?([0-9][0-9_]*)?\.[0-9.]*([eE][-+][0-9]+)?$")
_INT = re.compile(r"^[-+]?(0|[1-9][0-9_]*)$")


def _resolve(text: str) -> tuple[str, object]:
    text = text.strip()
    if text in ("true", "false"):
        return "bool", text == "true"
    if _INT.match(text):
        return "int", int(text)
    if _FLOAT.match(text):
        return "double", float(text)
    if text.startswith('"') and text.endswith('"'):
        return "string", text[1:-1]
    return "string", text


def read_yaml(text: str) -> dict:
    """Nested maps by indentation, flow sequences (also over lines), comments: each leaf a
    ``(type, value)`` with ``type`` the parameter type a ROS loader gives it."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("#")]
    joined, buf = [], ""
    for ln in lines:                                  # a flow sequence may span lines
        buf = f"{buf} {ln.strip()}" if buf else ln
        if buf.count("[") == buf.count("]"):
            joined.append(buf)
            buf = ""
    root: dict = {}
    stack = [(-1, root)]
    for ln in joined:
        indent = len(ln) - len(ln.lstrip())
        key, _, value = ln.strip().partition(":")
        while stack[-1][0] >= indent:
            stack.pop()
        if not value.strip():
            stack[-1][1][key] = {}
            stack.append((indent, stack[-1][1][key]))
        elif value.strip().startswith("["):
            items = [_resolve(v) for v in value.strip()[1:-1].split(",")]
            kinds = {k for k, _ in items}
            assert len(kinds) == 1, f"{key}: mixed types {kinds}"
            stack[-1][1][key] = (f"{kinds.pop()}_array", [v for _, v in items])
        else:
            stack[-1][1][key] = _resolve(value)
    return root


K = OdometryIntrinsics(m_per_tick_left=4.47e-4, m_per_tick_right=4.43e-4, wheel_base_m=0.2362)
URDF = """<?xml version="1.0"?>
<robot name="bot">
  <link name="base_link"/>
  <link name="left_wheel"><collision><geometry><cylinder radius="0.036" length="0.02"/>
  </geometry></collision></link>
  <link name="right_wheel"><visual><geometry><cylinder radius="0.036" length="0.02"/>
  </geometry></visual></link>
  <link name="caster"/>
  <joint name="wheel_left_joint" type="continuous"><parent link="base_link"/>
    <child link="left_wheel"/><origin xyz="0 0.1175 0.03" rpy="-1.5708 0 0"/></joint>
  <joint name="wheel_right_joint" type="continuous"><parent link="base_link"/>
    <child link="right_wheel"/><origin xyz="0 -0.1175 0.03" rpy="-1.5708 0 0"/></joint>
  <joint name="caster_joint" type="fixed"><parent link="base_link"/><child link="caster"/>
  </joint>
</robot>
"""


@pytest.fixture(scope="module")
def model(tiny_model):
    return tiny_model.with_intrinsics(K)


@pytest.fixture(scope="module")
def model_file(model, tmp_path_factory):
    return model.save(tmp_path_factory.mktemp("export") / "model_intrinsics.json")


def test_the_exporters_tables_agree_with_the_definitions_copied_here():
    for name, kind in DDC_ROS2_TYPES.items():
        assert DDC_JAZZY_DEFINITION[name] == kind, name
    for name, kind in DDC_ROS1_TYPES.items():
        assert DDC_NOETIC_DEFINITION[name] == kind, name


@pytest.mark.parametrize(("target", "definition", "path"), [
    ("diff_drive_controller", DDC_JAZZY_DEFINITION, ("diff_drive_controller", "ros__parameters")),
    ("diff_drive_controller_ros1", DDC_NOETIC_DEFINITION, ("diff_drive_controller",)),
])
@pytest.mark.parametrize("nominal", [
    Nominal(wheel_radius_m=0.036, wheel_separation_m=0.235, left_joint="wheel_left_joint",
            right_joint="wheel_right_joint", source="test"),
    Nominal(),
], ids=["nominal", "absolute"])
def test_the_yaml_loads_as_the_controllers_parameters(model, target, definition, path, nominal):
    doc = read_yaml(export_text(model, target, nominal=nominal))
    for key in path:
        doc = doc[key]
    params = {k: v for k, v in doc.items() if k != "type"}
    assert {"wheel_radius", "wheel_separation", "left_wheel_radius_multiplier",
            "right_wheel_radius_multiplier", "wheel_separation_multiplier",
            "pose_covariance_diagonal", "twist_covariance_diagonal", "publish_rate"} <= set(params)
    for name, (kind, value) in params.items():
        assert definition.get(name) == kind, f"{name}: written as {kind}"
        if kind == "double_array":
            assert len(value) == 6 and all(v > 0 for v in value), name   # no zero variance
    if nominal.left_joint:
        wheels = "left_wheel" if target.endswith("ros1") else "left_wheel_names"
        assert params[wheels] == ("string_array", ["wheel_left_joint"])


@pytest.mark.parametrize("nominal", [
    Nominal(wheel_radius_m=0.036, wheel_separation_m=0.235, ticks_per_rev=508.8),
    Nominal(wheel_radius_m=0.05, wheel_separation_m=0.30, ticks_per_rev=2048.0),
    Nominal(ticks_per_rev=1000.0),
], ids=["create2", "other", "absolute"])
def test_the_controllers_wheel_travel_is_the_calibrated_travel_per_tick(model, nominal):
    """diff_drive_controller: travel = joint angle * wheel_radius * multiplier, separation *
    multiplier; the hardware interface's angle of n ticks is n 2 pi / ticks_per_rev."""
    p = read_yaml(export_text(model, "diff_drive_controller", nominal=nominal))
    p = {k: v[1] for k, v in p["diff_drive_controller"]["ros__parameters"].items()}
    angle_per_tick = 2 * math.pi / nominal.ticks_per_rev
    left = angle_per_tick * p["wheel_radius"] * p["left_wheel_radius_multiplier"]
    right = angle_per_tick * p["wheel_radius"] * p["right_wheel_radius_multiplier"]
    base = p["wheel_separation"] * p["wheel_separation_multiplier"]
    # written with 7 significant digits: each factor within 5e-7, a product within 1e-6
    assert left == pytest.approx(K.m_per_tick_left, rel=1e-6)
    assert right == pytest.approx(K.m_per_tick_right, rel=1e-6)
    assert base == pytest.approx(K.wheel_base_m, rel=1e-6)
    if nominal.wheel_radius_m is not None:
        assert p["wheel_radius"] == nominal.wheel_radius_m
        assert p["wheel_separation"] == nominal.wheel_separation_m


def test_the_twist_variances_are_the_model_noise_over_the_publish_period(model):
    p = read_yaml(export_text(model, "diff_drive_controller", publish_rate_hz=25.0))
    p = {k: v[1] for k, v in p["diff_drive_controller"]["ros__parameters"].items()}
    scale = model.dt_s * 25.0
    assert p["twist_covariance_diagonal"][0] == pytest.approx(model.R[0, 0] * scale, rel=1e-6)
    assert p["twist_covariance_diagonal"][5] == pytest.approx(model.R[1, 1] * scale, rel=1e-6)
    assert p["pose_covariance_diagonal"][5] == pytest.approx(model.R[1, 1] * scale / 25**2,
                                                             rel=1e-6)
    assert p["publish_rate"] == 25.0


def test_robot_localization_gets_a_symmetric_15x15_per_second_process_noise(model):
    doc = read_yaml(export_text(model, "robot_localization", frequency_hz=30.0))
    p = doc["ekf_filter_node"]["ros__parameters"]
    kind, values = p["process_noise_covariance"]
    q = np.array(values).reshape(15, 15)
    assert kind == "double_array" and np.array_equal(q, q.T)
    assert np.all(np.diag(q) > 0) and np.all(np.linalg.eigvalsh(q) > 0)
    i = RL_STATE.index
    # the velocities' per-second noise times the period is the speed error over a period
    s = model.output_error_covariance(3)[2]               # 1/30 s: two 15 ms periods
    assert q[i("vx"), i("vx")] / 30.0 == pytest.approx(s[0, 0], rel=1e-6)
    assert q[i("vyaw"), i("vyaw")] / 30.0 == pytest.approx(s[1, 1], rel=1e-6)
    assert p["frequency"] == ("double", 30.0) and p["two_d_mode"] == ("bool", True)
    assert p["odom0_config"][1] == [name in ("vx", "vyaw") for name in RL_STATE]


def test_fuse_gets_the_same_numbers_in_its_eight_states(model):
    rl = read_yaml(export_text(model, "robot_localization"))["ekf_filter_node"]
    q = np.array(rl["ros__parameters"]["process_noise_covariance"][1]).reshape(15, 15)
    doc = read_yaml(export_text(model, "fuse"))
    kind, diag = doc["state_estimator"]["ros__parameters"]["unicycle_motion_model"][
        "process_noise_diagonal"]
    assert kind == "double_array" and len(diag) == len(FUSE_STATE) and min(diag) > 0
    assert diag[FUSE_STATE.index("yaw_vel")] == q[RL_STATE.index("vyaw"), RL_STATE.index("vyaw")]
    assert diag[FUSE_STATE.index("x")] == q[0, 0]


def test_the_command_line_reads_a_urdf_and_writes_the_file(model_file, tmp_path, capsys):
    urdf = tmp_path / "bot.urdf"
    urdf.write_text(URDF)
    out = tmp_path / "ddc.yaml"
    assert main(["export", "--model", str(model_file), "--to", "diff_drive_controller",
                 "--urdf", str(urdf), "--out", str(out)]) == 0
    assert f"to {out}" in capsys.readouterr().out
    p = read_yaml(out.read_text())["diff_drive_controller"]["ros__parameters"]
    assert p["left_wheel_names"] == ("string_array", ["wheel_left_joint"])
    assert p["right_wheel_names"] == ("string_array", ["wheel_right_joint"])
    assert p["wheel_separation"] == ("double", 0.235)
    assert p["wheel_radius"] == ("double", 0.036)
    assert "# nominal, from the URDF" in out.read_text()


def test_the_command_line_prints_to_stdout(model_file, capsys):
    assert main(["export", "--model", str(model_file), "--to", "fuse"]) == 0
    assert "process_noise_diagonal: [" in capsys.readouterr().out


def _one_line_error(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_model_without_intrinsics_is_refused_with_how_to_calibrate(tiny_model, tmp_path,
                                                                     capsys):
    path = tiny_model.save(tmp_path / "model_arx.json")
    line = _one_line_error(["export", "--model", str(path), "--to", "diff_drive_controller"],
                           capsys)
    assert "no odometry intrinsics" in line
    assert "lti-motion calibrate --log" in line and "--reference" in line
    assert "--wall-run" in line and "docs/intrinsics.md" in line


def test_a_urdf_without_wheel_joints_is_refused(model_file, tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text('<robot name="arm"><link name="a"/><link name="b"/><joint name="j" '
                    'type="revolute"><parent link="a"/><child link="b"/></joint></robot>')
    line = _one_line_error(["export", "--model", str(model_file), "--to",
                            "diff_drive_controller", "--urdf", str(urdf)], capsys)
    assert "no wheel joints" in line and "arm.urdf" in line


def test_an_unknown_target_is_refused(model_file, capsys):
    line = _one_line_error(["export", "--model", str(model_file), "--to", "nav2"], capsys)
    assert "unknown --to 'nav2'" in line and "robot_localization" in line


@pytest.mark.parametrize(("extra", "words"), [
    (["--publish-rate", "0"], "--publish-rate must be a positive number"),
    (["--wheel-radius", "-0.1"], "wheel_radius_m must be a positive number"),
    (["--left-joint", "a"], "give --urdf FILE"),
])
def test_other_bad_options_are_one_line(model_file, capsys, extra, words):
    line = _one_line_error(["export", "--model", str(model_file), "--to",
                            "diff_drive_controller", *extra], capsys)
    assert words in line


def test_a_model_without_measured_odometry_errors_says_so_in_the_file_and_one_line(
        model_file, capsys):
    assert main(["export", "--model", str(model_file), "--to", "diff_drive_controller"]) == 0
    out, err = capsys.readouterr()
    assert "# odometry pose error: NOT MEASURED" in out
    assert len(err.strip().splitlines()) == 1
    assert "carries no measured odometry error" in err and "upper bound" in err


def test_a_model_with_measured_odometry_errors_names_them_and_prints_no_note(
        tiny_model, tmp_path, capsys):
    from lti_motion.odometry_errors import OdometryErrors

    errors = OdometryErrors(2.3e-6, np.diag([6e-14, 6e-14, 3e-8]), 2e-7, "a test calibration")
    path = tiny_model.with_intrinsics(K, odometry_errors=errors).save(tmp_path / "m.json")
    assert main(["export", "--model", str(path), "--to", "robot_localization"]) == 0
    out, err = capsys.readouterr()
    assert "# odometry pose error: measured, a random walk of 2.3e-06 m^2" in out
    assert "a test calibration" in out and err == ""
