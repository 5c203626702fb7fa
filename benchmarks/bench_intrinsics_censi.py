"""Benchmark ``intrinsics_censi``: the intrinsics calibration on Censi et al.'s own data.

Issue 32. A Khepera III with a laser scanner off its axle (Censi, Franchi, Marchionni,
Oriolo, IEEE T-RO 29(2), 2013; ``real/censi2013`` under ``LTI_MOTION_DATA``). Every
configuration whose ``X_results.json`` is in the folder (``lstraight`` and ``l90`` here;
another configuration dropped in runs the same way), each whole run ``X`` and its subsets
``X_i``, raw, calibrated as ``lti-motion calibrate --reference X.tuple --sensor-pose`` does
(:func:`lti_motion.calibration.calibrate_intrinsics_intervals` with its defaults and
``sensor_pose=True``), against the authors' published results.

Figures (worst over all runs):

``intrinsics_censi.axle_error_pct``, ``..._diameter_error_pct``
    ``|ours / authors - 1|`` [%] of the axle and of either wheel's diameter (target 0.3).
``intrinsics_censi.laser_heading_error_deg``, ``..._laser_xy_error_mm``
    The laser's heading (target 0.5 deg) and position (target 2 mm) on the robot.
``intrinsics_censi.unit_change_pct``
    The largest relative change of the axle, scales (per count) and laser pose when the
    counts are given in units 10x finer and 10x coarser (target 0.01).
``intrinsics_censi.raw_axle_error_pct``
    The same without outlier rounds (no target; the issue's 4-16% before).
``intrinsics_censi.std_over_subset_spread_min``, ``..._max``
    Per configuration and parameter, the subsets' mean reported standard deviation over
    the standard deviation of their estimates; smallest and largest (target: 0.5 to 2).
``intrinsics_censi.std_over_blocks_B_spread_min``, ``..._max`` (B = 6, 10)
    The same with each whole run cut into B interleaved blocks (sample ``i`` into block
    ``i mod B``; B = 3 gives the authors' subsets exactly): a spread of B estimates, B - 1
    degrees of freedom against the subsets' 2 (no target).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from benchmarks.harness import Figure, benchmark
from lti_motion.calibration import calibrate_intrinsics_intervals
from lti_motion.recordings import read_motion_intervals


def data_folder() -> Path:
    """``real/censi2013`` under ``LTI_MOTION_DATA`` (default ``../shared/data``)."""
    path = Path(os.environ.get("LTI_MOTION_DATA", "../shared/data")) / "real" / "censi2013"
    if not path.is_dir():
        raise SystemExit(f"Censi 2013 data not found at {path}; set LTI_MOTION_DATA")
    return path


def _vector(cal) -> tuple[np.ndarray, np.ndarray]:
    """(axle, left and right diameter, l_x, l_y, l_theta) and their standard deviations
    (counts in wheel radians: a diameter is twice the scale)."""
    k, s = cal.intrinsics, cal.std
    return (np.array([k.wheel_base_m, 2 * k.m_per_tick_left, 2 * k.m_per_tick_right,
                      *cal.sensor_pose]),
            np.array([s[2], 2 * s[0], 2 * s[1], *s[3:]]))


def run_scores(path: Path) -> dict[str, float]:
    """The figures' values (module docstring)."""
    runs = sorted(p.name[:-len("_results.json")] for p in path.glob("*_results.json"))
    err = {"axle": 0.0, "diam": 0.0, "head": 0.0, "xy": 0.0, "unit": 0.0, "raw": 0.0}
    subsets: dict[str, list] = {}
    for run in runs:
        s = read_motion_intervals(path / f"{run}.tuple")
        ref = json.loads((path / f"{run}_results.json").read_text())
        cal = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion, sensor_pose=True)
        v, sd = _vector(cal)
        a = np.array([ref[k] for k in ("axle", "l_diam", "r_diam", "l_x", "l_y", "l_theta")])
        rel = np.abs(v[:3] / a[:3] - 1) * 100
        err["axle"] = max(err["axle"], rel[0])
        err["diam"] = max(err["diam"], rel[1:].max())
        err["head"] = max(err["head"], abs(np.rad2deg(v[5] - a[5])))
        err["xy"] = max(err["xy"], np.abs(v[3:5] - a[3:5]).max() * 1e3)
        raw = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion, sensor_pose=True,
                                             outlier_rounds=0)
        err["raw"] = max(err["raw"], abs(raw.intrinsics.wheel_base_m / a[0] - 1) * 100)
        for factor in (10.0, 0.1):
            other = calibrate_intrinsics_intervals(s.wheel_rad * factor, s.sensor_motion,
                                                   sensor_pose=True)
            w, _ = _vector(other)
            w[1:3] *= factor
            change = np.abs(w - v) / np.maximum(np.abs(v), [1e-3] * 5 + [1e-2])
            err["unit"] = max(err["unit"], change.max() * 100)
        if "_" in run:
            subsets.setdefault(run.rsplit("_", 1)[0], []).append((v, sd))
    ratios = []
    for parts in subsets.values():
        est = np.array([p[0] for p in parts])
        std = np.array([p[1] for p in parts])
        ratios.extend(std.mean(axis=0) / est.std(axis=0, ddof=1))
    err["ratio_min"], err["ratio_max"] = float(min(ratios)), float(max(ratios))
    for blocks in BLOCKS:
        ratios = []
        for run in runs:
            if "_" not in run:
                ratios.extend(block_ratios(path / f"{run}.tuple", blocks))
        err[f"blocks_{blocks}"] = (float(min(ratios)), float(max(ratios)))
    return err


#: Interleaved blocks per whole run for the second look at the standard deviations.
BLOCKS = (6, 10)


def block_ratios(tuple_path: Path, blocks: int) -> np.ndarray:
    """Per parameter: the blocks' mean reported standard deviation over the standard
    deviation of their estimates, the run cut into ``blocks`` interleaved blocks."""
    s = read_motion_intervals(tuple_path)
    parts = [_vector(calibrate_intrinsics_intervals(s.wheel_rad[i::blocks],
                                                    s.sensor_motion[i::blocks],
                                                    sensor_pose=True))
             for i in range(blocks)]
    est = np.array([p[0] for p in parts])
    std = np.array([p[1] for p in parts])
    return std.mean(axis=0) / est.std(axis=0, ddof=1)


@benchmark("intrinsics_censi")
def run() -> list[Figure]:
    e = run_scores(data_folder())
    return [
        Figure("intrinsics_censi.axle_error_pct", float(e["axle"]), "%", target=0.3,
               better="lower"),
        Figure("intrinsics_censi.diameter_error_pct", float(e["diam"]), "%", target=0.3,
               better="lower"),
        Figure("intrinsics_censi.laser_heading_error_deg", float(e["head"]), "deg",
               target=0.5, better="lower"),
        Figure("intrinsics_censi.laser_xy_error_mm", float(e["xy"]), "mm", target=2.0,
               better="lower"),
        Figure("intrinsics_censi.unit_change_pct", float(e["unit"]), "%", target=0.01,
               better="lower"),
        Figure("intrinsics_censi.raw_axle_error_pct", float(e["raw"]), "%", better="lower"),
        Figure("intrinsics_censi.std_over_subset_spread_min", e["ratio_min"], "ratio",
               target=0.5, better="higher"),
        Figure("intrinsics_censi.std_over_subset_spread_max", e["ratio_max"], "ratio",
               target=2.0, better="lower"),
    ] + [Figure(f"intrinsics_censi.std_over_blocks_{b}_spread_{end}", e[f"blocks_{b}"][i],
                "ratio", better="lower")
         for b in BLOCKS for i, end in enumerate(("min", "max"))]
