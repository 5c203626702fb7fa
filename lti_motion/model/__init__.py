"""The model wing: the state-space :class:`MotionModel` and its identification.

- :mod:`lti_motion.model.motion_model`: :class:`MotionModel`, both seed models as one
  discrete state space with noise (``docs/architecture.md``), its JSON file;
- :mod:`lti_motion.model.excitation`: the manoeuvres as command sequences and the check
  that data excites the system;
- :mod:`lti_motion.model.fir`, :mod:`lti_motion.model.fir_steps`: the moving-average (FIR)
  model, from least squares or from the step manoeuvre (paper section II.B);
- :mod:`lti_motion.model.arx`, :mod:`lti_motion.model.arx_structure`: the ARX model by SVD
  least squares, order and delay selection, RLS, its physical structure (section II.C);
- :mod:`lti_motion.model.least_squares`, :mod:`lti_motion.model.state_space`: the least
  squares on lagged data both fits share; simulation of a state space by its impulse
  response;
- :mod:`lti_motion.model.output_error`, :mod:`lti_motion.model.structure_cv`: fits aimed at
  the integrated motion (output-error refinement, structure chosen by cross-validation).

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "COVARIANCE_JITTER",
    "DEFAULT_MAX_CONDITION",
    "FORMAT",
    "READ_VERSIONS",
    "VERSION",
    "ArxFit",
    "ArxSelection",
    "Candidate",
    "FirFit",
    "LeastSquares",
    "MotionModel",
    "OutputErrorFit",
    "OutputErrorOptions",
    "RecursiveARX",
    "StateSpace",
    "StepSequence",
    "StructureScore",
    "arx_regression",
    "arx_state_space",
    "block_condition",
    "check_excitation",
    "check_runs",
    "check_stable",
    "condition_number",
    "cv_blocks",
    "dc_gain",
    "estimate_arx",
    "estimate_fir",
    "excitation_condition_number",
    "fir_from_steps",
    "fir_state_space",
    "fit_arx",
    "fit_candidate",
    "fit_fir_from_steps",
    "free_run_errors",
    "lagged_columns",
    "markov_parameters",
    "nearest_servo_gain",
    "noise_covariances",
    "one_step_predictor",
    "output_error_covariances",
    "output_scales",
    "q_scale_from_errors",
    "qr_r_factor",
    "random_held_normal",
    "refine_model",
    "refine_output_error",
    "regression_matrix",
    "restrict_dc_gain",
    "rls_update",
    "rotation_in_place",
    "scale_outputs",
    "score_structures",
    "select_arx",
    "servo_dc_gain",
    "simulate_state_space",
    "simulate_state_space_loop",
    "split_runs",
    "step_sequence",
    "svd_least_squares",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "lti_motion.model.arx": (
            "ArxFit",
            "ArxSelection",
            "RecursiveARX",
            "arx_regression",
            "arx_state_space",
            "check_stable",
            "estimate_arx",
            "free_run_errors",
            "one_step_predictor",
            "rls_update",
            "select_arx",
            "split_runs",
        ),
        "lti_motion.model.arx_structure": (
            "dc_gain",
            "nearest_servo_gain",
            "output_scales",
            "restrict_dc_gain",
            "scale_outputs",
            "servo_dc_gain",
        ),
        "lti_motion.model.excitation": (
            "DEFAULT_MAX_CONDITION",
            "StepSequence",
            "check_excitation",
            "check_runs",
            "excitation_condition_number",
            "random_held_normal",
            "rotation_in_place",
            "step_sequence",
        ),
        "lti_motion.model.fir": (
            "FirFit",
            "estimate_fir",
            "fir_state_space",
        ),
        "lti_motion.model.fir_steps": ("fir_from_steps",),
        "lti_motion.model.least_squares": (
            "LeastSquares",
            "block_condition",
            "condition_number",
            "lagged_columns",
            "qr_r_factor",
            "regression_matrix",
            "svd_least_squares",
        ),
        "lti_motion.model.motion_model": (
            "COVARIANCE_JITTER",
            "FORMAT",
            "MotionModel",
            "READ_VERSIONS",
            "VERSION",
            "fit_arx",
            "fit_fir_from_steps",
            "noise_covariances",
            "output_error_covariances",
            "q_scale_from_errors",
        ),
        "lti_motion.model.output_error": (
            "OutputErrorFit",
            "OutputErrorOptions",
            "refine_model",
            "refine_output_error",
        ),
        "lti_motion.model.state_space": (
            "StateSpace",
            "markov_parameters",
            "simulate_state_space",
            "simulate_state_space_loop",
        ),
        "lti_motion.model.structure_cv": (
            "Candidate",
            "StructureScore",
            "cv_blocks",
            "fit_candidate",
            "score_structures",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from lti_motion.model.arx import (
        ArxFit,
        ArxSelection,
        RecursiveARX,
        arx_regression,
        arx_state_space,
        check_stable,
        estimate_arx,
        free_run_errors,
        one_step_predictor,
        rls_update,
        select_arx,
        split_runs,
    )
    from lti_motion.model.arx_structure import (
        dc_gain,
        nearest_servo_gain,
        output_scales,
        restrict_dc_gain,
        scale_outputs,
        servo_dc_gain,
    )
    from lti_motion.model.excitation import (
        DEFAULT_MAX_CONDITION,
        StepSequence,
        check_excitation,
        check_runs,
        excitation_condition_number,
        random_held_normal,
        rotation_in_place,
        step_sequence,
    )
    from lti_motion.model.fir import FirFit, estimate_fir, fir_state_space
    from lti_motion.model.fir_steps import fir_from_steps
    from lti_motion.model.least_squares import (
        LeastSquares,
        block_condition,
        condition_number,
        lagged_columns,
        qr_r_factor,
        regression_matrix,
        svd_least_squares,
    )
    from lti_motion.model.motion_model import (
        COVARIANCE_JITTER,
        FORMAT,
        READ_VERSIONS,
        VERSION,
        MotionModel,
        fit_arx,
        fit_fir_from_steps,
        noise_covariances,
        output_error_covariances,
        q_scale_from_errors,
    )
    from lti_motion.model.output_error import (
        OutputErrorFit,
        OutputErrorOptions,
        refine_model,
        refine_output_error,
    )
    from lti_motion.model.state_space import (
        StateSpace,
        markov_parameters,
        simulate_state_space,
        simulate_state_space_loop,
    )
    from lti_motion.model.structure_cv import (
        Candidate,
        StructureScore,
        cv_blocks,
        fit_candidate,
        score_structures,
    )
