"""The MRCLAM reader on the real files (found through LTI_MOTION_DATA, docs/mrclam.md)."""

import itertools

import numpy as np
import pytest

from drivers.datasets import load_mrclam, resample_robot
from drivers.exceptions import DatasetError


@pytest.fixture(scope="module")
def dataset(mrclam_path):
    return load_mrclam(mrclam_path)


def test_reads_all_robots_landmarks_and_sightings(dataset):
    assert sorted(dataset.robots) == [1, 2, 3, 4, 5]
    assert sorted(dataset.landmarks) == list(range(6, 21))
    for robot in dataset.robots.values():
        assert robot.commands.shape[1] == 3 and len(robot.commands) > 50_000
        assert 0.0 <= robot.commands[:, 1].min() and robot.commands[:, 1].max() <= 0.09
        # sightings of robots and of unknown barcodes are dropped
        assert np.all(np.isin(robot.sightings[:, 1], list(range(6, 21))))
        assert np.all(np.diff(robot.groundtruth[:, 0]) > 0)


def test_resampled_speeds_follow_the_commands_with_lag_and_gain(dataset):
    """The motion lags the commands (the data README: 0.15-0.2 s) and falls short of them.

    The median true v while v is commanded at its maximum is about 0.6 of the command
    here: that includes sharp turns, where the wheels saturate and forward speed drops,
    so it is lower than the README's regression gain of 0.86-0.93.
    """
    segments = resample_robot(dataset.robots[2], dt_s=0.1)
    assert sum(len(s.t_s) for s in segments) * 0.1 > 800
    seg = max(segments, key=lambda s: len(s.t_s))
    cmd, true = seg.commands_vw[:, 0], seg.speeds_vw[:, 0]
    lags = range(0, 6)
    corr = [np.corrcoef(cmd[: len(cmd) - k], true[k:])[0, 1] for k in lags]
    assert 1 <= int(np.argmax(corr)) <= 3                       # 0.1-0.3 s
    moving = cmd > 0.08
    gain = np.median(true[moving]) / np.median(cmd[moving])
    assert 0.5 < gain < 0.97


def test_gaps_split_segments(dataset):
    """Robot 4's ground truth has two gaps of about 2 s."""
    segments = resample_robot(dataset.robots[4], dt_s=0.1)
    assert len(segments) >= 3
    for a, b in itertools.pairwise(segments):
        assert b.t_s[0] - a.t_s[-1] > 0.25


def test_missing_folder_names_the_file(tmp_path):
    with pytest.raises(DatasetError, match=r"missing dataset file .*Barcodes\.dat"):
        load_mrclam(tmp_path)
