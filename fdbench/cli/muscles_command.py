"""``fdbench muscles``: a model's muscles along a motion, as OpenSim's MuscleAnalysis
(``fdbench.multibody.muscle_analysis``): one row per sample and muscle."""

from __future__ import annotations

import json

from .app import BadInput, app, bad_input
from .common import check_outputs, emit, number_text, text_table, validated, wrote
from .conditions import noise_seed, spec_inputs, with_conditions
from .options import Format, Kinematics, NoiseSeed, Output, Quiet, Simulation

# the columns of a row after t, muscle and before the moment arms: (column, MuscleAnalysis field)
QUANTITY_COLUMNS = (("length", "length"), ("fiber_length", "fiber_length"), ("pennation_angle", "pennation_angle"),
                    ("normalized_fiber_velocity", "fiber_velocity"), ("active_fiber_force", "active_fiber_force"),
                    ("passive_fiber_force", "passive_fiber_force"))
HEADINGS = {"length": "length (m)", "fiber_length": "fibre length (m)", "pennation_angle": "pennation (rad)",
            "normalized_fiber_velocity": "fibre velocity (norm.)", "active_fiber_force": "active force (N)",
            "passive_fiber_force": "passive force (N)"}


@app.command()
@with_conditions
def muscles(
    kinematics: Kinematics = None,
    seed: NoiseSeed = 0,
    fmt: Format = "table",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Each muscle of the model (its [[muscles]]) on each sample of the motion, as OpenSim's MuscleAnalysis: De Groote-Fregly 2016 muscles at full activation.

    --format csv and json give one row per sample and muscle (rows ordered by t, then the model's muscles), its fields: t (s), muscle (its name), length (the muscle-tendon path's, m), fiber_length (m), pennation_angle (rad), normalized_fiber_velocity (fibre velocity / (max_contraction_velocity x optimal_fiber_length); -1 the fastest shortening), active_fiber_force (N, along the fibre, activation 1: F0 f_L f_V), passive_fiber_force (N, along the fibre: F0 (f_PE + damping x velocity)), then <coordinate>_moment_arm for each coordinate of the model (-dl/dq, m per rad or m/m for a translation; 0 for one the path does not span). JSON holds a list of those rows (null where a value is not finite); the table shows each muscle's least and greatest values over the motion. A rigid tendon keeps its slack length: the fibre lies along the path at length - tendon_slack_length, its height optimal_fiber_length x sin(pennation_angle) kept, its velocity cos(pennation) times the path's lengthening speed (moment arms times the coordinates' rates). A compliant tendon is stretched to the fibre's static equilibrium at full activation (zero fibre velocity: tendon force = cos(pennation) (f_L + f_PE), as a simulation starts), and the fibre velocity is that equilibrium's rate along the motion (quasi-static), at which f_V is taken."""
    from ..run_inputs import engine, motions, nominal
    from ..spec import RunSpec

    check_outputs(fmt, output=output, inputs=spec_inputs(conditions, kinematics))
    spec = validated(RunSpec(command="simulate", **noise_seed(conditions, seed),
                             **Simulation().spec_fields(kinematics, conditions)))
    model = nominal(spec)
    if not model.muscles:
        raise BadInput(f"model '{spec.model_name}' has no muscles")
    from ..multibody.muscle_analysis import muscle_analysis

    desired, _ = motions(spec)
    with bad_input():
        z, zd, _ = desired(desired.samples)
        analysis = muscle_analysis(engine(spec, model), z, zd)
    rows = _rows(desired.samples, model, analysis)
    if fmt == "csv":
        from ..files import csv_text

        text = csv_text(list(rows[0]), ([v if isinstance(v, str) else repr(float(v)) for v in row.values()]
                                        for row in rows))
    elif fmt == "json":
        from ..files import finite_or_none

        text = json.dumps([{k: finite_or_none(v) for k, v in row.items()} for row in rows], indent=2) + "\n"
    else:
        arms = {f"{name}_moment_arm": f"{name} arm (m)" for name in model.coordinates}
        text = text_table(f"{spec.model_name}: its muscles over the {len(desired.samples)} samples of motion "
                          f"'{desired.name}' (--format csv or json: every sample)", _ranges(model, analysis),
                          ["muscle", "tendon", "over the motion", *HEADINGS, *arms], HEADINGS | arms)
    emit(text, output)
    wrote(output, quiet)


def _rows(t, model, analysis) -> list[dict]:
    """One dict per sample and muscle: t, muscle, the QUANTITY_COLUMNS, <coordinate>_moment_arm."""
    return [{"t": float(t[i]), "muscle": muscle.name,
             **{column: float(getattr(analysis, field)[i, m]) + 0.0 for column, field in QUANTITY_COLUMNS},
             **{f"{name}_moment_arm": float(analysis.moment_arm[i, m, j]) + 0.0
                for j, name in enumerate(model.coordinates)}}
            for i in range(len(t)) for m, muscle in enumerate(model.muscles)]


def _ranges(model, analysis) -> list[dict]:
    """A person's table: two rows per muscle, each quantity's least and greatest value over the
    motion, the moment arms about the coordinates the muscle spans (blank: the others)."""
    rows = []
    for m, muscle in enumerate(model.muscles):
        spanned = [j for j in range(len(model.coordinates)) if (analysis.moment_arm[:, m, j] != 0.0).any()]
        for bound, reduce in (("least", "min"), ("greatest", "max")):
            row = {"muscle": muscle.name if bound == "least" else "", "tendon": muscle.tendon if bound == "least" else "",
                   "over the motion": bound}
            row.update({column: float(getattr(getattr(analysis, field)[:, m], reduce)()) + 0.0
                        for column, field in QUANTITY_COLUMNS})
            row.update({f"{model.coordinates[j]}_moment_arm": float(getattr(analysis.moment_arm[:, m, j], reduce)()) + 0.0
                        for j in spanned})
            rows.append(row)
    return rows
