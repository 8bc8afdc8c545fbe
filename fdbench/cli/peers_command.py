"""``fdbench peer``: one peer (OpenSim's forward simulation, its CMCTool, Moco's MocoTrack) run alone, its record
as any run's."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from .app import BadInput, app, bad_input
from .common import given, validated
from .conditions import noise_seed, run_fields, spec_inputs, with_conditions
from .options import Alpha, Dt, Kinematics, NoiseSeed, Omega, RunOutputs, Xi, with_groups

PEER_OPTIONS = ("nodes", "regularization", "tolerance", "max_iter")  # moco's; kp and kd are opensim's


@app.command()
@with_conditions
@with_groups
def peer(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(metavar="opensim|opensim-cmc|moco", help="opensim: OpenSim's forward simulation under fdbench's PD law with computed feedforward, one integrate (beside 'fdbench control'); opensim-cmc: OpenSim's CMCTool tracking the motion with the model made torque-driven, or muscle-driven with reserves on a model with muscles (beside 'fdbench control'); moco: OpenSim Moco's MocoTrack, torque-driven, or muscle-driven on a model with muscles, its torque (or excitations and reserves) replayed by fdbench's forward simulation (beside 'fdbench collocate').", show_default=False)],
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
    seed: NoiseSeed = 0,
    out: RunOutputs = None,
    conditions: dict = None,
):
    """Run one peer on fdbench's model, motion and indicators: 'fdbench peer opensim --model arm2 -f json'. OpenSim runs in a child process; needs pip install 'fdbench\\[opensim]'."""
    from ..peers import check_available, parse_names
    from ..spec import peer_spec

    out.check(spec_inputs(conditions, kinematics))
    with bad_input():
        (name,) = parse_names(name, "PEER")
    takes = {"opensim": {"kp", "kd"}, "opensim-cmc": set()}.get(name, set(PEER_OPTIONS))
    wrong = [key for key in ("kp", "kd", *PEER_OPTIONS) if key not in takes and given(ctx, key)]
    if wrong:
        raise BadInput(f"--{min(wrong).replace('_', '-')} does not apply to peer {name} (it takes "
                       f"{', '.join('--' + k.replace('_', '-') for k in sorted(takes)) or 'none of the peer options'})")
    options = dict(nodes=nodes, regularization=regularization, tolerance=tolerance, max_iter=max_iter)
    with bad_input():
        spec = peer_spec(name, options if name == "moco" else None, kp, kd, **noise_seed(conditions, seed),
                         **run_fields(kinematics, "rk4", dt, 1e-6, 1e-9, alpha, xi, omega, conditions))
    spec = validated(spec)
    out.check_store()
    with bad_input():
        check_available()
    from ..method_runs import run

    outcome = run(spec)
    out.deliver(outcome, spec, f"fdbench peer {name}")
