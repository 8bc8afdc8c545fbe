"""A model's muscles out to OpenSim (``to_osim``, ``fdbench.multibody.osim_muscles_out``): the
library's arm26 (polynomial paths, compliant tendons) and arm2 with four point-path muscles (one on
ground, one through two points of a body, rigid tendons), exported and read by OpenSim 4.6 in one
child process: its getLength and computeMomentArm against fdbench's muscle_geometry at random
states, its DeGrooteFregly2016Muscle constants against the model's; OpenSim's coefficient order of
a MultivariatePolynomialFunction against the closed form of its monomials; the points model
imported back."""

from __future__ import annotations

import importlib.util
import math
from dataclasses import replace

import numpy as np
import pytest

from fdbench.models import find_model
from fdbench.multibody.model import ModelError, model_from_dict, to_dict
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.osim import check_exportable, import_osim, to_osim
from fdbench.multibody.osim_muscles_out import exponents

from helpers.opensim_child import run_opensim

# arm2's muscles (F0 N, l_opt m, l_s m, points (body, x, y) m) and constants away from the defaults
MUSCLES = {
    "deltoid": (500.0, 0.08, 0.06, [("ground", 0.0, 0.08), ("upper_arm", 0.1, 0.02)]),
    "pectoral": (300.0, 0.05, 0.04, [("ground", 0.02, -0.08), ("upper_arm", 0.12, -0.02)]),
    "biceps": (400.0, 0.12, 0.22, [("ground", 0.0, 0.03), ("upper_arm", 0.15, 0.035), ("forearm", 0.05, 0.02)]),
    "triceps": (300.0, 0.09, 0.11, [("upper_arm", 0.1, -0.03), ("upper_arm", 0.29, -0.03), ("forearm", -0.03, -0.02)]),
}
OTHERS = {"pennation_angle": 0.1, "max_contraction_velocity": 8.0, "activation_time": 0.02, "deactivation_time": 0.05,
          "tendon_strain": 0.04, "passive_strain": 0.5, "fiber_damping": 0.01}
STATES = 20
FIELDS = {"max_isometric_force": "max_isometric_force", "optimal_fiber_length": "optimal_fiber_length",
          "tendon_slack_length": "tendon_slack_length", "pennation_angle": "pennation_angle_at_optimal",
          "max_contraction_velocity": "max_contraction_velocity", "activation_time": "activation_time_constant",
          "deactivation_time": "deactivation_time_constant", "tendon_strain": "tendon_strain_at_one_norm_force",
          "passive_strain": "passive_fiber_strain_at_one_norm_force", "fiber_damping": "fiber_damping"}

OPENSIM_READ = """
answer = {}
for key, path in request["paths"].items():
    model = osim.Model(path)
    state = model.initSystem()
    coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"][key]]
    muscles = [model.getMuscles().get(i) for i in range(model.getMuscles().getSize())]
    lengths, arms = [], []
    for row in request["q"][key]:
        for coordinate, value in zip(coordinates, row):
            coordinate.setValue(state, value, False)
        model.realizePosition(state)
        lengths.append([m.getLength(state) for m in muscles])
        arms.append([[m.computeMomentArm(state, c) for c in coordinates] for m in muscles])
    constants = []
    for m in muscles:
        muscle = osim.DeGrooteFregly2016Muscle.safeDownCast(m)
        constants.append({name: getattr(muscle, "get_" + name)() for name in request["fields"]}
                         | {"ignore_tendon_compliance": muscle.get_ignore_tendon_compliance(),
                            "path": muscle.getPath().getConcreteClassName()})
    answer[key] = {"names": [m.getName() for m in muscles], "lengths": lengths, "arms": arms, "constants": constants}
function = osim.MultivariatePolynomialFunction()
function.setDimension(3)
function.setOrder(3)
function.setCoefficients(osim.Vector(20, 1.0))
x = osim.Vector(3, 0.0)
for k, value in enumerate(request["x"]):
    x.set(k, value)
terms = function.getTermValues(x)
answer["terms"] = [terms.get(i) for i in range(terms.size())]
print(json.dumps(answer))
"""


def arm2_with_muscles():
    data = to_dict(find_model("arm2"))
    data["muscles"] = [{"name": name, "max_isometric_force": f0, "optimal_fiber_length": l_opt,
                        "tendon_slack_length": l_s, **OTHERS,
                        "path": {"points": [{"body": b, "at": [x, y]} for b, x, y in points]}}
                       for name, (f0, l_opt, l_s, points) in MUSCLES.items()]
    return model_from_dict(data, "arm2-muscles")


def states(model, seed):
    ranges = np.array([joint.limits or (-math.pi, math.pi) for joint in model.joints])
    return ranges[:, 0] + np.random.default_rng(seed).random((STATES, len(ranges))) * np.diff(ranges, axis=1)[:, 0]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')")
    folder = tmp_path_factory.mktemp("muscles_out")
    models = {"arm26": find_model("arm26"), "arm2": arm2_with_muscles()}
    paths, q = {}, {}
    for k, (key, model) in enumerate(models.items()):
        paths[key] = folder / f"{key}.osim"
        paths[key].write_text(to_osim(model))
        q[key] = states(model, k)
    request = {"paths": {key: str(path) for key, path in paths.items()}, "fields": list(FIELDS.values()),
               "coordinates": {key: list(model.coordinates) for key, model in models.items()},
               "q": {key: value.tolist() for key, value in q.items()}, "x": [2.0, 3.0, 5.0]}
    return models, paths, q, run_opensim(OPENSIM_READ, request, timeout=300)


@pytest.mark.parametrize("key", ["arm26", "arm2"])
def test_opensim_s_lengths_moment_arms_and_constants_of_the_exported_muscles_are_fdbench_s(exported, key):
    models, _, q, answer = exported
    model, found = models[key], answer[key]
    assert found["names"] == [m.name for m in model.muscles]
    lengths, arms = muscle_geometry(model, q[key])
    assert np.ptp(lengths, axis=0).min() > 1e-3  # the states move every muscle
    np.testing.assert_allclose(np.array(found["lengths"]), lengths, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(found["arms"]), arms, rtol=0, atol=1e-9)
    for muscle, constants in zip(model.muscles, found["constants"]):
        assert {ours: constants[theirs] for ours, theirs in FIELDS.items()} == {
            ours: getattr(muscle, ours) for ours in FIELDS}
        assert constants["ignore_tendon_compliance"] == (muscle.tendon == "rigid")
        assert constants["path"] == ("GeometryPath" if key == "arm2" else "FunctionBasedPath")


def test_opensim_s_coefficient_order_is_the_one_written(exported):
    """OpenSim's monomials of dimension 3 and order 3 at (2, 3, 5), one per coefficient, are the
    products of the powers ``exponents`` gives, in its order."""
    terms = exported[3]["terms"]
    assert terms == [2.0 ** a * 3.0 ** b * 5.0 ** c for a, b, c in exponents(3, 3)]
    assert len(set(exponents(3, 3))) == len(terms) == math.comb(6, 3)


def test_the_exported_points_import_back_as_the_same_muscles(exported):
    models, paths, _, _ = exported
    back, _ = import_osim(paths["arm2"])
    model = models["arm2"]
    assert [replace(m, path=None) for m in back.muscles] == [replace(m, path=None) for m in model.muscles]
    for theirs, ours in zip(back.muscles, model.muscles):
        assert [p.body for p in theirs.path.points] == [p.body for p in ours.path.points]
        np.testing.assert_allclose([p.at for p in theirs.path.points], [p.at for p in ours.path.points], atol=1e-12)


def test_a_polynomial_path_too_large_for_opensim_is_refused_in_one_line(monkeypatch):
    """arm26's TRIlong, of total degree 14 in two coordinates, takes C(16, 2) = 120 coefficients:
    written under a limit of 120, refused naming it under 119."""
    from fdbench.multibody import osim_muscles_out

    model = find_model("arm26")
    monkeypatch.setattr(osim_muscles_out, "MAX_COEFFICIENTS", 120)
    check_exportable(model)
    monkeypatch.setattr(osim_muscles_out, "MAX_COEFFICIENTS", 119)
    with pytest.raises(ModelError, match="muscle TRIlong: .* degree 14 in 2 coordinates takes 120 coefficients"):
        check_exportable(model)
