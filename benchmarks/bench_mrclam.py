"""MRCLAM set 6, the tables of docs/mrclam.md as records.

Per robot: the ARX model calibrated on the first half of its run
(:func:`lti_motion.app.mrclam.evaluate_robot`), scored on the second half
against the commands taken at face value:

- ``mrclam.dead_reckoning_30s_ratio_r<N>``: median end-of-window position error
  of 30 s sensor-less dead reckoning, ARX / raw; ``..._max`` and ``..._median``
  over the five robots (targets 0.8 and 0.75).
- ``mrclam.ekf_landmarks_ratio_r<N>``: RMS position error of the landmark EKFs,
  model / raw (:func:`lti_motion.app.mrclam_filters.evaluate_filters`, long-run
  noise rule); ``..._mean`` and ``..._max`` (targets 0.85 and 0.95).
- ``mrclam.smoother_over_ekf_r<N>``: RMS of the model-driven batch smoother
  (:func:`lti_motion.app.mrclam_graph.evaluate_graph`) over the model EKF's;
  ``..._max`` (target 1.05: the smoother never more than 5% worse).
- ``mrclam.free_run_fit_w_r<N>``: the ARX model's free-run fit of w [%] on the
  second half (no target; context).

The ARX model is the one :data:`CRITERION` gives (``"selected"``: per robot, the
candidate structure with the least first-half cross-validated 30 s path error, by the
rules of docs/mrclam.md). The data are found through ``LTI_MOTION_DATA`` (default: the
data folder beside the working directory), as the tests do. About 2 minutes for all five robots on a
quiet machine (the selection fits 14 candidates x 3 folds per robot).
"""

from __future__ import annotations

import os
import statistics
from pathlib import Path

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.datasets import load_mrclam
from lti_motion.app.mrclam import evaluate_robot
from lti_motion.app.mrclam_filters import evaluate_filters
from lti_motion.app.mrclam_graph import evaluate_graph

ROBOTS = (1, 2, 3, 4, 5)
#: The ARX model's fit criterion (:func:`lti_motion.app.mrclam.evaluate_robot`), chosen by
#: the rules of docs/mrclam.md on the first half.
CRITERION = "selected"


def dataset_path() -> Path:
    """MRCLAM set 6 under ``LTI_MOTION_DATA`` (default: the data beside the working directory)."""
    root = Path(os.environ.get("LTI_MOTION_DATA", "../shared/data"))
    path = root / "mrclam" / "MRCLAM_Dataset6"
    if not path.is_dir():
        raise SystemExit(f"MRCLAM set 6 not found at {path}; set LTI_MOTION_DATA to the "
                         "shared data folder")
    return path


def robot_ratios(robot, landmarks, *, criterion: str = CRITERION) -> dict[str, float]:
    """One robot's ratios (module docstring) and the ARX free-run fit of w [%]."""
    res = evaluate_robot(robot, criterion=criterion)
    dr = float(np.median(res.end_position_m["arx"]) / np.median(res.end_position_m["raw"]))
    ekf = evaluate_filters(robot, landmarks, res.arx)
    graph = evaluate_graph(robot, landmarks, res.arx)
    return {"dead_reckoning_30s_ratio": dr,
            "ekf_landmarks_ratio": ekf.rms_m["model"] / ekf.rms_m["raw"],
            "smoother_over_ekf": graph.rms_m["model"] / ekf.rms_m["model"],
            "free_run_fit_w": float(res.fit["arx"][1])}


@benchmark("mrclam")
def mrclam(criterion: str = CRITERION) -> list[Figure]:
    data = load_mrclam(dataset_path())
    per = {r: robot_ratios(data.robots[r], data.landmarks, criterion=criterion)
           for r in ROBOTS}
    figs: list[Figure] = []
    for r in ROBOTS:
        p = per[r]
        figs += [
            Figure(f"mrclam.dead_reckoning_30s_ratio_r{r}", p["dead_reckoning_30s_ratio"], "x",
                   target=0.8, better="lower"),
            Figure(f"mrclam.ekf_landmarks_ratio_r{r}", p["ekf_landmarks_ratio"], "x",
                   target=0.95, better="lower"),
            Figure(f"mrclam.smoother_over_ekf_r{r}", p["smoother_over_ekf"], "x",
                   target=1.05, better="lower"),
            Figure(f"mrclam.free_run_fit_w_r{r}", p["free_run_fit_w"], "%"),
        ]
    dr = [per[r]["dead_reckoning_30s_ratio"] for r in ROBOTS]
    ekf = [per[r]["ekf_landmarks_ratio"] for r in ROBOTS]
    figs += [
        Figure("mrclam.dead_reckoning_30s_ratio_max", max(dr), "x", target=0.8, better="lower"),
        Figure("mrclam.dead_reckoning_30s_ratio_median", statistics.median(dr), "x",
               target=0.75, better="lower"),
        Figure("mrclam.ekf_landmarks_ratio_mean", statistics.fmean(ekf), "x", target=0.85,
               better="lower"),
        Figure("mrclam.ekf_landmarks_ratio_max", max(ekf), "x", target=0.95, better="lower"),
        Figure("mrclam.smoother_over_ekf_max", max(per[r]["smoother_over_ekf"] for r in ROBOTS),
               "x", target=1.05, better="lower"),
    ]
    return figs
