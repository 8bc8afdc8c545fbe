"""A run's full specification (``RunSpec``), its identity (the hash of its canonical settings,
the digests of its input files) and the constructors of the commands' specs (``control_spec``,
``optimize_spec``, ``collocate_spec``, ``peer_spec``). The run layer's value: it imports the
methods and the engine below it (to check a spec), never the runs above it (``method_runs``)."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import InitVar, asdict, dataclass, replace

from . import run_inputs
from .collocation import (DEFAULT_EXCITATION_WEIGHT, DEFAULT_MAX_ITER, DEFAULT_MAX_TIME, DEFAULT_REGULARIZATION,
                          check_model, check_options)
from .controllers import CONTROLLERS
from .controllers.pd import PAPER_KD, PAPER_KP
from .excitation_problem import DEFAULT_EFFORT_WEIGHT
from .integrate import check_integrator
from .memory import check_run
from .method_options import accepted_options, check_method_options, options_for
from .models import default_motion, is_file, n_joints, named_motions
from .multibody.motions import DEFAULT_CAPTURE_HZ, DEFAULT_CUTOFF_HZ
from .optimizers import OPTIMIZERS, make_optimizer
from .peers import check_spec as check_peer_spec
from .peers import peer
from .run_inputs import model_digest, motion_digest
from .torques import TORQUES, make_torque
from .torques.ann import AUTO_MAX_HIDDEN
from .torques.cs import DEFAULT_KNOTS, knots_for
from .validation import MAX_CAPTURE_HZ, MAX_NOISE_DEG, MAX_SEED, check_conditions, check_gradient

COMMANDS = ("control", "optimize", "simulate", "collocate", "peer")  # peer: fdbench.peers
ACTUATIONS = ("torques", "muscles")  # what an optimisation's parameters drive (``--actuation``)
MAX_BUDGET = 1_000_000  # evaluations: hours of work, and the history kept in memory stays small
__all__ = ["ACTUATIONS", "COMMANDS", "MAX_BUDGET", "MAX_CAPTURE_HZ", "MAX_NOISE_DEG", "MAX_SEED", "OMITTED_AT_DEFAULT", "PAPER_KD",
           "PAPER_KP", "RunSpec", "collocate_spec", "control_spec", "gradient_for", "model_digest", "motion_digest",
           "optimize_spec", "peer_spec", "with_model_file", "with_motion_file", "with_motion_knots"]


@dataclass(frozen=True)
class RunSpec:
    """Everything that determines a run's numbers (the seed included, the runtime excluded)."""

    command: str = "control"
    motion: str = "paper"  # eq. 5's variant, a named motion of the model or a recorded motion's CSV file (named
    # ``kinematics`` in records, stored settings and the hash, as on the command line)
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
    # how the desired motion is read and estimated
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
    loads: str | None = None  # external loads from data: an OpenSim ExternalLoads file (its content among inputs)
    residual_weight: float | None = None  # optimize on a floating base: eq. 18's residual term, deg per N (N m)
    actuation: str = "torques"  # optimize: "torques" (joint torques) or "muscles" (the muscles' excitations)
    effort_weight: float | None = None  # optimize --actuation muscles: w_e, deg per excitation^2 s (None: default)
    kinematics: InitVar[str | None] = None  # ``motion`` by its stored name (stored settings, the record's field)

    def __post_init__(self, kinematics):
        if kinematics is not None:
            object.__setattr__(self, "motion", kinematics)
        if self.motion == "paper" and self.model_name != "forearm":  # the default motion is the model's own
            try:
                object.__setattr__(self, "motion", default_motion(self.model_name))
            except ValueError:  # an unknown model, or one without motions, is for ``validate`` to refuse
                pass

    def motions(self):
        """(desired, true) motions: the motion given to every method (a noisy capture when
        ``noise_deg`` > 0) and the one its indicators are measured against (``JointMotion``)."""
        return run_inputs.motions(self)

    def reference(self):
        """The inverse dynamics of the nominal model on the true motion, on its samples: what the
        indicators are measured against (``multibody.simulation.JointInverse``)."""
        return run_inputs.reference(self)

    def describe(self) -> dict:
        """The record's fields that say which motion, noise, filter, model and plant a run used."""
        return run_inputs.describe(self)

    def validate(self) -> "RunSpec":
        """Raise ValueError with a one-line message for anything out of range; no work done."""
        if self.command not in COMMANDS:
            raise ValueError(f"unknown command {self.command!r}; valid: {', '.join(COMMANDS)}")
        check_integrator(self.integrator)
        check_conditions(self)
        run_inputs.check(self)
        if self.command == "control":
            if self.controller not in (None, "pd"):
                check_method_options(CONTROLLERS, self.controller, dict(self.method_options), "controller")
            law = run_inputs.controller(self)  # a ValueError names a bad option or gain
            law.check_model(run_inputs.nominal(self))  # one it cannot design for in reasonable time
            law.check_run(run_inputs.nominal(self), run_inputs.motions(self)[0].duration, self.dt)
        if self.command == "peer":
            check_peer_spec(self)
        if self.command == "collocate":
            check_options(**dict(self.method_options))
            check_model(run_inputs.nominal(self))  # one whose equations take minutes to build
        if self.command == "optimize":
            if not isinstance(self.seed, int) or not 0 <= self.seed < MAX_SEED:
                raise ValueError(f"--seed must be an integer in [0, {MAX_SEED - 1}], got {self.seed}")
            if not isinstance(self.budget, int) or not 1 <= self.budget <= MAX_BUDGET:
                raise ValueError(f"--budget must be an integer in [1, {MAX_BUDGET}], got {self.budget}")
            if not (math.isfinite(self.penalty_weight) and self.penalty_weight >= 0):
                raise ValueError(f"--penalty-weight must be a non-negative finite number, got {self.penalty_weight}")
            if self.residual_weight is not None and not (math.isfinite(self.residual_weight)
                                                         and self.residual_weight >= 0):
                raise ValueError(f"--residual-weight must be a non-negative finite number, got {self.residual_weight}")
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
        self._check_actuation()
        self._check_memory()
        return self

    def _check_actuation(self) -> None:
        """--actuation and --effort-weight: ValueError (one line) for a value out of range, an option
        that does not apply, or an optimisation of muscles the model or the method cannot run."""
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"--actuation must be one of {', '.join(ACTUATIONS)}, got {self.actuation!r}")
        if self.actuation != "torques" and self.command not in ("optimize", "collocate"):
            raise ValueError("--actuation applies to optimize and collocate only")
        if self.effort_weight is not None and (self.actuation != "muscles" or self.command != "optimize"):
            raise ValueError("--effort-weight needs optimize --actuation muscles (collocate's is among its options)")
        if self.actuation != "muscles":
            return
        if self.effort_weight is not None and not (math.isfinite(self.effort_weight) and self.effort_weight >= 0):
            raise ValueError(f"--effort-weight must be a non-negative finite number, got {self.effort_weight}")
        model = run_inputs.nominal(self)
        if not model.muscles:
            raise ValueError(f"--actuation muscles: model {self.model_name!r} has no muscles ([[muscles]] in its "
                             "file); use --actuation torques")
        if self.integrator != "rk4":
            raise ValueError(f"--actuation muscles: muscles run on the compiled RK4 only, not --integrator "
                             f"{self.integrator}")
        if self.residual_weight is not None:
            raise ValueError("--residual-weight applies to --actuation torques only")
        if dict(self.torque_options).get("hidden") == "auto":
            raise ValueError("--hidden auto fits the inverse-dynamics torque: give a count with --actuation muscles")

    def _check_memory(self) -> None:
        """ValueError (one line naming the option to change) if the run's arrays would not fit in
        the memory fdbench allows a run (see ``fdbench.memory``)."""
        truth = self.motions()[1]
        population, hidden = 1, 0
        if self.command == "optimize" and self.integrator == "rk4" and self.optimizer == "cmaes":
            population = dict(self.optimizer_options).get("popsize") or 16  # cma's default is smaller
            if self.torque == "ann":
                hidden = dict(self.torque_options).get("hidden", 4)
                hidden = AUTO_MAX_HIDDEN if hidden == "auto" else hidden
        check_run(truth.duration, len(truth.samples), n_joints(self.model_name),
                  self.dt if self.integrator == "rk4" else None, population, hidden)

    def as_dict(self) -> dict:
        """The fields by name, ``motion`` under its stored name ``kinematics`` (in its place)."""
        return {("kinematics" if name == "motion" else name): value for name, value in asdict(self).items()}

    def canonical(self) -> dict:
        """The settings that determine the numbers, normalised so that equivalent specs compare equal
        (fields added since the first results schema left out at their defaults: stored runs keep
        their identity)."""
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
        if dict(self.inputs).get("--loads"):  # and a loads file (with its data)
            data["loads"] = "file"
        if data.get("controller") == "pd":  # the paper's PD is the default controller
            data["controller"] = None
        if data.get("actuation") == "muscles" and data.get("effort_weight") is None and self.command == "optimize":
            # the default, written out (collocate's is among its method options)
            data["effort_weight"] = float(DEFAULT_EFFORT_WEIGHT)
        for name, default in OMITTED_AT_DEFAULT.items():
            if data.get(name) == default:
                data.pop(name)
        return data

    def hash(self) -> str:
        """A digest of the canonical settings (stable across runs and machines), 16 hex digits."""
        text = json.dumps(self.canonical(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


FLOAT_FIELDS = ("dt", "rtol", "atol", "alpha", "xi", "omega", "kp", "kd", "penalty_weight", "cutoff_hz",
                "spline_lambda", "sample_dt", "noise_deg", "capture_hz", "residual_weight", "effort_weight")
def with_model_file(spec: "RunSpec") -> "RunSpec":
    """The spec with its model file's content digest among its inputs (none for a library model)."""
    if not is_file(spec.model_name):
        return spec
    inputs = tuple(p for p in spec.inputs if p[0] != "--model") + (("--model", model_digest(spec.model_name)),)
    return replace(spec, inputs=tuple(sorted(inputs)))


def with_motion_file(spec: "RunSpec") -> "RunSpec":
    """The spec with its recorded motion's content digest among its inputs (none for eq. 5)."""
    if spec.motion in named_motions(spec.model_name):
        return spec
    inputs = tuple(p for p in spec.inputs if p[0] != "--motion") + (("--motion", motion_digest(spec.motion)),)
    return replace(spec, inputs=tuple(sorted(inputs)))
# fields a spec's hash leaves out while they hold these values (added after the first results schema)
OMITTED_AT_DEFAULT = {"inputs": (), "controller": None, "method_options": (), "radians": False,
                      "cutoff_hz": DEFAULT_CUTOFF_HZ, "smoothing": "butterworth", "spline_lambda": None,
                      "sample_dt": None, "noise_deg": 0.0, "capture_hz": DEFAULT_CAPTURE_HZ, "plant": (), "model": (), "gradient": "fd",
                      "model_name": "forearm", "loads": None, "residual_weight": None, "actuation": "torques",
                      "effort_weight": None}


def control_spec(kp=None, kd=None, controller="pd", controller_options=None, **common) -> RunSpec:
    """A control spec: PD (kp, kd; not given: the paper's for the forearm, else None, scaled per
    joint by ``run_inputs.pd_gains``) or another registered controller with its options."""
    options = accepted_options(CONTROLLERS, controller or "pd", controller_options, "controller")
    if controller in (None, "pd"):
        kp, kd = dict(options).get("kp", kp), dict(options).get("kd", kd)
        if common.get("model_name", "forearm") == "forearm":
            kp, kd = PAPER_KP if kp is None else kp, PAPER_KD if kd is None else kd
        return RunSpec(command="control", kp=kp, kd=kd, feedforward=True, **common)
    return RunSpec(command="control", controller=controller, feedforward=True, method_options=options, **common)


def collocate_spec(nodes=100, scheme="hermite-simpson", regularization=None, max_iter=None, max_time=None,
                   residual_force_weight=None, residual_moment_weight=None, actuation="torques", effort_weight=None,
                   **common) -> RunSpec:
    """A direct-collocation spec (see ``fdbench.collocation.collocate``, with ``actuation`` 'muscles'
    ``collocate_muscles`` and its ``effort_weight``); None takes the default (a residual weight's
    depends on the loads, so it is left out of the options). ValueError (one line) for a weight
    that does not apply to the actuation."""
    if actuation == "muscles":
        for option, value in (("--regularization", regularization), ("--residual-force-weight", residual_force_weight),
                              ("--residual-moment-weight", residual_moment_weight)):
            if value is not None:
                raise ValueError(f"{option} applies to --actuation torques only (muscles: --effort-weight)")
        options = dict(nodes=nodes, scheme=scheme, max_iter=DEFAULT_MAX_ITER if max_iter is None else max_iter,
                       max_time=DEFAULT_MAX_TIME if max_time is None else max_time,
                       effort_weight=DEFAULT_EXCITATION_WEIGHT if effort_weight is None else effort_weight)
        return RunSpec(command="collocate", method_options=tuple(sorted(options.items())), actuation=actuation,
                       **common)
    if effort_weight is not None:
        raise ValueError("--effort-weight applies to --actuation muscles only")
    options = dict(nodes=nodes, scheme=scheme,
                   regularization=DEFAULT_REGULARIZATION if regularization is None else regularization,
                   max_iter=DEFAULT_MAX_ITER if max_iter is None else max_iter,
                   max_time=DEFAULT_MAX_TIME if max_time is None else max_time)
    for key, value in (("residual_force_weight", residual_force_weight),
                       ("residual_moment_weight", residual_moment_weight)):
        if value is not None:
            options[key] = value
    return RunSpec(command="collocate", method_options=tuple(sorted(options.items())), **common)


def peer_spec(name: str, options: dict | None = None, kp=None, kd=None, **common):
    """A peer run's spec on the settings ``common`` (as ``control_spec``'s): command "peer", its
    name and options (the peer's defaults where not given) in ``method_options``; the opensim
    peer's PD gains are ``control``'s (the forearm's 80 and 0.3, else scaled per joint)."""
    found = peer(name)
    unknown = sorted(set(options or {}) - set(found.defaults))
    if unknown:
        raise ValueError(f"peer {name}: unknown option {unknown[0]!r}"
                         f" (it takes {', '.join(found.defaults) or 'no options'})")
    values = {**found.defaults, **{k: v for k, v in (options or {}).items() if v is not None}, "peer": name}
    if name == "opensim" and common.get("model_name", "forearm") == "forearm":
        kp, kd = PAPER_KP if kp is None else kp, PAPER_KD if kd is None else kd
    gains = {"kp": kp, "kd": kd, "feedforward": True} if name == "opensim" else {}
    return RunSpec(command="peer", method_options=tuple(sorted(values.items())), **gains, **common)


def optimize_spec(torque="cs", optimizer="bfgs", feedforward=False, seed=0, budget=200,
                  torque_options=None, optimizer_options=None, gradient="fd", *, shared_options=False,
                  **common) -> RunSpec:
    """An optimisation spec. ``torque_options`` and ``optimizer_options`` name options their classes
    take (another name is a ValueError), or, with ``shared_options`` (a sweep's), each keeps those
    it takes."""
    if shared_options:
        torque_options = options_for(TORQUES, torque, torque_options)
        optimizer_options = options_for(OPTIMIZERS, optimizer, optimizer_options)
    options = {k: v for k, v in (optimizer_options or {}).items() if v is not None}
    if torque in TORQUES:  # the parameterisation's defaults for this optimiser, where not given
        options = {**getattr(TORQUES[torque], "optimizer_defaults", {}).get(optimizer, {}), **options}
    spec = RunSpec(command="optimize", torque=torque, optimizer=optimizer, feedforward=feedforward,
                   seed=seed, budget=budget, torque_options=accepted_options(TORQUES, torque, torque_options, "torque"),
                   optimizer_options=accepted_options(OPTIMIZERS, optimizer, options, "optimizer"),
                   gradient=gradient, **common)
    return with_motion_knots(spec, written_out="knots" in (torque_options or {}))


def with_motion_knots(spec: RunSpec, written_out: bool) -> RunSpec:
    """A spline spec without --knots gets one knot every 0.1 s of its motion (``cs.knots_for``),
    among its options if ``written_out`` (the command line's) or unlike the class default."""
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
    uses = optimizer in OPTIMIZERS and getattr(OPTIMIZERS[optimizer], "uses_gradient", False)
    return gradient if uses else "fd"
