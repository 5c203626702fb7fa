"""What ``lti-motion monitor`` prints a person: alarm lines, the summary, and the guide's
figures against the code's (``lti_motion.app.monitor``, ``docs/guide_alarms.md``)."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from fusion.monitoring.dynamics import START_THRESHOLD, DynamicsAlarm
from fusion.monitoring.residual import MonitorOptions, design_thresholds
from fusion.monitoring.scale import ScaleOptions
from lti_motion.app.monitor import MonitorRun, dynamics_detail, heading_deg

GUIDE = Path(__file__).resolve().parents[3] / "docs" / "guide_alarms.md"


def test_a_lag_is_printed_only_when_it_means_something():
    # a covariance alarm after windows without transients: sum b ~ 0, the lag is noise
    cov = DynamicsAlarm(0, "covariance", 13.0, 12.0, 20.0, 290496329.5, 2.0e4)
    assert dynamics_detail(cov) == "(covariance test)"
    assert dynamics_detail(DynamicsAlarm(0, "lag", 9.0, 6.4, 20.0, 2.41, 0.31)) == (
        "(lag test, lag 2.4 +- 0.3 periods)")
    # a lag test alarm whose lag is known to worse than a period: no lag either
    assert dynamics_detail(DynamicsAlarm(0, "lag", 9.0, 6.4, 20.0, 7.0, 1.5)) == "(lag test)"
    assert dynamics_detail(DynamicsAlarm(0, "lag", 9.0, 6.4, 20.0, math.nan)) == "(lag test)"


@pytest.mark.parametrize(("deg", "wrapped"), [(447.0, 87.0), (-180.0, 180.0), (180.0, 180.0),
                                              (-190.0, 170.0), (-720.5, -0.5)])
def test_heading_is_wrapped(deg, wrapped):
    assert heading_deg(math.radians(deg)) == pytest.approx(wrapped, abs=1e-9)


def test_summary_names_the_two_gates_and_wraps_the_heading():
    run = MonitorRun(frames=400, duration_s=6.0, counts={"samples": 333, "glitches": 0,
                                                         "missing": 0, "startup": 66},
                     glitch_gate_nis=2667.0, encoders_gated=16, fusion_gate_nis=13.8155,
                     final_pose=np.array([1.0, 0.5, math.radians(447.0)]))
    text = "\n".join(run.summary())
    gates = next(line for line in run.summary() if "gate" in line)
    assert "0 glitches above the monitor's glitch gate (NIS 2667" in gates
    assert "16 readings not fused by the EKF (its own fusion gate, NIS 13.8" in gates
    assert "66 left untested after starts from rest" in text
    assert "heading 87.0 deg" in text and "447" not in text


# -- the guide prints what the code prints ----------------------------------------------------
def _guide_sample() -> str:
    text = GUIDE.read_text()
    return text.split("Alarm lines, and the summary at the end:")[1].split("```text")[1] \
        .split("```")[0]


def test_the_guides_thresholds_are_the_codes():
    text = GUIDE.read_text()
    sample = _guide_sample()
    tests_line = next(line for line in sample.splitlines() if line.startswith("tests:"))
    m = re.search(r"glitch gate NIS (\d+) \(([\d.]+) x the nominal maximum (\d+)\).*"
                  r"lag ([\d.]+) \(from the nominal drives\), covariance ([\d.]+), "
                  r"start ([\d.]+)", tests_line)
    assert m, tests_line
    gate, factor, peak, lag, cov, start = (float(g) for g in m.groups())
    # fixed thresholds: the code's
    assert start == pytest.approx(START_THRESHOLD)
    from fusion.monitoring.cusum import cusum_llr_threshold
    windows_per_hour = 3600.0 / (0.015 * 30)
    assert cov == pytest.approx(round(cusum_llr_threshold(windows_per_hour, 0.05), 1))
    scale = float(re.search(r"scale test on 4 landmarks at 2 Hz \(threshold ([\d.]+)\)",
                            sample).group(1))
    assert scale == pytest.approx(round(ScaleOptions().threshold, 1))
    # Phase-I thresholds: the gate is the rule's, every alarm line's threshold the lag's
    assert factor == 10.0 and gate == pytest.approx(factor * peak, abs=factor)
    alarm_thresholds = {float(t) for t in re.findall(r"\(threshold ([\d.]+)\)", sample)
                        if "scale" not in t}
    assert lag in alarm_thresholds
    # the table quotes the same figures: the example's Phase-I ones and the code's fixed ones
    th = design_thresholds(MonitorOptions())
    table = text.split("## The kinds, and what to do")[1].split("## ")[0]
    for figure in (f"{gate:,.0f}", f"{lag:.2f}", f"{start:.2f}", f"{cov:.1f}",
                   f"{th.gate:.1f}", f"{th.nis_bound:.1f}", f"{th.cusum_h:.1f}",
                   f"{scale:.1f}"):
        assert figure in table, figure
