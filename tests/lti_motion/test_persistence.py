"""Atomic writes: whole or not at all, with the permissions a plain ``open`` gives."""

import os
import stat

import numpy as np
import pytest

from drivers.sim.simulator import Simulator
from lti_motion.persistence import atomic_write, read_document, write_document
from lti_motion.recordings.logfile import save_log

posix = pytest.mark.skipif(os.name != "posix", reason="file modes and the umask are POSIX")


@pytest.fixture
def umask():
    """Set the process umask for one test, and put the old one back."""
    old = os.umask(0o022)
    yield os.umask
    os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def _writers(folder):
    """Every way the package writes a file, plus a plain ``open`` to compare with."""
    log = Simulator("create2", seed=0).run(np.full((5, 2), 0.1))
    return {
        "open": lambda: (folder / "plain.txt").write_text("x") and folder / "plain.txt",
        "atomic_write": lambda: _atomic(folder / "atomic.bin"),
        "write_document": lambda: write_document(folder / "doc.json", {"a": 1}, fmt="t",
                                                 version=1),
        "save_log": lambda: save_log(folder / "log.npz", log),
    }


def _atomic(path):
    with atomic_write(path) as f:
        f.write(b"x")
    return path


@posix
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002, 0o027])
def test_new_files_get_the_mode_open_gives_under_the_umask(tmp_path, umask, mask):
    umask(mask)
    modes = {name: _mode(write()) for name, write in _writers(tmp_path).items()}
    assert set(modes.values()) == {0o666 & ~mask}, modes          # 0o600 whatever the umask before
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


@posix
def test_writing_over_a_file_keeps_its_mode_as_open_does(tmp_path, umask):
    umask(0o022)
    path = write_document(tmp_path / "doc.json", {"a": 1}, fmt="t", version=1)
    os.chmod(path, 0o640)
    write_document(path, {"a": 2}, fmt="t", version=1)
    assert _mode(path) == 0o640 and read_document(path, fmt="t", versions=(1,))["a"] == 2


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "doc.json"
    path.write_text("old")
    with pytest.raises(RuntimeError, match="disk full"), atomic_write(path, text=True) as f:
        f.write("new, half")
        raise RuntimeError("disk full")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["doc.json"]


@pytest.mark.parametrize(("first_bytes", "said"), [
    (b"PK\x03\x04rest of a zip", "is a NumPy .npz archive (a recorded log?)"),
    (b"#ROSBAG V2.0\n", "is a ROS 1 bag"),
    (b"\x89MCAP0\r\n", "is an MCAP (ROS 2) bag"),
    (b"SQLite format 3\x00", "is an SQLite (ROS 2) bag"),
])
def test_another_kind_of_file_is_named_for_what_it_is_not_called_damaged(tmp_path, first_bytes,
                                                                        said):
    path = tmp_path / "given_as_a_model"
    path.write_bytes(first_bytes)
    with pytest.raises(ValueError, match="not a 'demo' file") as info:
        read_document(path, fmt="demo", versions=(1,))
    assert said in str(info.value) and "damaged" not in str(info.value)


def test_a_real_log_given_as_a_document_is_named_a_log(tmp_path):
    path = tmp_path / "drive.npz"
    save_log(path, Simulator("create2", seed=1).run(np.full((20, 2), 0.1)))
    with pytest.raises(ValueError, match=r"NumPy \.npz archive \(a recorded log\?\)"):
        read_document(path, fmt="demo", versions=(1,))
