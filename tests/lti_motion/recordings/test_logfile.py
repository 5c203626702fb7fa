"""The recorded-log format: round trip, atomic write, damaged and foreign files."""

import json

import numpy as np
import pytest

from drivers.sim.simulator import Simulator
from lti_motion.exceptions import LogFileError
from lti_motion.recordings.logfile import LOG_VERSION, RECORDING_VERSION, load_log, save_log


@pytest.fixture
def sim_log():
    return Simulator("create2", seed=2).run(np.full((60, 2), 0.2))


def test_round_trip_is_exact(tmp_path, sim_log):
    path = save_log(tmp_path / "drive.npz", sim_log)
    again = load_log(path)
    for name in ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid", "true_pose",
                 "true_body_m_s"):
        np.testing.assert_array_equal(getattr(again, name), getattr(sim_log, name))
    assert again.dt_s == sim_log.dt_s and again.meta == json.loads(json.dumps(sim_log.meta))
    assert [p.name for p in tmp_path.iterdir()] == ["drive.npz"]     # no temporary left


def test_damaged_foreign_and_future_files_raise(tmp_path, sim_log):
    path = save_log(tmp_path / "drive.npz", sim_log)
    truncated = tmp_path / "cut.npz"
    truncated.write_bytes(path.read_bytes()[:200])
    with pytest.raises(LogFileError, match="damaged or not a log file"):
        load_log(truncated)
    foreign = tmp_path / "other.npz"
    np.savez(foreign, header=np.array(json.dumps({"format": "something-else"})))
    with pytest.raises(LogFileError, match="is not an lti-motion-log file"):
        load_log(foreign)
    future = tmp_path / "future.npz"
    np.savez(future, header=np.array(json.dumps({"format": "lti-motion-log",
                                                 "version": RECORDING_VERSION + 1})))
    with pytest.raises(LogFileError, match=f"version {RECORDING_VERSION + 1}"):
        load_log(future)
    with pytest.raises(FileNotFoundError):
        load_log(tmp_path / "missing.npz")


# -- bad input: every failure is a LogFileError naming the file, on one line ----------------
def _arrays(log):
    return {name: getattr(log, name) for name in ("t_s", "ticks", "light_bump", "bumps",
                                                  "cmd_m_s", "valid")}


def _header(**changes):
    header = {"format": "lti-motion-log", "version": LOG_VERSION, "dt_s": 0.015, "meta": {}}
    header.update(changes)
    return np.array(json.dumps(header))


def _write(path, log, header=None, **arrays):
    np.savez(path, header=_header() if header is None else header, **{**_arrays(log), **arrays})


def _text(path, log):
    path.write_text("t_s,ticks\n0.0,12\n")


def _npy(path, log):
    with open(path, "wb") as fh:
        np.save(fh, log.t_s)


def _pickled_header(path, log):
    np.savez(path, header=np.array([{"format": "lti-motion-log"}], dtype=object), **_arrays(log))


BAD_FILES = [
    ("zero bytes", lambda p, log: p.write_bytes(b""), "is empty"),
    ("a text file", _text, "not an NPZ"),
    ("a single .npy array", _npy, r"single NumPy array \(\.npy\)"),
    ("an archive without a header", lambda p, log: np.savez(p, **_arrays(log)), "no header"),
    ("a pickled header", _pickled_header, "Python objects"),
    ("a header that is a JSON list", lambda p, log: _write(p, log, np.array("[1, 2]")),
     "header is a JSON list, not an object"),
    ("a header that is not JSON", lambda p, log: _write(p, log, np.array("{dt_s: 1")),
     "header is not valid JSON"),
    ("a numeric header", lambda p, log: _write(p, log, np.array(5.0)), "header is not a JSON"),
    ("a header without dt_s", lambda p, log: _write(
        p, log, np.array(json.dumps({"format": "lti-motion-log", "version": 1}))),
     "header lacks dt_s"),
    ("a negative dt_s", lambda p, log: _write(p, log, _header(dt_s=-0.015)), "dt_s = -0.015"),
    ("a dt_s that is text", lambda p, log: _write(p, log, _header(dt_s="15 ms")),
     "dt_s = '15 ms'"),
    ("meta that is a list", lambda p, log: _write(p, log, _header(meta=[1])),
     "meta is a JSON list"),
    ("zero frames", lambda p, log: _write(p, log.window(0, 0)), "holds no frames"),
    ("meta.landmarks that is not a list", lambda p, log: _write(
        p, log, _header(meta={"landmarks": 5, "observations": [[1, 7, 2.0, 0.1]]})),
     r"meta\.landmarks is a JSON number; expected a list of \[id, x_m, y_m\] rows"),
    ("meta.landmarks rows that are not rows", lambda p, log: _write(
        p, log, _header(meta={"landmarks": "abc", "observations": [[1, 7, 2.0, 0.1]]})),
     r"meta\.landmarks is a JSON string"),
    ("an observation row too short", lambda p, log: _write(
        p, log, _header(meta={"landmarks": [[7, 1.0, 2.0]], "observations": [[1, 7, 2.0]]})),
     r"row 0 of its meta\.observations is \[1, 7, 2\.0\]"),
    ("an observation at a fractional frame", lambda p, log: _write(
        p, log, _header(meta={"landmarks": [[7, 1.0, 2.0]], "observations": [[1.5, 7, 2, 0]]})),
     r"row 0 of its meta\.observations"),
    ("ticks of the wrong shape", lambda p, log: _write(p, log, ticks=log.ticks[:, :1]),
     r"ticks has shape \(40, 1\); expected \(40, 2\)"),
    ("commands as text", lambda p, log: _write(p, log, cmd_m_s=log.cmd_m_s.astype(str)),
     r"cmd_m_s holds <U\d+ values; expected numbers"),
    ("valid flags as floats", lambda p, log: _write(p, log, valid=log.valid + 0.5),
     "valid holds float64 values; expected flags"),
    ("a NaN time", lambda p, log: _write(p, log, t_s=np.where(np.arange(40) == 7, np.nan,
                                                            log.t_s)),
     r"frame 7 has no valid time \(t_s = nan\)"),
    ("a time that goes backwards", lambda p, log: _write(
        p, log, t_s=np.where(np.arange(40) == 12, log.t_s[5], log.t_s)),
     r"time goes backwards at frame 12, t_s = 0\.0\d{5} s after 0\.1\d{5} s at frame 11"),
    ("a reversed log", lambda p, log: _write(p, log, t_s=log.t_s[::-1].copy()),
     "time goes backwards at frame 1, .* it goes back 39 times"),
]


@pytest.mark.parametrize("label, make, match", BAD_FILES, ids=[c[0] for c in BAD_FILES])
def test_bad_files_raise_one_line_log_file_errors(tmp_path, sim_log, label, make, match):
    path = tmp_path / "bad.npz"
    make(path, sim_log.window(0, 40))
    with pytest.raises(LogFileError, match=match) as exc:
        load_log(path)
    message = str(exc.value)
    assert isinstance(exc.value, ValueError)
    assert str(path) in message and "\n" not in message
    assert "pickle" not in message.lower()           # never an invitation to load one


def test_integer_flags_load_as_booleans(tmp_path, sim_log):
    log = sim_log.window(0, 40)
    path = tmp_path / "flags.npz"
    _write(path, log, valid=log.valid.astype(np.uint8), bumps=log.bumps.astype(np.int64))
    again = load_log(path)
    assert again.valid.dtype == bool and again.bumps.dtype == bool
    np.testing.assert_array_equal(again.valid, log.valid)


def test_every_truncation_and_bit_flip_is_a_log_file_error(tmp_path, sim_log):
    """Whatever zipfile, zlib or numpy raise inside, the caller sees one LogFileError."""
    data = save_log(tmp_path / "drive.npz", sim_log.window(0, 20)).read_bytes()
    rng = np.random.default_rng(5)
    flips = []
    for _ in range(600):
        blob = bytearray(data)
        byte = int(rng.integers(len(blob)))
        blob[byte] ^= 1 << int(rng.integers(8))
        flips.append(bytes(blob))
    path = tmp_path / "bad.npz"
    loaded = 0
    for blob in [data[:cut] for cut in range(0, len(data), 3)] + flips:
        path.write_bytes(blob)
        try:
            load_log(path)
            loaded += 1
        except LogFileError as exc:
            assert "\n" not in str(exc) and "pickle" not in str(exc).lower(), str(exc)
    assert loaded < len(flips) // 2                     # most flips are caught, none escapes


def test_a_batch_log_names_the_robot_whose_time_goes_backwards(tmp_path):
    log = Simulator("create2", n_robots=3, seed=1).run(np.full((3, 30, 2), 0.1))
    t = log.t_s.copy()
    t[2, 20] = t[2, 3]
    path = tmp_path / "batch.npz"
    _write(path, log, t_s=t)
    with pytest.raises(LogFileError, match="time goes backwards at robot 2's frame 20"):
        load_log(path)
