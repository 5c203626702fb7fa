"""Tests of lti_motion.model.structure_cv: blocks, and the integrated-motion score."""

import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, DT, commands, plant

from lti_motion.exceptions import CalibrationError
from lti_motion.model.output_error import OutputErrorOptions
from lti_motion.model.structure_cv import Candidate, cv_blocks, score_structures

OFFSET = np.array([0.004, -0.03])


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(11)
    out = []
    for n in (1500, 1200):
        u = commands(rng, n)
        out.append((u, plant(u, rng) + OFFSET))
    return out


def test_blocks_partition_the_samples_in_time_order(runs):
    blocks = cv_blocks(runs, 3)
    lengths = [sum(len(u) for u, _ in b) for b in blocks]
    assert sum(lengths) == 2700 and max(lengths) - min(lengths) <= 1
    assert np.array_equal(blocks[0][0][0], runs[0][0][:900])
    assert np.array_equal(blocks[1][0][0], runs[0][0][900:])     # 600 from run 0, then
    assert np.array_equal(blocks[1][1][0], runs[1][0][:300])     # 300 from run 1


def test_the_offset_model_scores_better_and_a_bad_structure_worse(runs):
    oe = OutputErrorOptions(horizons_s=(1.0,), max_nfev=15)
    cands = [Candidate(2, 2, DELAY), Candidate(2, 2, DELAY, oe), Candidate(1, 1, 0)]
    scores = score_structures(runs, cands, dt_s=DT, wheel_base_m=BASE, warmup=10,
                              horizon_s=3.0, n_folds=2)
    ls, with_offset, no_delay = (s.median_end_error_m for s in scores)
    assert scores[1].candidate.label == "arx(2,2,4)+oe+c"
    assert with_offset < 0.7 * ls, (with_offset, ls)
    assert no_delay > ls
    assert all(s.n_windows >= 10 for s in scores)


def test_too_short_runs_are_refused(runs):
    with pytest.raises(CalibrationError, match="holds a 30 s window"):
        score_structures(runs, [Candidate(1, 1, 0)], dt_s=DT, wheel_base_m=BASE, warmup=10,
                         horizon_s=30.0, n_folds=2)
    with pytest.raises(ValueError, match="n_folds must be at least 2"):
        score_structures(runs, [Candidate(1, 1, 0)], dt_s=DT, wheel_base_m=BASE, warmup=10,
                         n_folds=1)


def test_the_commands_candidate_fits_nothing(runs):
    from lti_motion.kinematics import body_from_wheel
    from lti_motion.model.structure_cv import fit_candidate
    c = Candidate(0, 1, 0, commands=True)
    model = fit_candidate(c, runs, dt_s=DT, wheel_base_m=BASE, warmup=10)
    u = runs[0][0]
    np.testing.assert_allclose(model.simulate(u), body_from_wheel(u, wheel_base_m=BASE),
                               atol=1e-12)
    assert c.label == "commands(delay 0)"
    with pytest.raises(ValueError, match="na=0, nb=1 and no fit"):
        Candidate(1, 1, 0, commands=True)
