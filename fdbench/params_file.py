"""Saved optimisation results (``optimize --save-params``) and the torque they define."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from . import __version__
from .files import BadFile, parse_json, read_input_text
from .method_options import check_method_options
from .models import n_joints, named_motions
from .torques import TORQUES, make_torque

MAX_PARAMS_BYTES = 2**20  # a saved parameter file holds at most a few thousand numbers


def params_json(spec, outcome) -> str:
    """JSON text describing the best torque of an optimisation run (its model, motion, torque
    parameterisation, feedforward and parameters)."""
    motion = spec.motion if spec.motion in named_motions(spec.model_name) else spec.motions()[1].name
    data = {
        "fdbench_version": __version__,
        "model": spec.model_name,
        "torque": spec.torque,
        "torque_options": dict(spec.torque_options),
        "n_params": len(outcome.params),
        "feedforward": spec.feedforward,
        "kinematics": motion,
        "params": [float(v) for v in outcome.params],
        "rmse_rot_deg": outcome.record["rmse_rot_deg"],
    }
    if data["torque_options"].get("hidden") == "auto":  # 3 n + 1 parameters per joint

        joints = n_joints(spec.model_name)
        data["torque_options"]["hidden"] = (len(outcome.params) // joints - 1) // 3
    return json.dumps(data, indent=2) + "\n"


def read_params(path, model: str, motion_name: str, named_motions, option: str = "--params") -> dict:
    """A saved parameter file for ``model`` (files without a model are the forearm's), checked:
    {torque, options, feedforward, kinematics, params (array), digest}. ``kinematics`` is the named
    motion to use, or None when the file's motion is the run's recorded one (``motion_name``).
    Raises BadFile with a one-line message."""
    path = Path(path)
    try:
        data = parse_json(read_input_text(path, option, MAX_PARAMS_BYTES))
    except ValueError as exc:
        raise BadFile(f"{option}: cannot read {path} as JSON: {exc}") from None
    try:
        if not isinstance(data, dict):
            raise TypeError("content: a JSON object")
        name, options, ff, kinematics = data["torque"], data.get("torque_options", {}), data["feedforward"], data["kinematics"]
        saved_model = data.get("model", "forearm")
        for key, value, kind in (("torque", name, str), ("torque_options", options, dict), ("feedforward", ff, bool),
                                 ("kinematics", kinematics, str), ("params", data["params"], list),
                                 ("model", saved_model, str)):
            if not isinstance(value, kind):
                raise TypeError(f"{key} ({kind.__name__})")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in data["params"]):
            raise TypeError("params (a list of numbers)")
        params, options = np.asarray(data["params"], dtype=float), dict(options)
    except (KeyError, TypeError, ValueError) as exc:
        raise BadFile(f"{option}: {path} is not a saved parameter file (missing or bad {exc})") from None
    if saved_model != model:
        raise BadFile(f"{option}: {path} holds parameters optimised for the model {saved_model}; give --model "
                      f"{saved_model}")
    if kinematics not in named_motions and kinematics != motion_name:
        raise BadFile(f"{option}: {path} holds parameters optimised for the motion {kinematics!r}; give that motion "
                      f"with --motion")
    if not np.all(np.isfinite(params)):
        raise BadFile(f"{option}: {path}: the parameters must be finite numbers")
    identity = json.dumps([name, sorted(options.items()), ff, kinematics, params.tolist()]
                          + ([saved_model] if saved_model != "forearm" else []), default=str)
    return {"torque": name, "options": options, "feedforward": ff, "params": params,
            "kinematics": kinematics if kinematics in named_motions else None,
            "digest": hashlib.sha256(identity.encode()).hexdigest(), "path": path}


def make_saved_torque(saved: dict, option: str = "--params"):
    """The torque parameterisation a saved file names with its options (one the torque does not
    take is refused, as a misspelling would be)."""
    try:
        check_method_options(TORQUES, saved["torque"], saved["options"], "torque")
        torque = make_torque(saved["torque"], **saved["options"])
    except (TypeError, ValueError) as exc:
        raise BadFile(f"{option}: {saved['path']}: {exc}") from None
    return torque
