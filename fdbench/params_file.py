"""Saved optimisation results (``optimize --save-params``) and the torque they define."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from . import __version__
from .files import BadFile, read_input_text
from .motion import KINEMATICS

MAX_PARAMS_BYTES = 2**20  # a saved parameter file holds at most a few thousand numbers


def params_json(spec, outcome) -> str:
    """JSON text describing the best torque of an optimisation run."""
    data = {
        "fdbench_version": __version__,
        "torque": spec.torque,
        "torque_options": dict(spec.torque_options),
        "n_params": len(outcome.params),
        "feedforward": spec.feedforward,
        "kinematics": spec.settings().motion.name if spec.kinematics not in KINEMATICS else spec.kinematics,
        "params": [float(v) for v in outcome.params],
        "rmse_rot_deg": outcome.record["rmse_rot_deg"],
    }
    if data["torque_options"].get("hidden") == "auto":
        data["torque_options"]["hidden"] = (len(outcome.params) - 1) // 3
    return json.dumps(data, indent=2) + "\n"


def load_torque(path, settings, option: str = "--params"):
    """The open-loop torque function (t (s) -> N m) of a saved parameter file, a label, and a
    digest of what the file defines (the torque, its options, feedforward, kinematics, parameters)."""
    from .torques import make_torque

    path = Path(path)
    try:
        data = json.loads(read_input_text(path, option, MAX_PARAMS_BYTES))
    except (json.JSONDecodeError, RecursionError) as exc:
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        raise BadFile(f"{option}: cannot read {path} as JSON: {reason}") from None
    try:
        if not isinstance(data, dict):
            raise TypeError("content: a JSON object")
        name, options, ff, kinematics = data["torque"], data.get("torque_options", {}), data["feedforward"], data["kinematics"]
        for key, value, kind in (("torque", name, str), ("torque_options", options, dict), ("feedforward", ff, bool),
                                 ("kinematics", kinematics, str), ("params", data["params"], list)):
            if not isinstance(value, kind):
                raise TypeError(f"{key} ({kind.__name__})")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in data["params"]):
            raise TypeError("params (a list of numbers)")
        params, options = np.asarray(data["params"], dtype=float), dict(options)
        if kinematics in KINEMATICS:
            settings = replace(settings, kinematics=kinematics)
        elif kinematics != settings.motion.name:
            raise ValueError(f"kinematics: these parameters were optimised for the motion {kinematics!r}; "
                             f"give that motion with --motion")
    except (KeyError, TypeError, ValueError) as exc:
        raise BadFile(f"{option}: {path} is not a saved parameter file (missing or bad {exc})") from None
    try:
        torque = make_torque(name, **options)
    except (TypeError, ValueError) as exc:
        raise BadFile(f"{option}: {path}: {exc}") from None
    if params.shape != (torque.n_params,) or not np.all(np.isfinite(params)):
        raise BadFile(f"{option}: {path}: expected {torque.n_params} finite parameters for {name}")
    from .problem import TrackingProblem

    # the problem restores the scaling the parameters refer to and adds the feedforward
    problem = TrackingProblem(torque, settings, ff)
    label = f"{name} (feedforward) from {path.name}" if ff else f"{name} from {path.name}"
    identity = json.dumps([name, sorted(options.items()), ff, kinematics, params.tolist()], default=str)
    return problem.torque_function(params), label, hashlib.sha256(identity.encode()).hexdigest()
