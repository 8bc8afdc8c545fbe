"""Saved optimisation results (``optimize --save-params``) and the torque they define."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import __version__
from .files import BadFile
from .motion import check_kinematics


def params_json(spec, outcome) -> str:
    """JSON text describing the best torque of an optimisation run."""
    data = {
        "fdbench_version": __version__,
        "torque": spec.torque,
        "torque_options": dict(spec.torque_options),
        "n_params": len(outcome.params),
        "feedforward": spec.feedforward,
        "kinematics": spec.kinematics,
        "params": [float(v) for v in outcome.params],
        "rmse_rot_deg": outcome.record["rmse_rot_deg"],
    }
    if data["torque_options"].get("hidden") == "auto":
        data["torque_options"]["hidden"] = (len(outcome.params) - 1) // 3
    return json.dumps(data, indent=2) + "\n"


def load_torque(path, model, option: str = "--params"):
    """The open-loop torque function (t (s) -> N m) of a saved parameter file."""
    from .torques import make_torque

    path = Path(path)
    try:
        data = json.loads(path.read_text())
        name, params = data["torque"], np.asarray(data["params"], dtype=float)
        options, ff, kinematics = dict(data.get("torque_options", {})), data["feedforward"], data["kinematics"]
        if not isinstance(ff, bool):
            raise ValueError("feedforward (true or false)")
        check_kinematics(kinematics)
    except FileNotFoundError:
        raise BadFile(f"{option}: {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise BadFile(f"{option}: cannot read {path} as JSON: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise BadFile(f"{option}: {path} is not a saved parameter file (missing or bad {exc})") from None
    try:
        torque = make_torque(name, **options)
    except ValueError as exc:
        raise BadFile(f"{option}: {path}: {exc}") from None
    if params.shape != (torque.n_params,) or not np.all(np.isfinite(params)):
        raise BadFile(f"{option}: {path}: expected {torque.n_params} finite parameters for {name}")
    from .integrate import Settings
    from .problem import TrackingProblem

    # the problem restores the scaling the parameters refer to and adds the feedforward
    problem = TrackingProblem(torque, Settings(model=model, kinematics=kinematics), ff)
    label = f"{name} (feedforward) from {path.name}" if ff else f"{name} from {path.name}"
    return problem.torque_function(params), label
