"""OpenSim in a child process (its own CasADi cannot share fdbench's): a peer's request (JSON on
stdin) in, one JSON line out. Parent side: ``call(request)``; child side: ``main()`` dispatches to
the peer module's ``solve(osim, request)``, with the helpers the peers share."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

from ..files import shown
from ..isolation import python_command
from ..multibody.osim import INSTALL_HINT

CHILD_TIMEOUT_S = 3600  # s: a MocoTrack solve of a large model may take long
ENTRY = "from fdbench.peers.child import main; main()"
SOLVERS = {"opensim": "fdbench.peers.opensim_pd", "opensim-cmc": "fdbench.peers.cmc", "moco": "fdbench.peers.moco"}


class PeerUnavailable(ValueError):
    """The opensim package cannot be imported where the peers run (one line naming the extra)."""


def call(request: dict, timeout_s: float = CHILD_TIMEOUT_S) -> dict:
    """The child's answer (a dict) to ``request``; PeerUnavailable without the opensim package,
    RuntimeError (one line) when the child fails."""
    try:
        with tempfile.TemporaryDirectory(prefix="fdbench-opensim-") as folder:  # its working directory: MocoTrack
            # writes '<name>_tracked_states.sto' there, which must not land in the user's
            done = subprocess.run(python_command(ENTRY), input=json.dumps(request), capture_output=True,
                                  text=True, timeout=timeout_s, cwd=folder)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"OpenSim's process did not finish within {timeout_s:g} s") from None
    try:
        answer = json.loads(done.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"OpenSim's process failed (exit {done.returncode}): {shown(last, 300)}") from None
    if answer.get("unavailable"):
        raise PeerUnavailable(f"the peers run OpenSim and need the opensim package: {INSTALL_HINT}")
    if "error" in answer:
        raise RuntimeError(answer["error"])
    return answer


def opensim_version() -> str:
    """OpenSim's version where the peers run ('4.6'); PeerUnavailable without it."""
    return call({"peer": "version"}, timeout_s=120)["version"]


# ---------------------------------------------------------------------------------------- the child


def main() -> None:
    """The child process: one request in, one JSON line out (OpenSim's own output silenced)."""
    import importlib
    import io

    request = json.loads(sys.stdin.read())
    real_stdout, sys.stdout = sys.stdout, io.StringIO()  # nothing but the answer on the pipe
    try:
        try:
            import opensim as osim
        except ImportError:
            answer = {"unavailable": True}
        else:
            osim.Logger.setLevelString("Off")
            if request["peer"] == "version":
                answer = {"version": osim.GetVersion()}
            else:
                answer = importlib.import_module(SOLVERS[request["peer"]]).solve(osim, request)
                answer["version"] = osim.GetVersion()
    except Exception as exc:  # noqa: BLE001 - OpenSim raises RuntimeErrors of many kinds; the parent records it
        answer = {"error": " ".join(f"OpenSim: {exc}".split())[:400]}
    finally:
        sys.stdout = real_stdout
    print(json.dumps(answer))


def model_from(osim, content: str, muscles: bool = False):
    """An OpenSim model of the file text ``content`` (read from a private copy), its forces but the
    PrescribedForces (the loads fdbench keeps) removed: muscles and other forces are not part of a
    torque-driven model. With ``muscles`` its muscles and CoordinateActuators that apply force are
    kept too (a muscle-driven model and its reserves)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="fdbench-peer-") as folder:
        path = os.path.join(folder, "model.osim")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(content)
        model = osim.Model(path)
    forces = model.updForceSet()
    for i in reversed(range(forces.getSize())):
        force = forces.get(i)
        kept = osim.PrescribedForce.safeDownCast(force) is not None or (muscles and force.get_appliesForce() and (
            osim.Muscle.safeDownCast(force) is not None or osim.CoordinateActuator.safeDownCast(force) is not None))
        if not kept:
            forces.remove(i)
    return model


def loads_file(loads: dict | None) -> str | None:
    """The path of the external loads file (``common.loads_request``) written, with its data file,
    into the working folder (the private one ``call`` gives the process); None without loads."""
    if not loads:
        return None
    folder = os.getcwd()
    with open(os.path.join(folder, loads["data_name"]), "w", encoding="utf-8") as handle:
        handle.write(loads["data"])
    path = os.path.join(folder, "external_loads.xml")
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(loads["xml"])
    return path


def with_loads(osim, model, loads: dict | None):
    """``model`` with the external loads of the request added as OpenSim's users add them (its
    ``ExternalLoads`` read from the file, a component of the model); the model itself."""
    path = loads_file(loads)
    if path is not None:
        model.addModelComponent(osim.ExternalLoads(path, True))
    return model


def torque_driven(osim, model, coordinates, suffix: str):
    """Add a CoordinateActuator ``<coordinate><suffix>`` (optimal force 1 N m, so its control is
    its torque, unbounded) at each of ``coordinates``; returns them in that order."""
    import math

    actuators = []
    for name in coordinates:
        actuator = osim.CoordinateActuator(name)
        actuator.setName(name + suffix)
        actuator.setOptimalForce(1.0)
        actuator.setMinControl(-math.inf)
        actuator.setMaxControl(math.inf)
        model.addForce(actuator)
        actuators.append(actuator)
    return actuators


def coordinate_paths(model, coordinates) -> list[str]:
    """The state paths of the coordinates' values, '/jointset/<joint>/<coordinate>' (after initSystem)."""
    found = model.getCoordinateSet()
    return [found.get(name).getAbsolutePathString() for name in coordinates]


def radians_table(osim, labels, t, values):
    """A TimeSeriesTable in radians: columns ``labels``, rows ``values`` (m, len(labels)) at t (s)."""
    table = osim.TimeSeriesTable()
    names = osim.StdVectorString()
    for label in labels:
        names.append(label)
    table.setColumnLabels(names)
    table.addTableMetaDataString("inDegrees", "no")
    for k in range(len(t)):
        row = osim.RowVector(len(labels), 0.0)
        for j, value in enumerate(values[k]):
            row[j] = float(value)
        table.appendRow(float(t[k]), row)
    return table


def muscle_reserves(osim, model, coordinates, optimal_force: float, bound: float) -> tuple[list, bool]:
    """A muscle-driven model's reserves: ([(name, coordinate)] of its CoordinateActuators, their
    unbounded controls bounded by +-``bound``, False) or, where it has none, (those added: one per
    coordinate of ``optimal_force`` N m per unit control, controls within +-``bound``, True)."""
    import math

    found = []
    for force in model.getForceSet():
        actuator = osim.CoordinateActuator.safeDownCast(force)
        if actuator is not None:
            found.append((actuator.getName(), actuator.get_coordinate()))
            if actuator.getMinControl() == -math.inf:
                actuator.setMinControl(-bound)
            if actuator.getMaxControl() == math.inf:
                actuator.setMaxControl(bound)
    if found:
        return found, False
    for actuator in torque_driven(osim, model, coordinates, "_reserve"):
        actuator.setOptimalForce(optimal_force)
        actuator.setMinControl(-bound)
        actuator.setMaxControl(bound)
    return [(name + "_reserve", name) for name in coordinates], True


def optimal_forces(osim, model, reserves) -> list[float]:
    """The optimal forces (N m per unit control) of the CoordinateActuators ``reserves`` ([(name, _)])."""
    forces = model.getForceSet()
    return [osim.CoordinateActuator.safeDownCast(forces.get(name)).getOptimalForce() for name, _ in reserves]
