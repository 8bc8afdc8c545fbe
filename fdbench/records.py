"""A run's flat record (the command-line contract: ``RECORD_FIELDS``) and its outcome
(``RunOutcome``: the record, the simulation, the reference, the trajectory table)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import __version__
from .plausible import implausible


# The keys of every record, in this order (JSON keys and CSV header).
RECORD_FIELDS = (
    "command", "kinematics", "integrator", "dt", "torque", "optimizer", "feedforward",
    "kp", "kd", "seed", "budget", "rmse_rot_deg", "rmse_torque_nm", "runtime_s", "evaluations",
    "best_objective", "initial_objective", "t_end", "status", "message", "stop_reason", "max_violation", "n_params",
    "torque_options", "optimizer_options", "gradient", "alpha", "xi", "omega", "penalty_weight", "motion", "derivatives",
    "noise_deg", "model", "model_options", "plant", "spec_hash", "fdbench_version",
)


@dataclass
class RunOutcome:
    record: dict
    result: object  # multibody.simulation.Simulation on the motion's samples
    inverse: object  # multibody.simulation.JointInverse on the motion's samples
    history: list = field(default_factory=list)  # best-so-far objective per evaluation
    params: np.ndarray | None = None  # best parameters (optimize)
    extra: dict = field(default_factory=dict)
    table: tuple | None = None  # the trajectory as (CSV header, rows of shape (n, k))

    def trajectory(self) -> tuple[list, np.ndarray]:
        """The run's time history on the motion's samples: (CSV header, rows of shape (n, k)), in the
        units of a motion file (s, deg, deg/s; torques N m), so that it can be read back as
        ``--motion`` (the simulated angles) or ``--torque-file`` (the applied torques)."""
        return self.table


def noise_seed(spec) -> int | None:
    """The seed a run uses: its own, or 0 for the noise of a run given none (as ``motions``
    draws it); None for a run that draws nothing."""
    if spec.seed is not None:
        return spec.seed
    return 0 if spec.noise_deg else None


def base_record(spec) -> dict:
    record = dict.fromkeys(RECORD_FIELDS)
    record.update(
        command=spec.command, kinematics=spec.motion, integrator=spec.integrator, dt=spec.dt,
        feedforward=spec.feedforward, alpha=spec.alpha, xi=spec.xi, omega=spec.omega,
        spec_hash=spec.hash(), fdbench_version=__version__, seed=noise_seed(spec),
    )
    described = spec.describe()
    record.update({k: v for k, v in described.items() if k in record})
    return record


ALPHA_HINT = "; try a larger --alpha (or a smaller --dt with rk4)"


def explained(outcome: RunOutcome, spec) -> RunOutcome:
    """A failed run's message names the likely cause when a constant of the model or the plant
    is implausible (centimetres typed for metres), instead of the generic hint on --alpha."""
    causes = implausible(spec.model + spec.plant)
    record = outcome.record
    if causes and record.get("status") not in (None, "success"):
        message = str(record.get("message") or "").replace(ALPHA_HINT, "")
        record["message"] = f"{message}; likely cause: {'; '.join(causes)}"
    return outcome
