"""The health gate of ``calibrate --bag`` and ``--log``: a held-out span, the healthy fit,
the order and delay at their range's edge, ``--dt`` against the recording's period, and a
damaged MCAP bag, each refusal one line with exit code 2."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from drivers.bags.integrity import mcap_damage
from drivers.bags.writer import write_drive_bag
from drivers.sim.config import Fault
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.calibration import calibrate_recording
from lti_motion.model.excitation import random_held_normal
from lti_motion.recordings import Recording

START_NS = 1_750_000_000 * 1_000_000_000


def _excitation(seed: int, n: int) -> np.ndarray:
    return random_held_normal(n=n, dt_s=0.015, rng=np.random.default_rng(seed), std_m_s=0.2,
                              mean_m_s=0.05, hold_s=(0.5, 2.0), correlation=0.85)


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A 45 s excitation drive of the simulated Create 2, 2 % of its frames lost, as an
    MCAP bag."""
    folder = tmp_path_factory.mktemp("health")
    log = Simulator("create2", seed=11, faults=[Fault("lost_frames", t_s=0.0,
                                                      probability=0.02)]).run(_excitation(1, 3000))
    return {"folder": folder, "log": log,
            "bag": write_drive_bag(folder / "cal", log, start_ns=START_NS)}


def _one_line_refusal(capsys, *words: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("lti-motion calibrate: error:"), err
    for word in words:
        assert word in err, err
    return err


def test_an_unhealthy_model_is_refused_and_not_written(drive, tmp_path, capsys):
    """Measured: held-out (last 20 %, 36.0-45.0 s) fit v 83.4 %, w 82.3 %: below 85 %."""
    out = tmp_path / "o"
    assert main(["calibrate", "--bag", str(drive["bag"]),
                 "--robot", "create2", "--out", str(out)]) == 2
    printed = capsys.readouterr()
    assert "on the held-out 36.0-45.0 s (never fitted)" in printed.out
    assert "condition of the regression" in printed.out            # the excitation report
    assert printed.err.count("\n") == 1 and "below the healthy 85%" in printed.err
    assert "--accept-unhealthy" in printed.err
    assert not (out / "model_arx.json").exists() and (out / "excitation.txt").is_file()
    assert main(["calibrate", "--bag", str(drive["bag"]), "--robot", "create2", "--out", str(out),
                 "--accept-unhealthy"]) == 0
    assert "saving an unhealthy model as --accept-unhealthy asks" in capsys.readouterr().out
    assert (out / "model_arx.json").is_file()


def test_the_user_names_the_held_out_window(drive, tmp_path, capsys):
    assert main(["calibrate", "--bag", str(drive["bag"]),
                 "--robot", "create2", "--out", str(tmp_path / "o"),
                 "--start-s", "10", "--duration-s", "10", "--accept-unhealthy"]) == 0
    assert "on the held-out 10.0-20.0 s (never fitted)" in capsys.readouterr().out
    assert main(["calibrate", "--bag", str(drive["bag"]),
                 "--robot", "create2", "--out", str(tmp_path / "p"),
                 "--start-s", "60"]) == 2
    _one_line_refusal(capsys, "--start-s 60", "45.0 s drive")


def test_a_period_far_from_the_recordings_own_is_refused(drive, tmp_path, capsys):
    assert main(["calibrate", "--bag", str(drive["bag"]),
                 "--robot", "create2", "--out", str(tmp_path / "o"),
                 "--dt", "0.1"]) == 2
    _one_line_refusal(capsys, "--dt 100 ms", "15.01 ms", "/joint_states")
    assert not (tmp_path / "o" / "model_arx.json").exists()


def test_a_log_is_held_out_and_gated_too(drive, tmp_path, capsys):
    from lti_motion.recordings import save_recording

    path = save_recording(tmp_path / "drive.npz", Recording.from_frame_log(drive["log"]))
    assert main(["calibrate", "--log", str(path), "--robot", "create2",
                 "--out", str(tmp_path / "o")]) == 2
    printed = capsys.readouterr()
    assert "condition of the regression" in printed.out and "held-out" in printed.out
    assert printed.err.count("\n") == 1 and "unhealthy" in printed.err
    assert not (tmp_path / "o" / "model_arx.json").exists()


@pytest.mark.parametrize(("delays", "widened", "at_edge"), [
    (range(0, 3), True, True),      # 2 chosen, widened to 0-4: the true 4 is its top again
    (range(0, 4), True, False),     # 3 chosen, widened to 0-6: the true 4 inside it
    (range(0, 9), False, False),    # the default range holds the simulator's delay
])
def test_a_delay_at_the_top_of_its_range_widens_it_or_is_flagged(drive, delays, widened,
                                                                    at_edge):
    """The simulated Create 2 answers its commands 4 periods late."""
    rec = Recording.from_frame_log(drive["log"])
    cal = calibrate_recording(rec, wheel_base_m=0.235, m_per_tick=np.pi * 0.072 / 508.8,
                              encoders="commanded", orders=range(1, 4), delays=delays,
                              held_out_s=(36.0, 45.0))
    assert bool(cal.widened) == widened and bool(cal.at_edge) == at_edge
    if widened and not at_edge:
        assert cal.model.orders["delay"] == 4
    if at_edge:
        assert "delay 4 is the top of the delays tried (0-4)" in cal.at_edge[0]


def test_a_bag_with_4_kib_zeroed_mid_file_is_refused(drive, tmp_path, capsys):
    bag = shutil.copytree(drive["bag"], tmp_path / "damaged")
    mcap = next(bag.glob("*.mcap"))
    assert mcap_damage(mcap) is None                               # whole before
    data = bytearray(mcap.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 4096] = bytes(4096)
    mcap.write_bytes(bytes(data))
    found = mcap_damage(mcap)
    assert found is not None and middle - 70_000 < found.offset <= middle + 4096
    assert main(["calibrate", "--bag", str(bag), "--robot", "create2", "--out", str(tmp_path / "o"),
                 "--accept-unhealthy"]) == 2
    _one_line_refusal(capsys, "damaged at byte", "into the bag")
    assert not (tmp_path / "o" / "model_arx.json").exists()


@pytest.mark.parametrize("offset", [0, 100_000, -200_000])
def test_a_ros1_bag_with_4_kib_zeroed_is_refused(drive, tmp_path, capsys, offset):
    """ROS 1 bags have no checksums: the record lengths and opcodes rosbags reads break."""
    bag = write_drive_bag(tmp_path / "drive.bag", drive["log"], start_ns=START_NS)
    data = bytearray(bag.read_bytes())
    at = len(data) // 2 + offset
    data[at:at + 4096] = bytes(4096)
    bag.write_bytes(bytes(data))
    assert main(["calibrate", "--bag", str(bag), "--robot", "create2", "--out", str(tmp_path / "o"),
                 "--accept-unhealthy"]) == 2
    _one_line_refusal(capsys, "drive.bag is damaged: its messages cannot be read")


def test_a_log_with_a_far_period_is_refused(drive, tmp_path, capsys):
    from lti_motion.recordings import save_recording

    path = save_recording(tmp_path / "drive.npz", Recording.from_frame_log(drive["log"]))
    assert main(["calibrate", "--log", str(path), "--robot", "create2", "--dt", "0.1",
                 "--out", str(tmp_path / "o")]) == 2
    _one_line_refusal(capsys, "--dt 100 ms", "its wheel stamps")


@pytest.mark.parametrize(("argv", "words"), [
    (["--duration-s", "-5"], ("--duration-s must be a positive number",)),
    (["--start-s", "-1"], ("--start-s must be 0 or more",)),
    (["--start-s", "44.9"], ("shorter than 5 s",)),
])
def test_a_held_out_window_that_cannot_measure_is_refused(drive, tmp_path, capsys, argv,
                                                          words):
    assert main(["calibrate", "--bag", str(drive["bag"]),
                 "--robot", "create2", "--out", str(tmp_path / "o"),
                 *argv]) == 2
    _one_line_refusal(capsys, *words)
