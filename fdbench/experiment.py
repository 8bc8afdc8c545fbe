"""fdbench's runs, by concern: a run's specification and identity (``fdbench.spec``), its checks
(``fdbench.validation``), one runner per command (``fdbench.runners``, carried out by
``fdbench.method_runs``) and its record (``fdbench.records``). This module gathers their
public names, the ones scripts and the command line import."""

from __future__ import annotations

from .method_options import check_method_options, options_for, options_text, taken_options
from .records import RECORD_FIELDS, RunOutcome, base_record, noise_seed
from .runners import inverse_run, replay, run, run_simulation
from .spec import (COMMANDS, MAX_BUDGET, MAX_SEED, OMITTED_AT_DEFAULT, RunSpec, collocate_spec, control_spec,
                   gradient_for, model_digest, motion_digest, optimize_spec, with_model_file, with_motion_file,
                   with_motion_knots)
from .validation import GRADIENTS, check_conditions, check_gradient

__all__ = [
    "COMMANDS", "GRADIENTS", "MAX_BUDGET", "MAX_SEED", "OMITTED_AT_DEFAULT", "RECORD_FIELDS",
    "RunOutcome", "RunSpec", "base_record", "check_conditions", "check_gradient", "check_method_options",
    "collocate_spec", "control_spec", "gradient_for", "inverse_run", "model_digest", "motion_digest",
    "noise_seed", "optimize_spec", "options_for", "options_text", "replay", "run", "run_simulation", "taken_options",
    "with_model_file", "with_motion_file", "with_motion_knots",
]
