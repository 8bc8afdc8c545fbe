"""A run's full specification and ``run(spec)``: the one place where a control, simulation or
optimisation run is carried out and turned into a flat record (the command-line contract)."""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass, field
from functools import lru_cache

import numpy as np

from . import __version__
from .integrate import Settings, SimulationResult, check_integrator
from .model import Penalty, forearm_with
from .motion import DEFAULT_CAPTURE_HZ, DEFAULT_CUTOFF_HZ, KINEMATICS

COMMANDS = ("control", "optimize", "simulate", "collocate")
MAX_SEED = 2**32 - 2  # cma draws from numpy with seed + 1, which must stay below 2**32
MAX_BUDGET = 1_000_000  # evaluations: hours of work, and the history kept in memory stays small

# The keys of every record, in this order (JSON keys and CSV header).
RECORD_FIELDS = (
    "command", "kinematics", "integrator", "dt", "torque", "optimizer", "feedforward",
    "kp", "kd", "seed", "budget", "rmse_rot_deg", "rmse_torque_nm", "runtime_s", "evaluations",
    "best_objective", "initial_objective", "t_end", "status", "message", "stop_reason", "max_violation", "n_params",
    "torque_options", "optimizer_options", "gradient", "alpha", "xi", "omega", "penalty_weight", "motion", "derivatives",
    "noise_deg", "model", "model_options", "plant", "spec_hash", "fdbench_version",
)


@dataclass(frozen=True)
class RunSpec:
    """Everything that determines a run's numbers (the seed included, the runtime excluded)."""

    command: str = "control"
    kinematics: str = "paper"
    integrator: str = "rk4"
    dt: float = 1e-3
    rtol: float = 1e-6
    atol: float = 1e-9
    alpha: float = 1e7
    xi: float = 1.0
    omega: float = 10.0
    kp: float | None = None  # control
    kd: float | None = None
    torque: str | None = None  # optimize
    optimizer: str | None = None
    feedforward: bool = False
    seed: int | None = None
    budget: int | None = None
    penalty_weight: float = 1.0
    torque_options: tuple = ()  # sorted (name, value) pairs, e.g. (("hidden", 4),)
    optimizer_options: tuple = ()
    inputs: tuple = ()  # (option, SHA-256 of the file's content) of every input file, e.g. (("--torque-file", "ab12..."),)
    controller: str | None = None  # control: a registered controller; None is the paper's PD (kp, kd)
    method_options: tuple = ()  # sorted (name, value) pairs of the controller or of collocate
    # the desired motion: ``kinematics`` names eq. 5's variant or a recorded motion's CSV file
    radians: bool = False  # the file's angles are in radians (else degrees)
    cutoff_hz: float = DEFAULT_CUTOFF_HZ  # derivative estimate: zero-lag Butterworth -3 dB frequency, Hz
    smoothing: str = "butterworth"  # or "spline" (a smoothing spline)
    spline_lambda: float | None = None  # the smoothing spline's factor (None: generalised cross-validation)
    sample_dt: float | None = None  # the reporting grid's step, s (None: the motion's samples)
    noise_deg: float = 0.0  # white Gaussian noise added to the captured angle, deg (seeded by ``seed``)
    capture_hz: float = DEFAULT_CAPTURE_HZ  # the capture rate of a noisy copy of an analytic motion, Hz
    plant: tuple = ()  # (key, value) pairs changing the simulated body only
    model: tuple = ()  # (key, value) pairs changing the nominal model and the simulated body
    gradient: str = "fd"  # optimize with bfgs/lbfgsb: "fd" finite differences (the paper's), "exact" sensitivities
    model_name: str = "forearm"  # the simulated body: a name of ``fdbench.models.names()`` or a model file

    def __post_init__(self):
        if self.kinematics == "paper" and self.model_name != "forearm":  # the default motion is the model's own
            from .models import default_motion

            try:
                object.__setattr__(self, "kinematics", default_motion(self.model_name))
            except ValueError:  # an unknown model, or one without motions, is for ``validate`` to refuse
                pass

    def _runs(self):
        """The module carrying out this spec's runs when its model is not the forearm, else None."""
        from .models import runs

        return runs(self.model_name)

    def settings(self) -> Settings:
        """The simulation settings: the plant simulated, the nominal model that inverse dynamics
        and model-based controllers believe, and the desired motion they are given (the forearm's)."""
        if self._runs() is not None:
            raise ValueError(f"the {self.model_name} model has no forearm settings")
        desired, _ = self.motions()
        nominal = forearm_with(self.model)
        plant = forearm_with(self.model + self.plant) if self.plant else nominal
        return Settings(plant, Penalty(self.alpha, self.xi, self.omega), desired,
                        self.integrator, self.dt, self.rtol, self.atol, nominal=None if plant == nominal else nominal)

    def motions(self):
        """(desired, true) motions: the motion given to every method (a noisy capture when
        ``noise_deg`` > 0) and the one its indicators are measured against."""
        if self._runs() is not None:
            return self._runs().motions(self)
        return _motions(self.kinematics, self.radians, self.cutoff_hz, self.smoothing, self.spline_lambda,
                        self.sample_dt, self.noise_deg, self.seed or 0, self.capture_hz, dict(self.inputs).get("--motion"))

    def reference(self):
        """The inverse dynamics of the nominal model on the true motion, on its samples: what the
        indicators are measured against (InverseResult; the model's own for another model)."""
        from .inverse import inverse_dynamics

        if self._runs() is not None:
            return self._runs().reference(self)
        _, truth = self.motions()
        return inverse_dynamics(None, forearm_with(self.model), truth)

    def describe(self) -> dict:
        """The record's fields that say which motion, noise, filter, model and plant a run used."""
        if self._runs() is not None:
            return self._runs().describe(self)
        desired, truth = self.motions()
        out = {"motion": desired.name, "duration_s": truth.duration, "samples": len(truth.samples)}
        if self.kinematics not in KINEMATICS or self.noise_deg:
            out["derivatives"] = desired.describe().get("derivatives")
        out["noise_deg"] = self.noise_deg
        out["model"] = self.model_name
        out["model_options"] = _options_text(self.model) or None
        out["plant"] = _options_text(self.plant) or None
        return out

    def validate(self) -> "RunSpec":
        """Raise ValueError with a one-line message for anything out of range; no work done."""
        if self.command not in COMMANDS:
            raise ValueError(f"unknown command {self.command!r}; valid: {', '.join(COMMANDS)}")
        check_integrator(self.integrator)
        check_conditions(self)
        if self._runs() is not None:
            self._runs().check(self)
        else:
            self.settings()
        if self.command == "control" and self.controller not in (None, "pd"):
            from .controllers import CONTROLLERS, make_controller

            check_method_options(CONTROLLERS, self.controller, dict(self.method_options), "controller")
            make_controller(self.controller, **dict(self.method_options))
        elif self.command == "control":
            from .control import check_gain

            check_gain("--kp", self.kp)
            check_gain("--kd", self.kd)
        if self.command == "collocate":
            from .collocation import check_options

            check_options(**dict(self.method_options))
        if self.command == "optimize":
            from .optimizers import make_optimizer
            from .torques import make_torque

            if not isinstance(self.seed, int) or not 0 <= self.seed < MAX_SEED:
                raise ValueError(f"--seed must be an integer in [0, {MAX_SEED - 1}], got {self.seed}")
            if not isinstance(self.budget, int) or not 1 <= self.budget <= MAX_BUDGET:
                raise ValueError(f"--budget must be an integer in [1, {MAX_BUDGET}], got {self.budget}")
            if not (math.isfinite(self.penalty_weight) and self.penalty_weight >= 0):
                raise ValueError(f"--penalty-weight must be a non-negative finite number, got {self.penalty_weight}")
            from .optimizers import OPTIMIZERS
            from .torques import TORQUES

            options = dict(self.torque_options)
            check_method_options(TORQUES, self.torque, options, "torque")
            check_method_options(OPTIMIZERS, self.optimizer, dict(self.optimizer_options), "optimizer")
            if options.get("hidden") == "auto":
                options.pop("hidden")
            torque = make_torque(self.torque, **options)
            optimizer = make_optimizer(self.optimizer, **dict(self.optimizer_options))
            check_gradient(self.gradient, optimizer, torque, self.integrator)
        elif self.gradient != "fd":
            raise ValueError("--gradient applies to optimisations only")
        self._check_memory()
        return self

    def _check_memory(self) -> None:
        """ValueError (one line naming the option to change) if the run's arrays would not fit in
        the memory fdbench allows a run (see ``fdbench.memory``)."""
        from .memory import check_run
        from .models import n_joints

        truth = self.motions()[1]
        population, hidden = 1, 0
        if self.command == "optimize" and self.integrator == "rk4" and self.optimizer == "cmaes":
            population = dict(self.optimizer_options).get("popsize") or 16  # cma's default is smaller
            if self.torque == "ann":
                from .torques.ann import AUTO_MAX_HIDDEN

                hidden = dict(self.torque_options).get("hidden", 4)
                hidden = AUTO_MAX_HIDDEN if hidden == "auto" else hidden
        check_run(truth.duration, len(truth.samples), n_joints(self.model_name),
                  self.dt if self.integrator == "rk4" else None, population, hidden)

    def as_dict(self) -> dict:
        return asdict(self)

    def canonical(self) -> dict:
        """The settings that determine the numbers, normalised so that equivalent specs compare
        equal: -0.0 is 0.0, whole numbers in float fields are floats, the tolerances of the
        adaptive integrators are left at their defaults for rk4 and the RK4 step for the others,
        and fields added since the first results schema are left out at their defaults (so that
        stored runs keep their identity)."""
        data = self.as_dict()
        defaults = RunSpec()
        if self.integrator == "rk4":
            data["rtol"], data["atol"] = defaults.rtol, defaults.atol
        else:
            data["dt"] = defaults.dt
        for name in FLOAT_FIELDS:
            if isinstance(data[name], (int, float)) and not isinstance(data[name], bool):
                data[name] = float(data[name]) + 0.0  # + 0.0 turns -0.0 into 0.0
        if dict(self.inputs).get("--motion"):  # a recorded motion counts by its content, not its file name
            data["kinematics"] = "file"
        if dict(self.inputs).get("--model"):  # so does a model file
            data["model_name"] = "file"
        if data.get("controller") == "pd":  # the paper's PD is the default controller
            data["controller"] = None
        for name, default in OMITTED_AT_DEFAULT.items():
            if data.get(name) == default:
                data.pop(name)
        return data

    def hash(self) -> str:
        """A digest of the canonical settings (stable across runs and machines), 16 hex digits."""
        text = json.dumps(self.canonical(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


FLOAT_FIELDS = ("dt", "rtol", "atol", "alpha", "xi", "omega", "kp", "kd", "penalty_weight", "cutoff_hz",
                "spline_lambda", "sample_dt", "noise_deg", "capture_hz")
MAX_NOISE_DEG = 45.0
MAX_CAPTURE_HZ = 100_000.0


GRADIENTS = ("fd", "exact")


def check_gradient(gradient, optimizer, torque, integrator) -> None:
    """ValueError with a one-line message unless ``gradient`` suits the optimiser, the torque
    parameterisation and the integrator (exact gradients: bfgs or lbfgsb, rk4, a torque with
    d tau / d p)."""
    if gradient not in GRADIENTS:
        raise ValueError(f"--gradient must be one of {', '.join(GRADIENTS)}, got {gradient!r}")
    if gradient == "fd":
        return
    if not optimizer.uses_gradient:
        from .optimizers import OPTIMIZERS

        users = ", ".join(n for n, c in OPTIMIZERS.items() if getattr(c, "uses_gradient", False))
        raise ValueError(f"--gradient exact needs a gradient-based optimiser ({users}), got {optimizer.name}")
    if integrator != "rk4":
        raise ValueError(f"--gradient exact needs --integrator rk4, got {integrator}")
    from .torques.base import TorqueParameterisation

    if type(torque).on_grid_jacobian is TorqueParameterisation.on_grid_jacobian:
        raise ValueError(f"--gradient exact: torque {torque.name!r} gives no d tau / d p")


def check_conditions(spec: "RunSpec") -> None:
    """The motion, noise and model options of a spec; ValueError with a one-line message."""
    from .motion import check_estimate

    check_estimate(spec.cutoff_hz, spec.smoothing, spec.spline_lambda)
    if not (math.isfinite(spec.noise_deg) and 0 <= spec.noise_deg <= MAX_NOISE_DEG):
        raise ValueError(f"--noise-deg must be in [0, {MAX_NOISE_DEG:g}] deg, got {spec.noise_deg}")
    if not (math.isfinite(spec.capture_hz) and 1 <= spec.capture_hz <= MAX_CAPTURE_HZ):
        raise ValueError(f"--capture-hz must be in [1, {MAX_CAPTURE_HZ:g}] Hz, got {spec.capture_hz}")
    if spec.noise_deg and spec.seed is not None and not (isinstance(spec.seed, int) and 0 <= spec.seed < MAX_SEED):
        raise ValueError(f"--seed must be an integer in [0, {MAX_SEED - 1}], got {spec.seed}")
    from .models import check_name, with_changes

    check_name(spec.model_name)
    digest = dict(spec.inputs).get("--model")
    if digest is not None and digest != model_digest(spec.model_name):
        from .files import BadFile

        raise BadFile(f"--model: {spec.model_name} has changed since this run was specified (or differs on this machine)")
    with_changes(spec.model_name, spec.model)
    with_changes(spec.model_name, spec.model + spec.plant)


@lru_cache(maxsize=64)
def _motions(source, radians, cutoff_hz, smoothing, spline_lambda, sample_dt, noise_deg, seed, capture_hz, digest):
    from .motion import load_motion, noisy

    truth = load_motion(source, radians, cutoff_hz, smoothing, spline_lambda, sample_dt)
    if digest is not None and digest != motion_digest(source):
        from .files import BadFile

        raise BadFile(f"--motion: {source} has changed since this run was specified (or differs on this machine)")
    if not noise_deg:
        return truth, truth
    return noisy(truth, noise_deg, seed, capture_hz, cutoff_hz, smoothing, spline_lambda), truth


def motion_digest(path) -> str:
    """SHA-256 of a recorded motion file's content."""
    from .files import read_input_text
    from .motion import check_source

    check_source(str(path))
    return hashlib.sha256(read_input_text(path, "--motion").encode()).hexdigest()


def model_digest(path) -> str:
    """SHA-256 of a model file's content."""
    from .files import read_input_bytes

    return hashlib.sha256(read_input_bytes(path, "--model")).hexdigest()


def with_model_file(spec: "RunSpec") -> "RunSpec":
    """The spec with its model file's content digest among its inputs (none for a library model)."""
    from dataclasses import replace

    from .models import is_file

    if not is_file(spec.model_name):
        return spec
    inputs = tuple(p for p in spec.inputs if p[0] != "--model") + (("--model", model_digest(spec.model_name)),)
    return replace(spec, inputs=tuple(sorted(inputs)))


def with_motion_file(spec: "RunSpec") -> "RunSpec":
    """The spec with its recorded motion's content digest among its inputs (none for eq. 5)."""
    from dataclasses import replace

    from .models import named_motions

    if spec.kinematics in named_motions(spec.model_name):
        return spec
    inputs = tuple(p for p in spec.inputs if p[0] != "--motion") + (("--motion", motion_digest(spec.kinematics)),)
    return replace(spec, inputs=tuple(sorted(inputs)))
# fields a spec's hash leaves out while they hold these values (added after the first results schema)
OMITTED_AT_DEFAULT = {"inputs": (), "controller": None, "method_options": (), "radians": False,
                      "cutoff_hz": DEFAULT_CUTOFF_HZ, "smoothing": "butterworth", "spline_lambda": None,
                      "sample_dt": None, "noise_deg": 0.0, "capture_hz": DEFAULT_CAPTURE_HZ, "plant": (), "model": (), "gradient": "fd",
                      "model_name": "forearm"}


def control_spec(kp=80.0, kd=0.3, controller="pd", controller_options=None, **common) -> RunSpec:
    """A control spec: the paper's PD (kp, kd) or another registered controller with its options
    (``controller_options``: names its class takes; another name is a ValueError)."""
    from .controllers import CONTROLLERS

    options = _accepted(CONTROLLERS, controller or "pd", controller_options, "controller")
    if controller in (None, "pd"):
        return RunSpec(command="control", kp=dict(options).get("kp", kp), kd=dict(options).get("kd", kd),
                       feedforward=True, **common)
    return RunSpec(command="control", controller=controller, feedforward=True, method_options=options, **common)


def collocate_spec(nodes=100, scheme="hermite-simpson", regularization=None, max_iter=None, max_time=None,
                   **common) -> RunSpec:
    """A direct-collocation spec (see ``fdbench.collocation.collocate``); None takes the default."""
    from .collocation import DEFAULT_MAX_ITER, DEFAULT_MAX_TIME, DEFAULT_REGULARIZATION

    options = dict(nodes=nodes, scheme=scheme,
                   regularization=DEFAULT_REGULARIZATION if regularization is None else regularization,
                   max_iter=DEFAULT_MAX_ITER if max_iter is None else max_iter,
                   max_time=DEFAULT_MAX_TIME if max_time is None else max_time)
    return RunSpec(command="collocate", method_options=tuple(sorted(options.items())), **common)


def optimize_spec(torque="cs", optimizer="bfgs", feedforward=False, seed=0, budget=200,
                  torque_options=None, optimizer_options=None, gradient="fd", *, shared_options=False,
                  **common) -> RunSpec:
    """An optimisation spec. ``torque_options`` and ``optimizer_options`` name options the torque's
    and the optimiser's classes take (another name is a ValueError), or, with ``shared_options``
    (a sweep handing one set to several methods), each keeps those it takes; so the same run has
    the same hash whichever command asks for it. ``gradient`` "exact" serves gradient-based
    optimisers only (see ``gradient_for``)."""
    from .optimizers import OPTIMIZERS
    from .torques import TORQUES

    if shared_options:
        torque_options = options_for(TORQUES, torque, torque_options)
        optimizer_options = options_for(OPTIMIZERS, optimizer, optimizer_options)
    options = {k: v for k, v in (optimizer_options or {}).items() if v is not None}
    if torque in TORQUES:  # the parameterisation's defaults for this optimiser, where not given
        options = {**getattr(TORQUES[torque], "optimizer_defaults", {}).get(optimizer, {}), **options}
    spec = RunSpec(command="optimize", torque=torque, optimizer=optimizer, feedforward=feedforward,
                   seed=seed, budget=budget, torque_options=_accepted(TORQUES, torque, torque_options, "torque"),
                   optimizer_options=_accepted(OPTIMIZERS, optimizer, options, "optimizer"),
                   gradient=gradient, **common)
    return with_motion_knots(spec, written_out="knots" in (torque_options or {}))


def with_motion_knots(spec: RunSpec, written_out: bool) -> RunSpec:
    """A spline spec without --knots gets one knot every 0.1 s of its motion (``cs.knots_for``).
    ``written_out`` (the command line's and the report's knots=None) puts the count among the
    torque options whatever it is; else (the Python API's omitted knots) only where it differs from
    the class default, so that every stored run keeps its hash."""
    from dataclasses import replace

    from .torques.cs import DEFAULT_KNOTS, knots_for

    if spec.torque != "cs" or "knots" in dict(spec.torque_options):
        return spec
    try:
        knots = knots_for(spec.motions()[1].duration)
    except (OSError, ValueError):  # a motion that cannot be read: for ``validate`` to refuse
        return spec
    if not written_out and knots == DEFAULT_KNOTS:
        return spec
    return replace(spec, torque_options=tuple(sorted(spec.torque_options + (("knots", knots),))))


def gradient_for(optimizer: str, gradient: str) -> str:
    """The gradient option a sweep gives ``optimizer``: ``gradient`` for a gradient-based
    optimiser, "fd" (the default, no gradient used) for the others."""
    from .optimizers import OPTIMIZERS

    uses = optimizer in OPTIMIZERS and getattr(OPTIMIZERS[optimizer], "uses_gradient", False)
    return gradient if uses else "fd"


def _accepted(registry, name, options, kind: str) -> tuple:
    """The options given (not None) as sorted (name, value) pairs, checked by ``check_method_options``."""
    options = {k: v for k, v in (options or {}).items() if v is not None}
    check_method_options(registry, name, options, kind)
    return tuple(sorted(options.items()))


def taken_options(registry, name) -> list:
    """The option names the class registered as ``name`` takes (none for an unknown name)."""
    import inspect

    return list(inspect.signature(registry[name]).parameters) if name in registry else []


def check_method_options(registry, name, options, kind: str) -> None:
    """ValueError naming an option the class registered as ``name`` does not take, and those it
    takes (a misspelt ``knot`` is not silently dropped). An unknown ``name`` is left to
    ``RunSpec.validate``."""
    if name not in registry:
        return
    taken = taken_options(registry, name)
    unknown = [key for key in options if key not in taken]
    if unknown:
        raise ValueError(f"{kind} {name!r} takes no option {unknown[0]!r}; it takes "
                         f"{', '.join(taken) if taken else 'none'}")


def options_for(registry, name, options) -> dict:
    """Of one set of options shared by several methods (a sweep's), those the class registered
    as ``name`` takes."""
    taken = taken_options(registry, name)
    return {k: v for k, v in (options or {}).items() if k in taken}


@dataclass
class RunOutcome:
    record: dict
    result: SimulationResult
    inverse: object  # InverseResult on the 1 ms samples
    history: list = field(default_factory=list)  # best-so-far objective per evaluation
    params: np.ndarray | None = None  # best parameters (optimize)
    extra: dict = field(default_factory=dict)
    table: tuple | None = None  # the trajectory as (CSV header, rows (n, k)) when not the forearm's

    def trajectory(self) -> tuple[list, np.ndarray]:
        """The run's time history on the motion's samples: (CSV header, rows of shape (n, k)), in the
        units of a motion file (s, deg, deg/s, deg/s^2; torques N m, positions m), so that it can be
        read back as ``--motion`` (the simulated theta) or ``--torque-file`` (the applied torque)."""
        if self.table is not None:
            return self.table
        r, inv = self.result, self.inverse
        theta_acc = np.full(len(r.t), np.nan) if r.qdd is None else r.qdd[:, 2]
        angles = np.degrees([r.q[:, 2], inv.theta, r.qd[:, 2], inv.theta_dot, theta_acc, inv.theta_ddot])
        header = ["t", "theta", "theta_desired", "theta_vel", "theta_vel_desired", "theta_acc", "theta_acc_desired",
                  "torque", "torque_inverse", "x2", "y2"]
        return header, np.column_stack([r.t, *angles, r.torque, inv.torque, r.q[:, 0], r.q[:, 1]])


def _options_text(pairs) -> str:
    return " ".join(f"{k}={v}" for k, v in pairs)


def noise_seed(spec: RunSpec) -> int | None:
    """The seed a run uses: its own, or 0 for the noise of a run given none (as ``motions``
    draws it); None for a run that draws nothing."""
    if spec.seed is not None:
        return spec.seed
    return 0 if spec.noise_deg else None


def base_record(spec: RunSpec) -> dict:
    record = dict.fromkeys(RECORD_FIELDS)
    record.update(
        command=spec.command, kinematics=spec.kinematics, integrator=spec.integrator, dt=spec.dt,
        feedforward=spec.feedforward, alpha=spec.alpha, xi=spec.xi, omega=spec.omega,
        spec_hash=spec.hash(), fdbench_version=__version__, seed=noise_seed(spec),
    )
    described = spec.describe()
    record.update({k: v for k, v in described.items() if k in record})
    return record


def fill_result(record: dict, result: SimulationResult, inverse) -> dict:
    from .indicators import rmse_rot_deg, rmse_torque_nm

    record.update(
        rmse_rot_deg=rmse_rot_deg(result, inverse.theta),
        rmse_torque_nm=rmse_torque_nm(result, inverse.torque),
        t_end=result.t_end, status=result.status.code, message=result.message,
        max_violation=result.max_violation,
    )
    return record


def run(spec: RunSpec, on_evaluation=None, on_start=None) -> RunOutcome:
    """Carry out a control or optimisation run. ``on_evaluation(count, best)`` reports progress;
    ``on_start(budget)`` is called once compilation and imports are done."""
    spec.validate()
    if spec._runs() is not None:
        return _explained(spec._runs().run(spec, on_evaluation, on_start), spec)
    if spec.command == "control":
        return _explained(_run_control(spec), spec)
    if spec.command == "optimize":
        return _explained(_run_optimize(spec, on_evaluation, on_start), spec)
    if spec.command == "collocate":
        return _explained(_run_collocate(spec), spec)
    raise ValueError("simulate runs are carried out by run_simulation")


ALPHA_HINT = "; try a larger --alpha (or a smaller --dt with rk4)"


def _explained(outcome: RunOutcome, spec: RunSpec) -> RunOutcome:
    """A failed run's message names the likely cause when a constant of the model or the plant
    is implausible (centimetres typed for metres), instead of the generic hint on --alpha."""
    from .model import implausible

    causes = implausible(spec.model + spec.plant)
    record = outcome.record
    if causes and record.get("status") not in (None, "success"):
        message = str(record.get("message") or "").replace(ALPHA_HINT, "")
        record["message"] = f"{message}; likely cause: {'; '.join(causes)}"
    return outcome


def _run_control(spec: RunSpec) -> RunOutcome:
    if spec.controller not in (None, "pd"):
        return _run_controller(spec)
    from .control import feedforward
    from .integrate import simulate, warm_up

    settings = spec.settings()
    warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = simulate(feedforward(settings), settings, spec.kp, spec.kd)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque="id", kp=spec.kp, kd=spec.kd, evaluations=1, runtime_s=runtime, controller="pd")
    return RunOutcome(record, result, inverse)


def _run_controller(spec: RunSpec) -> RunOutcome:
    """A registered controller other than the paper's PD: its design (feedback gains, Riccati
    solution) is part of the runtime."""
    from .control import track
    from .controllers import make_controller
    from .integrate import warm_up

    settings = spec.settings()
    controller = make_controller(spec.controller, **dict(spec.method_options))
    warm_up()
    controller.warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = track(controller, settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque=controller.feedforward_label, evaluations=1, runtime_s=runtime, controller=spec.controller,
                  controller_options=_options_text(spec.method_options))
    return RunOutcome(record, result, inverse)


def _run_collocate(spec: RunSpec) -> RunOutcome:
    """Direct collocation, then the torque found replayed by fdbench's own forward simulation:
    the three indicators are the replay's; the collocation's own tracking error, IPOPT's status,
    iterations and solve time stand beside them. ``extra['collocation']`` holds the solution."""
    from .collocation import collocate, record_fields
    from .integrate import simulate, warm_up

    settings = spec.settings()
    options = dict(spec.method_options)
    warm_up()
    import casadi  # noqa: F401  (its import is not part of the runtime)

    start = time.perf_counter()
    inverse = spec.reference()
    solution = collocate(settings, **options)
    result = simulate(solution.torque_function(), settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    theta_d = np.interp(solution.t, inverse.t, inverse.theta)
    own = float(np.sqrt(np.mean(np.degrees(solution.theta - theta_d) ** 2)))
    record.update(runtime_s=runtime, **record_fields(solution, options, own, result.message))
    return RunOutcome(record, result, inverse, extra={"collocation": solution})


def _run_optimize(spec: RunSpec, on_evaluation, on_start) -> RunOutcome:
    from .integrate import warm_up
    from .optimizers import make_optimizer
    from .problem import TrackingProblem
    from .torques import make_torque

    from .torques import TORQUES

    settings = spec.settings()
    optimizer = make_optimizer(spec.optimizer, **dict(spec.optimizer_options))
    warm_up()
    optimizer.warm_up()
    TORQUES[spec.torque].warm_up()
    if spec.gradient == "exact":
        from .gradient import warm_up as gradient_warm_up

        gradient_warm_up()
    if settings.integrator == "rk4":  # every evaluation on RK4 runs the population kernel, alone or together
        from .population import warm_up as population_warm_up

        population_warm_up()
    if on_start:
        on_start(spec.budget)
    start = time.perf_counter()
    torque_options = dict(spec.torque_options)
    extra = {}
    if torque_options.get("hidden") == "auto":
        from .inverse import inverse_dynamics
        from .torques.ann import select_hidden

        inv = inverse_dynamics(None, settings.nominal_model, settings.kinematics)
        torque_options["hidden"], extra["hidden_fits"] = select_hidden(inv.t, inv.torque)
    torque = make_torque(spec.torque, **torque_options)
    problem = TrackingProblem(torque, settings, spec.feedforward, spec.penalty_weight)
    gradient = problem.value_and_gradient_scaled if spec.gradient == "exact" else None
    batch = problem.objectives_scaled if problem.batched else None
    opt = optimizer.minimize(problem.objective_scaled, problem.x0, spec.budget, spec.seed, on_evaluation, gradient,
                             batch)
    params = opt.x * problem.scale
    result = problem.simulate(params)
    runtime = time.perf_counter() - start
    reference = spec.reference()
    record = fill_result(base_record(spec), result, reference)
    record.update(
        torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
        evaluations=opt.evaluations, best_objective=opt.fun, stop_reason=opt.stop_reason,
        n_params=problem.n_params, runtime_s=runtime, penalty_weight=spec.penalty_weight,
        torque_options=_options_text(sorted(torque_options.items())),
        optimizer_options=_options_text(spec.optimizer_options), gradient=spec.gradient,
    )
    record["initial_objective"] = problem.objective(problem.p0)
    return RunOutcome(record, result, reference, opt.history, params, extra)



def run_simulation(spec: RunSpec, torque_file=None, params_file=None) -> RunOutcome:
    """Open-loop forward dynamics driven by the inverse-dynamics torque, a CSV torque history
    or saved optimisation parameters. Bad files raise ``files.BadFile``."""
    from dataclasses import replace

    from .integrate import simulate, warm_up
    from .inverse import Feedforward

    if spec._runs() is not None:
        return _explained(spec._runs().run_simulation(spec, torque_file, params_file), spec)
    settings = spec.settings()
    if torque_file is not None:
        from .files import read_torque_csv

        t_file, q_file = read_torque_csv(torque_file, duration=settings.motion.duration)
        torque, label = (lambda t: np.interp(t, t_file, q_file)), f"file:{torque_file}"
        digest = hashlib.sha256(t_file.tobytes() + q_file.tobytes()).hexdigest()
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    elif params_file is not None:
        from .params_file import load_torque

        torque, label, digest = load_torque(params_file, settings)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--params", digest),))))
    else:
        torque, label = Feedforward(settings.nominal_model, settings.kinematics), "id"
    warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = simulate(torque, settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque=label, evaluations=1, runtime_s=runtime)
    return _explained(RunOutcome(record, result, inverse), spec)


def replay(spec: RunSpec, params) -> SimulationResult:
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    from .problem import TrackingProblem

    if spec._runs() is not None:
        return spec._runs().replay(spec, params)
    from .torques import make_torque

    settings = spec.settings()
    options = dict(spec.torque_options)
    if options.get("hidden") == "auto":
        options["hidden"] = (len(params) - 1) // 3
    problem = TrackingProblem(make_torque(spec.torque, **options), settings, spec.feedforward, spec.penalty_weight)
    return problem.simulate(np.asarray(params, dtype=float))


INVERSE_HEADER = ("t", "theta", "theta_vel", "theta_acc", "torque")  # s, deg, deg/s, deg/s^2, N m


def inverse_run(spec: RunSpec) -> tuple[dict, list, np.ndarray]:
    """Inverse dynamics of the desired motion with the nominal model: (record, CSV header, rows on
    the motion's samples) with the columns of a motion file (``INVERSE_HEADER``), angles in degrees."""
    if spec._runs() is not None:
        return spec._runs().inverse_run(spec)
    from .inverse import inverse_dynamics

    settings = spec.settings()
    desired, _ = spec.motions()
    start = time.perf_counter()
    inv = inverse_dynamics(desired.samples, settings.nominal_model, desired)
    runtime = time.perf_counter() - start
    record = {
        "command": "inverse", "kinematics": spec.kinematics, **spec.describe(),
        "theta_start_deg": float(np.degrees(inv.theta[0])), "theta_end_deg": float(np.degrees(inv.theta[-1])),
        "torque_min_nm": float(inv.torque.min()), "torque_max_nm": float(inv.torque.max()),
        "torque_start_nm": float(inv.torque[0]), "torque_end_nm": float(inv.torque[-1]),
        "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
        "fdbench_version": __version__,
    }
    rows = np.column_stack([inv.t, *np.degrees([inv.theta, inv.theta_dot, inv.theta_ddot]), inv.torque])
    return record, list(INVERSE_HEADER), rows
