"""Bad input on the command line: one line naming the file and the problem, exit code 2.

The README's promise, checked for damaged, foreign and inconsistent logs and
model files given to ``lti-motion replay``.
"""

import json

import numpy as np
import pytest

from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.recordings.logfile import save_log


@pytest.fixture(scope="module")
def files(tmp_path_factory, tiny_model):
    """A model file and a short simulated log (the model need not be good here)."""
    folder = tmp_path_factory.mktemp("cli")
    model = tiny_model
    log = Simulator("create2", seed=0).run(np.full((50, 2), 0.1))
    return {"model": model.save(folder / "model.json"), "log": log,
            "good": save_log(folder / "good.npz", log)}


def _npz(path, log, header=None, **changes):
    arrays = {name: getattr(log, name) for name in ("t_s", "ticks", "light_bump", "bumps",
                                                    "cmd_m_s", "valid")}
    if header is None:
        header = {"format": "lti-motion-log", "version": 1, "dt_s": 0.015, "meta": {}}
    np.savez(path, header=np.array(json.dumps(header)), **{**arrays, **changes})


def _reversed(path, log):
    _npz(path, log, t_s=log.t_s[::-1].copy())


def _nan_time(path, log):
    t = log.t_s.copy()
    t[10] = np.nan
    _npz(path, log, t_s=t)


def _repeated_time(path, log):
    t = log.t_s.copy()
    t[21] = t[20]
    _npz(path, log, t_s=t)


CASES = [
    ("a zero-byte file", lambda p, log: p.write_bytes(b""), "is empty (0 bytes)"),
    ("a header that is a JSON list", lambda p, log: _npz(p, log, header=[1, 2]),
     "header is a JSON list"),
    ("a header without dt_s", lambda p, log: _npz(p, log, header={"format": "lti-motion-log",
                                                                  "version": 1}),
     "header lacks dt_s"),
    ("zero frames", lambda p, log: save_log(p, log.window(0, 0)), "holds no frames"),
    ("meta.landmarks that is not a list", lambda p, log: _npz(
        p, log, header={"format": "lti-motion-log", "version": 1, "dt_s": 0.015,
                        "meta": {"landmarks": "L1", "observations": [[3, "L1", 1.0, 0.0]]}}),
     "meta.landmarks is a JSON string"),
    ("a text file", lambda p, log: p.write_text("frame,t_s\n0,0.0\n"),
     "not an NPZ (zip) archive"),
    ("a reversed log", _reversed, "time goes backwards at frame 1"),
    ("a NaN time", _nan_time, "frame 10 has no valid time"),
    ("a repeated time", _repeated_time, "frame 21 has the time of frame 20"),
]


@pytest.mark.parametrize("label, make, message", CASES, ids=[c[0] for c in CASES])
def test_replay_of_a_bad_log_prints_one_line_and_exits_2(files, tmp_path, capsys, label, make,
                                                         message):
    bad = tmp_path / "bad.npz"
    make(bad, files["log"])
    assert main(["replay", str(bad), "--model", str(files["model"]),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("lti-motion replay: error: "), err
    assert bad.name in err and message in err
    assert "Traceback" not in err and "pickle" not in err.lower()
    assert not (tmp_path / "out").exists()                # refused before any estimator ran


def test_replay_with_a_damaged_model_file_prints_one_line(files, tmp_path, capsys):
    from lti_motion.persistence import _digest

    doc = json.loads(files["model"].read_text())
    doc["matrices"] = 5                                  # consistent checksum, wrong content
    doc.pop("sha256")
    doc["sha256"] = _digest(doc)
    bad = tmp_path / "model.json"
    bad.write_text(json.dumps(doc))
    assert main(["replay", str(files["good"]), "--model", str(bad),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and "lacks the keys" in err
    assert "MotionModel" not in err                      # no internal names for a user


def test_an_error_message_with_line_breaks_is_printed_on_one_line(files, tmp_path, capsys,
                                                                  monkeypatch):
    import lti_motion.app.replay as replay

    def fails(*args, **kwargs):
        raise ValueError("first part\n  second part")

    monkeypatch.setattr(replay, "run_replay", fails)
    assert main(["replay", str(files["good"]), "--model", str(files["model"])]) == 2
    assert capsys.readouterr().err == "lti-motion replay: error: first part second part\n"
