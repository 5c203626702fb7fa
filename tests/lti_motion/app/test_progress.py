"""Progress on the long silent steps (issue 28, item 8): the library's callbacks, and the
command line's one transient status line on standard error."""

import io
import sys

import numpy as np

from drivers.sim.config import get_preset
from lti_motion.app.cli import main
from lti_motion.app.progress import StatusLine
from lti_motion.app.route import Odometry, drive_route

P = get_preset("create2")


def test_the_status_line_is_rewritten_in_place_and_wiped_before_output(capsys):
    err = io.StringIO()
    status = StatusLine(err, always=True)
    status.route("EKF", 3.0, 0, 30)
    status.route("EKF", 6.0, 1, 30)
    status.print("   EKF closure 0.012 m")
    shown = err.getvalue()
    assert shown.startswith("\r   EKF: 3 s of the route driven, 0 of 30 robots home")
    assert "\r   EKF: 6 s of the route driven, 1 of 30 robots home" in shown
    assert shown.endswith("\r" + " " * len("   EKF: 6 s of the route driven, 1 of 30 robots "
                                           "home") + "\r")            # wiped
    assert capsys.readouterr().out == "   EKF closure 0.012 m\n"    # the output unchanged


def test_no_status_where_the_stream_is_no_terminal():
    err = io.StringIO()                                   # isatty() is false
    StatusLine(err).phase_one("encoder NIS", 1, 20)
    assert err.getvalue() == ""


def test_drive_route_reports_route_time_and_robots_home_to_the_end():
    calls = []
    est = Odometry(m_per_tick=np.pi * P.wheel_diameter_m / P.ticks_per_rev,
                   wheel_base_m=P.wheel_base_m)
    result = drive_route(P, est, seeds=[1, 2], progress=lambda *a: calls.append(a))
    assert result.finished.all()
    times = [t for t, _, _ in calls]
    assert times == sorted(times) and times[0] > 0 and len(calls) > 5
    assert calls[-1] == (result.true_poses.shape[1] * P.period_s, 2, 2)   # the end: all home
    assert all(n == 2 for _, _, n in calls)


def test_monitor_shows_phase_one_on_a_terminal_and_prints_the_same_lines(tiny_model, tmp_path,
                                                                         monkeypatch, capsys):
    model = str(tiny_model.save(tmp_path / "model_arx.json"))
    argv = ["monitor", "--robot", "create2", "--model", model, "--duration", "40",
            "--nominal-drives", "2"]
    assert main(argv) == 0
    quiet = capsys.readouterr()
    assert quiet.err == ""                                # no terminal: nothing shown
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(argv) == 0
    shown = capsys.readouterr()
    assert shown.out == quiet.out
    assert "\r  phase I: encoder NIS of nominal drive 2 of 2 ..." in shown.err
    assert "\r  phase I: fitting the dynamics null (maximum likelihood) ..." in shown.err
    assert shown.err.endswith("\r")                       # wiped before the drive's lines
