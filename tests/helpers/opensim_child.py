"""OpenSim in a child process, for the tests that compare fdbench with it: OpenSim and CasADi in
one process break CasADi, and a child keeps OpenSim's own start-up and logging out of the tests.

A script (``run_opensim``) starts after ``PREAMBLE``: ``osim`` (OpenSim, its log off) and ``request``
(the JSON the test sent) are defined, and ``prescribe`` and ``integrate`` drive a forward simulation
as an OpenSim user does (a PrescribedController, one Manager). It prints its answer as JSON on its
last line."""

from __future__ import annotations

import json
import subprocess
import sys

PREAMBLE = '''
import json, math, os, sys
import opensim as osim
osim.Logger.setLevelString("Off")
request = json.loads(sys.stdin.read())


def prescribe(model, actuators, controls, times, name="controls"):
    """A PrescribedController on ``model`` driving each of ``actuators`` (OpenSim actuators) by its
    ``controls`` (values at ``times``, s), linear between them (PiecewiseLinearFunction)."""
    controller = osim.PrescribedController()
    controller.setName(name)
    for actuator, values in zip(actuators, controls):
        controller.addActuator(actuator)
        history = osim.PiecewiseLinearFunction()
        for t, value in zip(times, values):
            history.addPoint(t, value)
        controller.prescribeControlForActuator(actuator.getName(), history)
    model.addController(controller)


def integrate(model, state, accuracy, samples, sample):
    """One Manager at ``accuracy`` from ``state`` to each time of ``samples`` (s) in turn, the
    state realised to dynamics; the list of ``sample(state)`` at each."""
    manager = osim.Manager(model)
    manager.setIntegratorAccuracy(accuracy)
    manager.initialize(state)
    out = []
    for t in samples:
        if t > state.getTime():
            state = manager.integrate(t)
        model.realizeDynamics(state)
        out.append(sample(state))
    return out

'''
# the answer printed, the child ends without tearing down OpenSim's objects (SWIG prints leak
# warnings on stdout at teardown, after the answer)
ENDING = '''
sys.stdout.flush()
os._exit(0)
'''


def run_opensim(script: str, request, timeout: float = 600.0, args=(), cwd=None):
    """``script`` after ``PREAMBLE`` in a child Python with ``request`` (JSON-able) on its stdin,
    ``args`` on its command line, in the folder ``cwd``; the JSON of its last line of output. Fails the test with the
    child's error output if it fails."""
    done = subprocess.run([sys.executable, "-c", PREAMBLE + script + ENDING, *map(str, args)], input=json.dumps(request),
                          capture_output=True, text=True, timeout=timeout, cwd=cwd)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])
