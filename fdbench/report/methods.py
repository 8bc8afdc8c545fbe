"""The report's registered one-run methods: open loop, PD, computed torque, LQR, direct collocation
and splines tuned by CMA-ES or by BFGS with exact gradients, and on a model with muscles computed
muscle control and muscle-driven collocation; each one run per dataset (each is
deterministic; the shooting optimisation takes seed 0), stored and reused by spec hash like every
run of the report. A dataset is a model, a motion and its loads (``Dataset``); a method says
whether it applies to a dataset and, if not, why (``Method.skip``: one line in the report, like
benchopt's ``Solver.skip``). On the forearm the paper's report gives computed torque, LQR and
collocation (and a model with muscles its muscle-driven methods) the section "Beyond the paper"; on
a model with a floating base the report runs them all, and the same on the forearm to test the
paper's claim (``comparison``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from ..spec import RunSpec, collocate_spec, control_spec, optimize_spec

COLLOCATION_SUMMARY = ("states and torque are the unknowns of one sparse problem whose defects discretise the "
                       "equation of motion, solved by IPOPT (as OpenSim Moco, bioptim and Drake do); fdbench replays "
                       "the torque found through its own forward simulation, and the indicators are the replay's")
MUSCLE_COLLOCATION_SUMMARY = ("the same transcription with the muscles: activations are states, excitations "
                              "and reserve torques unknowns, the inverse dynamics equal to the muscles' generalised "
                              "forces plus the reserves at every point, tendons taken as rigid (as Moco's MocoTrack "
                              "with De Groote muscles); fdbench replays the excitations and reserves")
EXCITATIONS_SUMMARY = ("a cubic spline per muscle (a knot every 0.1 s) through a logistic into its excitation in "
                       "(0, 1), added to the logit of static optimisation's as feedforward, tuned on eq. 18 plus the "
                       "effort (1 deg per excitation^2 s), with no joint torques and no reserves (SCONE's approach)")
EXACT_GRADIENT_SUMMARY = ("the paper's cell with the gradient computed exactly, by forward sensitivities of the "
                          "RK4 simulation, instead of by finite differences; a simulation with its sensitivities "
                          "counts as one evaluation of the budget; seed 0")

OPEN_LOOP, PD, COMPUTED_TORQUE, LQR, COLLOCATION, CMAES, BFGS, CMC, MUSCLE_COLLOCATION = (
    "open-loop", "pd", "computed-torque", "lqr", "collocation", "cs-cmaes", "cs-bfgs", "cmc", "muscle-collocation")
EXCITATIONS_CMAES, EXCITATIONS_BFGS = "excitations-cmaes", "excitations-bfgs"
# the methods "Beyond the paper" (the paper's report of a model on a fixed base), then those that
# drive a model's muscles (on a model with muscles only): control, collocation, optimised excitations
BEYOND = (COMPUTED_TORQUE, LQR, COLLOCATION)
MUSCLE_DRIVEN = (CMC, MUSCLE_COLLOCATION, EXCITATIONS_CMAES, EXCITATIONS_BFGS)
# every registered method, in the report's order
EVERY = (OPEN_LOOP, PD, COMPUTED_TORQUE, LQR, COLLOCATION, CMAES, BFGS)
# the order in which their runs are handed out, the slowest first (so that workers share the work evenly)
SLOWEST_FIRST = (COLLOCATION, MUSCLE_COLLOCATION, EXCITATIONS_BFGS, EXCITATIONS_CMAES, COMPUTED_TORQUE, BFGS, CMAES,
                 CMC, LQR, PD, OPEN_LOOP)

# the shooting methods' defaults on a model with a floating base: the paper's budget of 200
# simulations, in generations of 8
SHOOTING_POPSIZE = 8
# eq. 18's penalty weight on a floating base (deg for the whole motion missed): the paper's 1 deg is
# small beside a falling model's error (open loop's RMSE on the walk until its fall is about 30 deg),
# so an optimiser would buy a smaller RMSE by falling sooner; at 1000 deg, 0.1 s more of a 2.5-s
# walk (40 deg) outweighs such errors: reaching further counts first, as in the report's ranking
FLOATING_BASE_PENALTY = 1000.0
# IPOPT's CPU time (s) for the report's muscle-driven collocation: the walk's 18 muscles need about 160
# iterations, 5 to 6 minutes, where collocate's default of 60 s stops it after about 35 (arm26: 5 s)
MUSCLE_COLLOCATION_MAX_TIME = 600.0


@dataclass(frozen=True)
class Dataset:
    """What the methods run on: a label ("walk", "forearm"), the RunSpec fields of the model, motion,
    loads and simulation settings (``common``), and eq. 18's penalty weight there (deg)."""

    label: str
    common: dict
    penalty_weight: float = 1.0


@dataclass(frozen=True)
class Options:
    """The report's options that shape the methods' runs: the shooting's budget, population, CMA-ES
    step, spline knots; PD's gains (None: the model's defaults); CMC's options (window, reserves'
    optimal force, tendons)."""

    budget: int = 200
    popsize: int = SHOOTING_POPSIZE
    sigma0: float | None = None
    knots: int | None = None
    kp: float | None = None
    kd: float | None = None
    cmc: tuple = ()  # computed muscle control's options given, sorted (name, value) pairs


@dataclass(frozen=True)
class Method:
    """One row of the report: the registered method's key, label, one sentence on what it does, and
    the run's specification."""

    name: str
    description: str
    spec: RunSpec
    key: str = ""


@dataclass(frozen=True)
class Registered:
    """A registered method: its key, label and description (both given the options), the spec it
    runs on a dataset, and ``skip`` (a reason it does not apply to a dataset, or None)."""

    key: str
    label: Callable
    description: Callable
    spec: Callable
    skip: Callable = field(default=lambda dataset, options: None)

    def method(self, dataset: Dataset, options: Options) -> Method:
        return Method(self.label(options), self.description(dataset, options), self.spec(dataset, options), self.key)


def _shooting(optimizer: str, dataset: Dataset, options: Options, gradient: str = "fd", **more) -> RunSpec:
    optimizer_options = {"popsize": options.popsize} if optimizer == "cmaes" else {}
    if optimizer == "cmaes" and options.sigma0 is not None:
        optimizer_options["sigma0"] = options.sigma0
    torque_options = {} if options.knots is None else {"knots": options.knots}
    return optimize_spec("cs", optimizer, True, 0, options.budget, torque_options, optimizer_options,
                         gradient=gradient, shared_options=True, penalty_weight=dataset.penalty_weight,
                         **dataset.common, **more)


def _bfgs_skip(dataset: Dataset, options: Options) -> str | None:
    try:
        _shooting("bfgs", dataset, options, gradient="exact").validate()
    except ValueError as exc:
        return (f"BFGS with exact gradients is not in this report: {exc}. BFGS with finite differences is left "
                "out too: each gradient would cost one simulation per spline parameter, more than the whole budget.")
    return None


def _muscles_skip(spec: Callable, name: str) -> Callable:
    """A ``skip`` for a method that drives the muscles: the reason its spec (``spec(dataset, options)``)
    is refused on a dataset (a model without muscles), or None."""
    def skip(dataset: Dataset, options: Options) -> str | None:
        try:
            spec(dataset, options).validate()
        except ValueError as exc:
            return f"{name} is not in this report: {exc}"
        return None
    return skip


def _excitations_spec(optimizer: str, gradient: str = "fd") -> Callable:
    """The spec of the cubic splines on the muscles' excitations, with static optimisation's as
    feedforward, tuned by ``optimizer`` (seed 0, the report's budget)."""
    return lambda dataset, options: _shooting(optimizer, dataset, options, gradient, actuation="muscles")


def _excitations_skip(optimizer: str, gradient: str = "fd") -> Callable:
    """A ``skip`` for an optimisation of excitations: a model without muscles, or compliant tendons
    that RK4 cannot step at the dataset's --dt (their stable step at the motion's start with every
    muscle at its least activation: a run would fail at once)."""
    spec_of = _excitations_spec(optimizer, gradient)
    refused = _muscles_skip(spec_of, "optimisation of the muscles' excitations")

    def skip(dataset: Dataset, options: Options) -> str | None:
        reason = refused(dataset, options)
        if reason is not None:
            return reason
        spec = spec_of(dataset, options)
        limit = _compliant_step(spec)
        if limit is not None and spec.dt > limit[1]:
            dt = spec.dt
            return (f"optimisation of the muscles' excitations is not in this report: the model's compliant tendons "
                    f"need --dt below {limit[1]:.2g} s for RK4 to be stable ({limit[0]}'s near slack, at the least "
                    f"activation), and --dt is {dt:g} s: run the report with --dt {limit[1] / 2:.1g}, or give the "
                    "muscles rigid tendons")
        return None
    return skip


def _compliant_step(spec: RunSpec) -> tuple[str, float] | None:
    """(muscle, RK4's stable step (s)) of the stiffest compliant tendon at the spec's motion's start,
    every muscle at its least activation; None without compliant tendons."""
    import numpy as np

    from ..multibody.muscle import MIN_ACTIVATION
    from ..multibody.simulation import compliant_step_limits
    from ..run_inputs import engine, motions

    body = engine(spec)
    if not any(muscle.tendon == "compliant" for muscle in body.model.muscles):
        return None
    z, zd, _ = motions(spec)[0](np.zeros(1))
    limits = compliant_step_limits(body, z[0], zd[0], np.full(len(body.model.muscles), MIN_ACTIVATION))
    return min(limits, key=lambda pair: pair[1]) if limits else None


def _cmc_spec(dataset: Dataset, options: Options) -> RunSpec:
    """CMC with the model's tendons, or with rigid ones where a compliant tendon needs RK4 steps
    below CMC's (``_cmc_rigid``)."""
    given = dict(options.cmc)
    if "tendons" not in given and _cmc_rigid(dataset) is not None:
        given["tendons"] = "rigid"
    return control_spec(controller="cmc", controller_options=given or None, **dataset.common)


def _cmc_rigid(dataset: Dataset) -> tuple[str, float] | None:
    """(muscle, its stable step (s)) where the stiffest compliant tendon at the motion's start, every
    muscle at its least activation, needs RK4 steps below CMC's with compliant tendons: CMC then
    takes every tendon as rigid, as muscle-driven collocation does; None otherwise."""
    from ..controllers.cmc import COMPLIANT_MAX_STEP

    spec = control_spec(controller="cmc", **dataset.common)
    try:
        spec.validate()
    except ValueError:
        return None
    limit = _compliant_step(spec)
    return limit if limit is not None and limit[1] < COMPLIANT_MAX_STEP else None


def _cmc_description(dataset: Dataset, options: Options) -> str:
    from ..controllers.cmc import COMPLIANT_MAX_STEP

    given = dict(options.cmc).get("tendons")
    if given == "rigid":
        return _summary("cmc") + "; tendons taken as rigid (--tendons rigid), as collocation takes them"
    rigid = None if given else _cmc_rigid(dataset)
    if rigid is None:
        return _summary("cmc")
    return (_summary("cmc") + f"; tendons taken as rigid (--tendons rigid), as collocation takes them: the model's "
            f"compliant tendons would need RK4 steps below {rigid[1]:.2g} s ({rigid[0]}'s near slack, at the least "
            f"activation), CMC's with compliant tendons is {COMPLIANT_MAX_STEP:g} s")


def _muscle_collocation_spec(dataset: Dataset, options: Options) -> RunSpec:
    return collocate_spec(_nodes(), "hermite-simpson", actuation="muscles", max_time=MUSCLE_COLLOCATION_MAX_TIME,
                          **dataset.common)


def _cmc_label() -> str:
    from ..multibody.cmc import DEFAULT_KD, DEFAULT_KP, DEFAULT_WINDOW

    return f"Computed muscle control (kp {DEFAULT_KP:g}, kd {DEFAULT_KD:g}, window {DEFAULT_WINDOW:g} s)"


def _summary(name: str) -> str:
    from ..controllers import CONTROLLERS

    return CONTROLLERS[name].summary


def _cmaes_description(dataset: Dataset, options: Options) -> str:
    from ..problem import DEFAULT_RESIDUAL_WEIGHT

    return ("a cubic spline per coordinate (a knot every 0.1 s) added to the inverse-dynamics torques, "
            f"tuned by CMA-ES (population {options.popsize}, seed 0) on eq. 18 (a fall penalised by "
            f"{dataset.penalty_weight:g} deg; on a floating base with loads, the residuals' RMS by "
            f"{DEFAULT_RESIDUAL_WEIGHT:g} deg per N and per N m)")


def _nodes() -> int:
    from ..collocation import DEFAULT_NODES

    return DEFAULT_NODES


REGISTRY = {registered.key: registered for registered in (
    Registered(OPEN_LOOP, lambda o: "Open loop (inverse-dynamics torques)",
               lambda d, o: "the inverse-dynamics torques (on a floating base, its residual forces and moment too) "
                            "applied without feedback (PD with Kp = Kd = 0)",
               lambda d, o: control_spec(kp=0.0, kd=0.0, **d.common)),
    Registered(PD, lambda o: "PD + feedforward", lambda d, o: _summary("pd"),
               lambda d, o: control_spec(kp=o.kp, kd=o.kd, **d.common)),
    Registered(COMPUTED_TORQUE, lambda o: "Computed torque (omega_n 20 rad/s, zeta 1)",
               lambda d, o: _summary("computed-torque"),
               lambda d, o: control_spec(controller="computed-torque",
                                         controller_options=dict(bandwidth=20.0, damping=1.0), **d.common)),
    Registered(LQR, lambda o: "Time-varying LQR (q 1e4, 1; r 1)", lambda d, o: _summary("lqr"),
               lambda d, o: control_spec(controller="lqr", **d.common)),
    Registered(COLLOCATION, lambda o: f"Direct collocation (Hermite-Simpson, {_nodes()} intervals) + forward replay",
               lambda d, o: COLLOCATION_SUMMARY,
               lambda d, o: collocate_spec(_nodes(), "hermite-simpson", **d.common)),
    Registered(CMAES, lambda o: f"CS + CMA-ES + ff (budget {o.budget})", _cmaes_description,
               lambda d, o: _shooting("cmaes", d, o)),
    Registered(BFGS, lambda o: f"CS + BFGS + ff, exact gradient (budget {o.budget})",
               lambda d, o: "the same splines tuned by BFGS with gradients by forward sensitivities",
               lambda d, o: _shooting("bfgs", d, o, gradient="exact"), _bfgs_skip),
    Registered(CMC, lambda o: _cmc_label(), _cmc_description, _cmc_spec,
               _muscles_skip(_cmc_spec, "computed muscle control")),
    Registered(MUSCLE_COLLOCATION, lambda o: f"Direct collocation of the muscles ({_nodes()} intervals) + forward replay",
               lambda d, o: MUSCLE_COLLOCATION_SUMMARY, _muscle_collocation_spec,
               _muscles_skip(_muscle_collocation_spec, "muscle-driven collocation")),
    Registered(EXCITATIONS_CMAES, lambda o: f"CS excitations + CMA-ES + ff (budget {o.budget})",
               lambda d, o: EXCITATIONS_SUMMARY + f"; CMA-ES (population {o.popsize}, seed 0)",
               _excitations_spec("cmaes"), _excitations_skip("cmaes")),
    Registered(EXCITATIONS_BFGS, lambda o: f"CS excitations + BFGS + ff, exact gradient (budget {o.budget})",
               lambda d, o: EXCITATIONS_SUMMARY + "; BFGS with gradients by forward sensitivities through the "
                                                  "activation and tendon states",
               _excitations_spec("bfgs", "exact"), _excitations_skip("bfgs", "exact")),
)}


def select(keys, datasets: list[Dataset], options: Options) -> tuple[list[str], list[tuple[str, str]]]:
    """The keys among ``keys`` that apply to every dataset, and (key, reason) for each that does
    not (the first dataset's reason)."""
    kept, skipped = [], []
    for key in keys:
        reasons = [REGISTRY[key].skip(dataset, options) for dataset in datasets]
        reason = next((r for r in reasons if r), None)
        if reason is None:
            kept.append(key)
        else:
            skipped.append((key, reason))
    return kept, skipped


def methods(keys, dataset: Dataset, options: Options | None = None) -> list[Method]:
    """The registered methods ``keys`` on ``dataset``."""
    options = options or Options()
    return [REGISTRY[key].method(dataset, options) for key in keys]


def beyond_methods(options: Options | None = None, **common) -> tuple[list[Method], list[tuple[str, str]]]:
    """The methods "Beyond the paper" with their default options (the optimisations of excitations
    ``options``' budget and population), on the settings ``common`` (kinematics, integrator, dt,
    rtol, atol, alpha, xi, omega, conditions, model_name): computed torque, LQR and direct
    collocation, on the forearm or on another model (the arm), and on a model with muscles computed
    muscle control, muscle-driven collocation and the optimisations of excitations; and (key,
    reason) of each muscle-driven method left out on a model with muscles."""
    dataset, options = Dataset("", common), options or Options()
    muscle_driven, skipped = select(MUSCLE_DRIVEN, [dataset], options)
    if len(skipped) == len(MUSCLE_DRIVEN):  # a model without muscles: nothing to say
        skipped = []
    return methods(BEYOND + tuple(muscle_driven), dataset, options), skipped


def exact_gradient_methods(cells, budget, torque_options, optimizer_options, penalty_weight, **common) -> list[Method]:
    """A row per gradient-based cell of ``cells`` (``paper_methods.Cell``) run with ``--gradient
    exact`` (seed 0: one run, like the other rows of the table)."""
    from ..spec import gradient_for

    out = []
    for cell in cells:
        if gradient_for(cell.optimizer, "exact") != "exact":
            continue
        ff = " + ff" if cell.feedforward else ""
        spec = optimize_spec(cell.torque, cell.optimizer, cell.feedforward, 0, budget, torque_options,
                             optimizer_options, gradient="exact", penalty_weight=penalty_weight,
                             shared_options=True, **common)
        out.append(Method(f"{cell.torque.upper()} + {cell.optimizer}{ff}, exact gradient", EXACT_GRADIENT_SUMMARY,
                          spec, f"{cell.torque}-{cell.optimizer}{'-ff' if cell.feedforward else ''}-exact"))
    return out


def rows(methods: list[Method], runs: dict, provenance: dict | None = None, table: str = "beyond") -> list:
    """The report rows (``paper.Row``, one run each, in ``table``) of the methods from their stored
    runs ({spec hash: stored run}); ``provenance`` ({hash: info}, from ``Store.provenance``) adds
    when and where each was made."""
    from .paper import Row
    from .paper_methods import summarise

    provenance = provenance or {}
    out = []
    for method in methods:
        key = method.spec.hash()
        record = runs[key]["record"]
        out.append(Row(method.name, table, None, summarise([record]), None, [record],
                       provenance=[provenance[key]] if key in provenance else [], hashes=[key], specs=[method.spec],
                       key=method.key))
    return out


def beyond_markdown(rows: list, methods: list[Method], skipped=()) -> list[str]:
    """The section's Markdown lines: one sentence per method, then the table (PD's columns), and a
    line per method left out (``skipped``: (key, reason))."""
    from .paper import results_table, failure_lines, significant

    if not rows:
        return []
    out = ["## Beyond the paper", "",
           "The methods the field uses today, on the same model, motion and indicators (one run each: "
           "they are deterministic; the paper has no figures for them):", ""]
    described = {}
    for m in methods:  # one line per description (the exact-gradient rows share theirs)
        described.setdefault(m.description, []).append(m.name)
    out += [f"- {'; '.join(names)}: {description}." for description, names in described.items()]
    out += [f"- {reason.rstrip('.')}." for reason in dict.fromkeys(reason for _, reason in skipped)]
    out += [""] + results_table(rows, with_success=False)
    for row in (r for r in rows if r.records[0].get("command") == "collocate"):
        rec = row.records[0]
        out += ["", f"{row.name}: its own RMSE_rot at its nodes {significant(rec.get('collocation_rmse_rot_deg'))} "
                    f"deg; IPOPT: {rec.get('ipopt_status')}, {rec.get('ipopt_iterations')} iterations, "
                    f"{significant(rec.get('solve_time_s'))} s."]
    out += muscles_markdown(rows)
    failed = failure_lines(rows)
    if failed:
        out += ["", "Did not succeed (`status`, `t_end` and `message` in the CSV and JSON):", ""] + failed
    return out + [""]


def muscles_markdown(rows: list) -> list[str]:
    """The muscles' table of the rows whose run drove the model's muscles (a record with ``effort``):
    effort (the mean of sum a^2 over the samples reached), the reserves' RMS torque, the torque left
    unmet where a coordinate has no reserve, and each muscle's mean activation; [] without such rows."""
    from ..outcomes import ACTIVATION_MEAN, FULL_ACTIVATION
    from .paper import significant

    driven = [row for row in rows if row.records[0].get("effort") is not None]
    if not driven:
        return []
    muscles = [key[:-len(ACTIVATION_MEAN)] for key in driven[0].records[0] if key.endswith(ACTIVATION_MEAN)]
    unmet = any(row.records[0].get("unmet_rms_nm") is not None for row in driven)
    header = ["method", "effort (mean sum a^2)", "reserves RMS (N m)", *(["unmet RMS (N m)"] if unmet else []),
              *(f"{m} mean a" for m in muscles)]
    out = ["", "The muscles (activations a in [0, 1]; the reserves are the model's actuators, else one per "
               "coordinate; unmet: the torque of a coordinate without a reserve that its muscles did not give):",
           "", "| " + " | ".join(header) + " |", "|---|" + "---:|" * (len(header) - 1)]
    for row in driven:
        rec = row.records[0]
        cells = [rec.get("effort"), rec.get("reserve_rms_nm"), *([rec.get("unmet_rms_nm")] if unmet else []),
                 *(rec.get(m + ACTIVATION_MEAN) for m in muscles)]
        out.append("| " + " | ".join([row.name, *(significant(v) for v in cells)]) + " |")
    full = [f"- {row.name}: {row.records[0]['saturation']}." for row in driven if row.records[0].get("saturation")]
    if full:
        out += ["", f"At full activation (a >= {FULL_ACTIVATION:g}: the muscle gives all it can, the reserves or "
                    "the tracking take the rest):", ""] + full
    return out


def method_csv_rows(rows: list, named=None) -> list[list]:
    """CSV rows (the paper report's ``CSV_COLUMNS``) of one-run rows, the method named in
    ``torque``: by ``named(record)`` when given, else its controller, torque or command."""
    from .paper import CSV_COLUMNS, csv_rows

    out = csv_rows(rows)
    for values, row in zip(out, rows):
        rec = row.records[0]
        if named is not None:
            fixed = {"torque": named(rec), "feedforward": rec.get("feedforward"), "in_paper": False, "optimizer": ""}
        else:
            method = rec.get("torque") if rec.get("command") == "optimize" else rec.get("command")
            fixed = {"torque": rec.get("controller") or method, "feedforward": rec.get("feedforward"),
                     "in_paper": False}
        for column, value in fixed.items():
            values[CSV_COLUMNS.index(column)] = value
    return out


def beyond_csv_rows(rows: list) -> list[list]:
    """CSV rows (the report's ``CSV_COLUMNS``) of the table "Beyond the paper"."""
    return method_csv_rows(rows)
