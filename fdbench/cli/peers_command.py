"""``fdbench peer``: one peer (OpenSim's forward simulation, its CMCTool, Moco's MocoTrack) run alone, its record
as any run's."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from .app import BadInput, app
from .common import _check_outputs, _check_store, _finish, _save_history, _store, _validated
from .options import (Alpha, Db, Dt, Format, Kinematics, NoiseSeed, Omega, Output, Quiet, SaveHistory, Xi, _common,
                      _noise_seed, _spec_inputs, _with_conditions)

PEER_OPTIONS = ("nodes", "regularization", "tolerance", "max_iter")  # moco's; kp and kd are opensim's


@app.command()
@_with_conditions
def peer(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="opensim|opensim-cmc|moco", help="opensim: OpenSim's forward simulation under fdbench's PD law with computed feedforward, one integrate (beside 'fdbench control'); opensim-cmc: OpenSim's CMCTool tracking the motion with the model made torque-driven (beside 'fdbench control'); moco: OpenSim Moco's MocoTrack, its torque replayed by fdbench's forward simulation (beside 'fdbench collocate').", show_default=False)],
    kp: Annotated[Optional[float], typer.Option("--kp", help="opensim: proportional gain, N m/rad, on every joint (default: fdbench's PD's, 80 on the forearm).", show_default=False)] = None,
    kd: Annotated[Optional[float], typer.Option("--kd", help="opensim: derivative gain, N m s/rad, on every joint (default: fdbench's PD's, 0.3 on the forearm).", show_default=False)] = None,
    nodes: Annotated[int, typer.Option("--nodes", help="moco: mesh intervals over the motion's span, >= 2 (collocate's default).")] = 100,
    regularization: Annotated[float, typer.Option("--regularization", help="moco: weight of the integral of torque^2 beside that of the squared angle error in deg^2, deg^2/(N m)^2 (collocate's).")] = 1e-6,
    tolerance: Annotated[float, typer.Option("--tolerance", help="moco: IPOPT's convergence and constraint tolerance in MocoTrack, in (0, 1).")] = 1e-4,
    max_iter: Annotated[int, typer.Option("--max-iter", help="moco: IPOPT iteration limit, in [1, 1000000].")] = 1000,
    kinematics: Kinematics = None,
    dt: Dt = 1e-3,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Format = "table",
    output: Output = None,
    save_history: SaveHistory = None,
    db: Db = None,
    seed: NoiseSeed = 0,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Run one peer on fdbench's model, motion and indicators: 'fdbench peer opensim --model arm2 -f json'. OpenSim runs in a child process; needs pip install 'fdbench\\[opensim]'."""
    from ..peers import check_available, parse_names, peer_spec

    _check_outputs(fmt, output=output, save_history=save_history, db=db, inputs=_spec_inputs(conditions, kinematics))
    try:
        (name,) = parse_names(name, "PEER")
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    given = {key for key in ("kp", "kd", *PEER_OPTIONS)
             if getattr(ctx.get_parameter_source(key), "name", None) in ("COMMANDLINE", "ENVIRONMENT")}
    takes = {"opensim": {"kp", "kd"}, "opensim-cmc": set()}.get(name, set(PEER_OPTIONS))
    if given - takes:
        wrong = sorted(given - takes)[0]
        raise BadInput(f"--{wrong.replace('_', '-')} does not apply to peer {name} (it takes "
                       f"{', '.join('--' + k.replace('_', '-') for k in sorted(takes)) or 'none of the peer options'})")
    options = dict(nodes=nodes, regularization=regularization, tolerance=tolerance, max_iter=max_iter)
    try:
        spec = peer_spec(name, options if name == "moco" else None, kp, kd, **_noise_seed(conditions, seed),
                         **_common(kinematics, "rk4", dt, 1e-6, 1e-9, alpha, xi, omega, conditions))
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    spec = _validated(spec)
    _check_store(db)
    try:
        check_available()
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    from ..api import run

    outcome = run(spec)
    _store(outcome, spec, db, quiet)  # the run is stored before any output is written
    _save_history(outcome, save_history)
    _finish(outcome.record, fmt, output, f"fdbench peer {name}", quiet)
