"""Eq. 3 is written twice: compiled (``fdbench.multibody.inverse.inverse_torques``, behind
``Engine.inverse_torques``) and symbolic (CasADi, ``fdbench.multibody.symbolic``: the collocation's
and the LQR's). Two derivations (the points' mass matrix projected on the joints' levers, against
Kane's equations on the minimal coordinates) agree on random states of a pin chain, of random trees
and of OpenSim's gait model (a free pelvis, knees on paths) under its ground reactions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.multibody_strategies import models

from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.inverse import inverse_torques
from fdbench.multibody.symbolic import MinimalDynamics, load_parameters

ROOT = Path(__file__).resolve().parents[2]
WALK = ROOT / "examples" / "opensim"


def random_states(J, seed, k=5):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.5, 1.5, (k, J)), rng.uniform(-3, 3, (k, J)), rng.uniform(-20, 20, (k, J))


def compiled(engine, z, zd, zdd, t=None):
    """The compiled eq. 3 of the rows of z, zd, zdd (k, J), the loads at the times t (s, (k,))."""
    out = np.empty(z.shape)
    inverse_torques(z, zd, zdd, engine.layout, engine.paths, engine.loads_at(np.zeros(len(z)) if t is None else t), out)
    return out


def assert_same(compiled, symbolic):
    scale = max(1.0, np.abs(symbolic).max())
    np.testing.assert_allclose(compiled, symbolic, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("name", ["forearm", "arm2", "leg3"])
def test_the_compiled_and_symbolic_inverse_dynamics_agree_on_the_library_chains(name):
    model = find_model(name)
    engine = Engine(model)
    z, zd, zdd = random_states(engine.n_joints, 7)
    assert_same(compiled(engine, z, zd, zdd), MinimalDynamics(model).inverse(z, zd, zdd))


@settings(max_examples=10, deadline=None)
@given(model=models(max_bodies=5), seed=st.integers(0, 2**16))
def test_the_compiled_and_symbolic_inverse_dynamics_agree_on_random_trees(model, seed):
    engine = Engine(model)
    z, zd, zdd = random_states(engine.n_joints, seed, k=2)
    assert_same(compiled(engine, z, zd, zdd), MinimalDynamics(model).inverse(z, zd, zdd))


@pytest.mark.skipif(not (WALK / "subject01.osim").exists(), reason="the gait model's files are not shipped here")
def test_the_compiled_and_symbolic_inverse_dynamics_agree_on_the_gait_model_under_its_loads():
    from fdbench.multibody.loads import read_external_loads

    model = find_model(WALK / "subject01.osim")
    loads = read_external_loads(WALK / "subject01_walk_grf.xml", model)
    engine = Engine(model, loads=loads)
    assert engine.free is not None and engine.paths is not None
    z, zd, zdd = random_states(engine.n_joints, 3)
    z[:, :3] *= 0.3  # the pelvis near upright
    t = np.linspace(0.6, 1.8, len(z))  # times with both feet's reactions in the data
    ours = compiled(engine, z, zd, zdd, t)
    actuation = MinimalDynamics(model).actuation(loads.loads)
    p = load_parameters(loads, t)
    symbolic = np.array([np.asarray(actuation(z[i], zd[i], zdd[i], p[i]), dtype=float).ravel()
                         for i in range(len(z))])
    assert_same(ours, symbolic)
    assert np.abs(ours - compiled(engine, z, zd, zdd, t + 0.3)).max() > 1.0  # the loads count
