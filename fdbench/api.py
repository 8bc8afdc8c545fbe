"""The few entry points a Python script needs, re-exported lazily by ``fdbench`` itself:

    import fdbench
    outcome = fdbench.run(fdbench.optimize_spec("cs", "bfgs", budget=50))
    outcome.record["rmse_rot_deg"]                      # deg
    fdbench.simulate().record["rmse_rot_deg"]           # open loop, inverse-dynamics torque
    frame = fdbench.load_report("fdbench-results.sqlite")  # the report's table, a DataFrame

Runs, specifications and records are those of the command line: ``run``, ``run_simulation``,
``replay`` and ``inverse_run`` carry out a ``RunSpec`` (``fdbench.spec``) on the multibody engine
(``fdbench.method_runs``, one runner per command) and return its flat record
(``fdbench.records``); the registries ``TORQUES`` and ``OPTIMIZERS`` take new methods by decorator.
"""

from __future__ import annotations

from pathlib import Path

from .method_runs import inverse_run, replay, run, run_simulation  # noqa: F401 (the API's names)
from .spec import RunSpec  # noqa: F401


# the method options of 'fdbench report' by default (its runs are stored under these settings)
REPORT_TORQUE_OPTIONS = {"hidden": 4, "knots": None, "terms": 4}  # knots None: one every 0.1 s of the motion
REPORT_OPTIMIZER_OPTIONS = {"sigma0": None, "popsize": None}  # None: each torque's default


def simulate(torque=None, **settings):
    """Open-loop forward dynamics over the motion (eq. 5: [0, 1] s); returns a ``RunOutcome``
    whose ``record`` holds the indicators (``rmse_rot_deg``, ``rmse_torque_nm``, ``runtime_s``,
    ``t_end``, ``status``...) and whose ``result`` holds the histories on the motion's samples.

    ``torque``: None for the inverse-dynamics torque, or a function of the times (s, shape
    (n,)) returning the elbow torque (N m, shape (n,); for another model, e.g. ``model_name="arm2"``, the joint
    torques, shape (n, 2)). ``settings``: the fields of ``RunSpec`` (``kinematics``,
    ``integrator``, ``dt``, ``rtol``, ``atol``, ``alpha``, ``xi``, ``omega``, ``model_name``...);
    a bad value raises ValueError."""
    spec = RunSpec(command="simulate", **settings).validate()
    if torque is not None and not callable(torque):
        raise TypeError("torque must be None or a function of time (s) returning N m")
    return run_simulation(spec, torque=torque)


def inverse_dynamics(**settings):
    """The nominal model's inverse dynamics on the motion's samples (``multibody.simulation.JointInverse``:
    ``t`` (s), ``angles`` (rad), ``velocities``, ``accelerations`` and ``torque`` (N m), each of
    shape (n, J)); ``settings``: the fields of ``RunSpec`` (``model_name``, ``kinematics``, ``model``...)."""
    return RunSpec(command="simulate", **settings).validate().reference()


def load_runs(db) -> "pandas.DataFrame":  # noqa: F821
    """Every run stored in the results database ``db`` (a path), one row each: the record's
    fields (indicators in deg, N m, s) plus ``id``, ``created_at`` (UTC) and ``machine``."""
    import pandas as pd

    from .store import open_store

    db = _existing(db)
    with open_store(db) as store:
        hashes = [r["spec_hash"] for r in store.records()]
        made = store.provenance(hashes)
        rows = [{**record, **made.get(record["spec_hash"], {})} for record in store.records()]
    return pd.DataFrame(rows)


def load_report(db, seeds: int = 5, budget: int = 200, run_missing: bool = False, jobs: int = 1,
                **options) -> "pandas.DataFrame":  # noqa: F821
    """The report's table (one row per cell, the columns of ``fdbench report --format csv``)
    from the runs stored in ``db``, as a DataFrame.

    ``seeds``, ``budget`` and ``options`` (``torques``, ``optimizers``, ``feedforward``,
    ``all_cells``, ``control``, ``kp``, ``kd``, ``torque_options``, ``optimizer_options``,
    ``kinematics``, ``integrator``...) select the runs as the command's options do. Runs missing from the store raise LookupError, unless
    ``run_missing``: then they are made (``jobs`` worker processes) and stored."""
    import pandas as pd

    from .report.paper_methods import default_cells, execute, make_plan
    from .report import CSV_COLUMNS, build_rows, csv_rows
    from .store import open_store

    cells = default_cells(options.pop("torques", None), options.pop("optimizers", None),
                          options.pop("feedforward", None), options.pop("all_cells", False))
    options["torque_options"] = {**REPORT_TORQUE_OPTIONS, **(options.get("torque_options") or {})}
    options["optimizer_options"] = {**REPORT_OPTIMIZER_OPTIONS, **(options.get("optimizer_options") or {})}
    plan = make_plan(cells, seeds, budget, **options)
    if not run_missing:
        db = _existing(db)
    with open_store(db) as store:
        missing = [s for s in plan.all_specs() if s.hash() not in store.hashes()]
        if missing and not run_missing:
            raise LookupError(f"{len(missing)} of {len(plan.all_specs())} runs of this report are not stored in "
                              f"{db}: run 'fdbench report --db {db}' with the same options, or pass run_missing=True")
        runs = execute(plan, store, jobs)
        made = store.provenance(runs)
    return pd.DataFrame(csv_rows(build_rows(plan, runs, made)), columns=list(CSV_COLUMNS))


def _existing(db) -> Path:
    path = Path(db)
    if not path.is_file():
        raise FileNotFoundError(f"no results database {path}")
    return path
