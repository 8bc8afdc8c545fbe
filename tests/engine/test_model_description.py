"""Model descriptions as data: the library files are the built-in models' constants, every bad file
is one line naming the file and the key, valid trees of bodies survive a round trip through TOML and
JSON, the joints are put in topological order, and ``with_changes`` paths change what they name."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import find_model, library
from fdbench.multibody.model import (GROUND, RESERVED_SUFFIXES, Body, Joint, Load, Model, ModelError, resolved_end,
                                     to_dict)
from fdbench.multibody.model_changes import with_changes
from fdbench.multibody.model_files import load_model, to_toml

from helpers.cli_checks import assert_one_line_error
from helpers import forearm_closed_form as cf
from helpers.paths import ROOT

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


# ---- the library is the built-in models -------------------------------------------------------


def bar_point_masses(model: Model, body_name: str) -> tuple[float, float, float]:
    """(m_ii, m_ij, m_jj), kg: a planar bar's mass matrix in the natural coordinates of its joint
    point i and end point j, centre of mass on the line ij (García de Jalón & Bayo, ch. 3)."""
    body = model.body(body_name)
    origin = model.parent_joint(body_name).at_child
    end = resolved_end(model, body_name)
    length = math.dist(origin, end)
    along = math.dist(origin, body.com) / length
    about_joint = body.inertia + body.mass * math.dist(origin, body.com) ** 2
    m_jj = about_joint / length**2
    return body.mass - 2 * body.mass * along + m_jj, body.mass * along - m_jj, m_jj


def test_the_library_lists_its_models():
    assert set(library()) == {"forearm", "arm2", "arm26", "leg3"}
    for name, path in library().items():
        assert load_model(path).name == name
        assert find_model(name) == load_model(path)


def test_the_forearm_file_is_table_1():
    model = find_model("forearm")
    assert model.coordinates == ("theta",) and model.gravity == (0.0, -cf.G)
    assert resolved_end(model, "forearm") == (cf.L12, 0.0)  # the load's point, the hand
    _, _, point_mass = bar_point_masses(model, "forearm")
    assert point_mass == pytest.approx(cf.I1 / cf.L12**2, rel=1e-15)  # the hand point's mass, I1 / L12^2
    (load,) = model.loads
    body = model.body("forearm")
    load_y = load.force[1] + body.mass * model.gravity[1] * body.com[0] / load.at[0]
    # the load and gravity carried to the hand: -F_ext - m g L1G / L12
    assert load_y == pytest.approx(-cf.F_EXT - cf.M * cf.G * cf.L1G / cf.L12, rel=1e-15)


def test_the_arm2_file_is_the_two_segment_arm():
    from helpers.arm2_closed_form import ARM2

    model, c = find_model("arm2"), ARM2
    assert model.coordinates == ("shoulder", "elbow")
    assert [model.path(b) for b in ("upper_arm", "forearm")] == [(0,), (0, 1)]
    _, _, upper_jj = bar_point_masses(model, "upper_arm")  # its point i is the fixed shoulder
    fore_ii, fore_ij, fore_jj = bar_point_masses(model, "forearm")
    # the points' mass matrix of two bars in natural coordinates (the elbow and the hand), by hand
    a = c["L1G"] / c["L12"]
    m22 = c["I1"] / c["L12"] ** 2
    m12 = c["m"] * a - m22
    m11 = c["I0"] / c["L01"] ** 2 + c["m"] * (1.0 - 2.0 * a) + m22
    assert upper_jj + fore_ii == pytest.approx(m11, rel=1e-15)
    assert fore_ij == pytest.approx(m12, rel=1e-15)
    assert fore_jj == pytest.approx(m22, rel=1e-15)


def test_leg3_hangs_from_the_hip_with_its_ends_at_the_next_joints():
    model = find_model("leg3")
    assert model.coordinates == ("hip", "knee", "ankle")
    assert model.parent_joint("thigh").offset == -math.pi / 2
    assert [resolved_end(model, b.name) for b in model.bodies] == [(0.429, 0.0), (0.431, 0.0), (0.15, 0.0)]
    assert model.total_mass == pytest.approx(0.161 * 75)  # Winter: thigh + shank + foot fractions
    assert model.path("foot") == (0, 1, 2) and model.children("thigh") == (1,) and model.children(GROUND) == (0,)


def test_the_models_command_lists_the_library_and_shows_one():
    listed = json.loads(invoke("models", "--format", "json").stdout)
    assert [row["name"] for row in listed] == ["arm2", "arm26", "forearm", "leg3"]
    assert listed[3]["coordinates"] == ["hip", "knee", "ankle"] and listed[2]["description"]
    shown = invoke("models", "show", "forearm")
    assert shown.exit_code == 0, shown.stderr
    assert "theta" in shown.stdout and "0.33" in shown.stdout and "farthest load" in shown.stdout


@pytest.mark.parametrize("fmt", ("toml", "json"))
def test_what_models_show_prints_is_a_model_file_of_the_same_model(tmp_path, fmt):
    result = invoke("models", "show", "leg3", "--format", fmt)
    assert result.exit_code == 0, result.stderr
    path = tmp_path / f"mine.{fmt}"
    text = result.stdout if fmt == "toml" else json.dumps(json.loads(result.stdout)["model"])
    path.write_text(text)
    mine, leg = load_model(path), find_model("leg3")
    assert mine.joints == leg.joints and mine.loads == leg.loads
    assert [resolved_end(mine, b.name) for b in mine.bodies] == [resolved_end(leg, b.name) for b in leg.bodies]


def test_models_show_never_writes_over_its_input(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(to_toml(find_model("arm2")))
    before = path.read_bytes()
    assert_one_line_error(invoke("models", "show", path, "--format", "toml", "-o", path), "--output", "input")
    assert path.read_bytes() == before
    library_file = library()["forearm"]
    before = library_file.read_bytes()
    assert_one_line_error(invoke("models", "show", "forearm", "--format", "toml", "-o", library_file), "--output")
    assert library_file.read_bytes() == before


def test_an_unknown_model_name_lists_the_library():
    assert_one_line_error(invoke("models", "show", "lge3"), "'lge3'", "arm2, arm26, forearm, leg3", "did you mean 'leg3'")


# ---- bad files: exit 2, one line naming the file and the key ---------------------------------

BASE = {
    "name": "leg",
    "bodies": [
        {"name": "thigh", "mass": 7.5, "com": [0.19, 0.0], "inertia": 0.12},
        {"name": "shank", "mass": 3.5, "com": [0.19, 0.0], "inertia": 0.05},
        {"name": "foot", "mass": 1.1, "com": [0.07, 0.0], "inertia": 0.005},
    ],
    "joints": [
        {"name": "hip", "type": "pin", "parent": "ground", "child": "thigh", "at_parent": [0.0, 0.0], "at_child": [0.0, 0.0]},
        {"name": "knee", "type": "pin", "parent": "thigh", "child": "shank", "at_parent": [0.43, 0.0], "at_child": [0.0, 0.0]},
        {"name": "ankle", "type": "pin", "parent": "shank", "child": "foot", "at_parent": [0.43, 0.0], "at_child": [0.0, 0.0]},
    ],
    "loads": [{"body": "foot", "at": [0.15, 0.0], "force": [0.0, -10.0]}],
}


def toml_text(data: dict) -> str:
    """A description as TOML, whatever its values (for bad files too)."""
    def value(v):
        if isinstance(v, bool):
            return str(v).lower()
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, float) and not math.isfinite(v):
            return str(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + "}"
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in data.items() if not (isinstance(v, list) and v and isinstance(v[0], dict))]
    for key, entries in data.items():
        if isinstance(entries, list) and entries and isinstance(entries[0], dict):
            for entry in entries:
                lines += ["", f"[[{key}]]"] + [f"{k} = {value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"


def setting(path: str, new):
    """A change of BASE: the value at ``path`` ('joints.1.parent') set to ``new``, or removed if None."""
    def change(data):
        *parents, last = path.split(".")
        for part in parents:
            data = data[int(part)] if part.isdigit() else data[part]
        if new is None:
            del data[int(last) if last.isdigit() else last]
        else:
            data[int(last) if last.isdigit() else last] = new
    return change


BAD = [  # (id, change of BASE, words the message must hold: the key and what is allowed)
    ("unknown parent", setting("joints.1.parent", "thigth"), ("joints[1].parent", "'thigth'", "did you mean 'thigh'")),
    ("unknown child", setting("joints.2.child", "fot"), ("joints[2].child", "valid: thigh, shank, foot")),
    ("a cycle", setting("joints.1.parent", "foot"), ("joints[1].parent", "cycle", "shank -> foot -> shank")),
    ("a child of two joints", setting("joints.2.child", "thigh"), ("joints[2].child", "already the child of joints[0]")),
    ("a body with no joint", setting("joints.2", None), ("bodies[2]", "'foot'", "child of no joint")),
    ("a body as its own parent", setting("joints.1.parent", "shank"), ("joints[1].child", "hang from itself")),
    ("duplicate body names", setting("bodies.1.name", "thigh"), ("bodies[1].name", "already the name of bodies[0]")),
    ("duplicate joint names", setting("joints.2.name", "knee"), ("joints[2].name", "already the name of joints[1]")),
    ("a joint named like a body", setting("joints.0.name", "Thigh"), ("joints[0].name", "ignoring case")),
    ("ground as a name", setting("bodies.0.name", "Ground"), ("bodies[0].name", "reserved")),
    ("t as a joint name", setting("joints.0.name", "t"), ("joints[0].name", "columns")),
    ("a column suffix", setting("joints.0.name", "hip_vel"), ("joints[0].name", "_vel")),
    ("a name with a space", setting("bodies.0.name", "upper leg"), ("bodies[0].name", "a letter then")),
    ("zero mass", setting("bodies.1.mass", 0.0), ("bodies[1].mass", "positive", "kg")),
    ("negative mass", setting("bodies.1.mass", -3.5), ("bodies[1].mass", "positive")),
    ("zero inertia", setting("bodies.2.inertia", 0.0), ("bodies[2].inertia", "positive", "kg m^2")),
    ("negative inertia", setting("bodies.2.inertia", -0.1), ("bodies[2].inertia", "positive")),
    ("zero segment length", setting("joints.1.at_parent", [0.0, 0.0]), ("joints[1].at_parent", "zero length", "bodies[0].end")),
    ("an end at the joint", setting("bodies.2.end", [0.0, 0.0005]), ("bodies[2].end", "zero length")),
    ("nan", setting("bodies.0.mass", math.nan), ("bodies[0].mass", "finite")),
    ("inf", setting("bodies.0.com", [0.1, math.inf]), ("bodies[0].com[1]", "finite")),
    ("inf gravity", setting("gravity", [0.0, -math.inf]), ("gravity[1]", "finite")),
    ("above 1e6", setting("bodies.0.mass", 2e6), ("bodies[0].mass", "1e6")),
    ("a missing inertia", setting("bodies.0.inertia", None), ("bodies[0].inertia", "missing", "kg m^2")),
    ("a missing parent", setting("joints.0.parent", None), ("joints[0].parent", "missing", "ground")),
    ("a missing bodies", setting("bodies", None), ("bodies", "missing")),
    ("a string for a number", setting("bodies.0.mass", "7.5"), ("bodies[0].mass", "the text '7.5'", "positive number")),
    ("a bool for a number", setting("bodies.0.mass", True), ("bodies[0].mass", "got true")),
    ("a number for a point", setting("bodies.0.com", 0.19), ("bodies[0].com", "[x, y]")),
    ("three numbers for a point", setting("joints.1.at_parent", [0.43, 0.0, 0.0]), ("joints[1].at_parent", "a list of 3")),
    ("a number for a name", setting("bodies.0.name", 3.0), ("bodies[0].name", "a name")),
    ("a table for the joints", setting("joints", {"name": "hip"}), ("joints", "a list of tables")),
    ("an unknown top key", setting("bodys", []), ("bodys", "unknown key", "did you mean 'bodies'")),
    ("an unknown body key", setting("bodies.0.masss", 7.5), ("bodies[0].masss", "did you mean 'mass'")),
    ("an unknown joint type", setting("joints.0.type", "slider"), ("joints[0].type", "'slider'", "valid: pin")),
    ("no body", lambda data: data.update(bodies=[], joints=[], loads=[]), ("bodies", "at least one body")),
    ("a load on no body", setting("loads.0.body", "toe"), ("loads[0].body", "'toe'")),
    ("limits upside down", setting("joints.1.limits", [0.5, -0.5]), ("joints[1].limits", "lower < upper")),
]

KNEE_PATH = {"angles": [-1.0, 0.0, 1.0], "x": [0.0, 0.01, 0.02], "y": [0.0, -0.01, 0.0]}
FREE_HIP = {"type": "free", "coordinates": ["hip_tilt", "hip_tx", "hip_ty"]}


def joint_with(k: int, **keys):
    """A change of BASE: joint k with the keys given (None: removed)."""
    def change(data):
        for key, value in keys.items():
            if value is None:
                data["joints"][k].pop(key, None)
            else:
                data["joints"][k][key] = copy.deepcopy(value)
    return change


BAD += [  # free joints and joint paths
    ("a free joint not on ground", joint_with(1, **FREE_HIP), ("joints[1].parent", "must be 'ground'", "'thigh'")),
    ("a free joint without coordinates", joint_with(0, type="free"), ("joints[0].coordinates", "missing", "[angle, x, y]")),
    ("a free joint with two coordinates", joint_with(0, type="free", coordinates=["a", "b"]),
     ("joints[0].coordinates", "three names", "a list of 2")),
    ("a free coordinate named like a body", joint_with(0, type="free", coordinates=["tilt", "Shank", "ty"]),
     ("joints[0].coordinates[1].name", "already the name of bodies[1]")),
    ("a free joint with a path", joint_with(0, **FREE_HIP, path=KNEE_PATH), ("joints[0].path", "no path")),
    ("coordinates on a pin joint", joint_with(1, coordinates=["a", "b", "c"]), ("joints[1].coordinates", "only a free")),
    ("path angles not increasing", joint_with(1, path=KNEE_PATH | {"angles": [-1.0, 0.5, 0.5]}),
     ("joints[1].path.angles[2]", "strictly increasing", "more than angles[1]")),
    ("a NaN in a path", joint_with(1, path=KNEE_PATH | {"x": [math.nan, 0.0, 0.0]}), ("joints[1].path.x[0]", "finite")),
    ("a path of mismatched lengths", joint_with(1, path=KNEE_PATH | {"y": [0.0, 0.1]}),
     ("joints[1].path.y", "has 2 values but angles has 3", "one value per angle")),
    ("a path of one sample", joint_with(1, path={"angles": [0.0], "x": [0.0], "y": [0.0]}),
     ("joints[1].path.angles", "strictly increasing", "2 to 1000")),
    ("a path without y", joint_with(1, path={"angles": [0.0, 1.0], "x": [0.0, 0.0]}), ("joints[1].path.y", "missing")),
    ("a path's unknown key", joint_with(1, path=KNEE_PATH | {"z": [0.0, 0.0, 0.0]}),
     ("joints[1].path.z", "unknown key")),
]

SWING = {"name": "swing", "type": "minimum-jerk", "duration": 1.0, "start": {"hip": -0.3, "knee": -0.2, "ankle": 0.1},
         "goal": {"hip": 0.6, "knee": -1.0, "ankle": -0.2}}


def with_motion(path: str, new):
    """BASE with the motion SWING, then ``path`` of it ('motions.0.start.knee') set to ``new`` (None: removed)."""
    def change(data):
        data["motions"] = [copy.deepcopy(SWING)]
        setting(path, new)(data)
    return change


BAD += [  # named motions and short keys
    ("a motion without a joint", with_motion("motions.0.start.knee", None),
     ("motions[0].start.knee", "missing", "every joint: hip, knee, ankle")),
    ("a motion naming an unknown joint", with_motion("motions.0.goal.kne", 0.1),
     ("motions[0].goal.kne", "unknown joint 'kne'", "did you mean 'knee'")),
    ("a motion of zero duration", with_motion("motions.0.duration", 0.0), ("motions[0].duration", "positive", "(s)")),
    ("a motion of an unknown type", with_motion("motions.0.type", "cubic"), ("motions[0].type", "valid: minimum-jerk")),
    ("a motion without a goal", with_motion("motions.0.goal", None), ("motions[0].goal", "missing", "every joint")),
    ("a motion with a list for a start", with_motion("motions.0.start", [0.1, 0.2, 0.3]),
     ("motions[0].start", "a table {joint = angle}")),
    ("a motion with a text angle", with_motion("motions.0.start.hip", "10deg"), ("motions[0].start.hip", "an angle (rad)")),
    ("a motion with an infinite angle", with_motion("motions.0.start.hip", math.inf), ("motions[0].start.hip", "finite")),
    ("two motions of one name", lambda data: data.update(motions=[SWING, SWING | {"name": "Swing"}]),
     ("motions[1].name", "already the name of motions[0]")),
    ("a motion's unknown key", with_motion("motions.0.speed", 1.0), ("motions[0].speed", "unknown key")),
    ("eq. 5 on a three-joint leg", setting("motions", [{"name": "flex", "type": "eq5-paper"}]),
     ("motions[0].type", "eq5-paper moves the one angle of a one-joint model", "3 coordinates")),
    ("eq. 5 given a duration", setting("motions", [{"name": "flex", "type": "eq5-exact", "duration": 2.0}]),
     ("motions[0].duration", "eq. 5 fixes it", "remove it")),
    ("a short key to an unknown path", setting("keys", {"m1": "thigh.mas"}),
     ("keys.m1", "unknown path 'thigh.mas'", "did you mean 'thigh.mass'")),
    ("a short key to a number", setting("keys", {"m1": 7.5}), ("keys.m1", "a path of the model as a text")),
    ("an @ after a mass", setting("keys", {"m1": "thigh.mass@hip"}), ("keys.m1", "goes after a body's inertia")),
    ("an @ naming a far joint", setting("keys", {"I0": "thigh.inertia@ankle"}),
     ("keys.I0", "unknown joint of body 'thigh' 'ankle'", "valid: hip, knee")),
    ("a short key that is not a name", setting("keys", {"1m": "thigh.mass"}), ("keys.1m", "not a short key")),
    ("keys as a list", setting("keys", ["thigh.mass"]), ("keys", "a table of short names")),
]


@pytest.mark.parametrize("suffix", (".toml", ".json"))
@pytest.mark.parametrize("case, change, words", BAD, ids=[case[0] for case in BAD])
def test_a_bad_model_file_is_one_line_naming_the_file_and_the_key(tmp_path, suffix, case, change, words):
    data = copy.deepcopy(BASE)
    change(data)
    path = tmp_path / f"bad{suffix}"
    path.write_text(toml_text(data) if suffix == ".toml" else json.dumps(data))
    line = assert_one_line_error(invoke("models", "show", path), str(path), *words)
    assert "Traceback" not in line
    with pytest.raises(ModelError):
        load_model(path)


@pytest.mark.parametrize("name, text, words", [
    ("broken.toml", "[[bodies]\nname = 1\n", ("not valid TOML", "line 1")),
    ("broken.json", '{"bodies": [', ("not valid JSON",)),
    ("twice.json", '{"bodies": [], "bodies": []}', ("'bodies' appears twice",)),
    ("list.json", "[1, 2]", ("a table of keys", "a list of 2")),
    ("deep.json", "[" * 100_000 + "]" * 100_000, ("nested too deeply",)),
    ("deep.toml", "x = " + "[" * 5000 + "]" * 5000, ("nested too deeply",)),
    ("long.toml", "bodies = [{mass = 1" + "0" * 5000 + "}]", ("a number too long",)),
    ("huge.toml", toml_text(BASE).replace("mass = 7.5", "mass = 1" + "0" * 400), ("bodies[0].mass", "finite")),
])
def test_a_file_that_is_not_a_description_is_one_line(tmp_path, name, text, words):
    path = tmp_path / name
    path.write_text(text)
    assert_one_line_error(invoke("models", "show", path), str(path), *words)


def test_a_missing_file_and_a_directory_are_one_line(tmp_path):
    assert_one_line_error(invoke("models", "show", tmp_path / "none.toml"), "none.toml", "does not exist")
    assert_one_line_error(invoke("models", "show", tmp_path), "is a directory")


def test_a_model_file_over_1_mib_is_refused(tmp_path):
    path = tmp_path / "huge.toml"
    path.write_text(toml_text(BASE) + "#" * 2**20 + "\n")
    assert_one_line_error(invoke("models", "show", path), "larger than 1 MiB")


# ---- valid trees: round trip and order ------------------------------------------------------

NAMES = st.from_regex(r"[a-z][a-z0-9_]{0,7}", fullmatch=True).filter(
    lambda s: s not in (GROUND, "t") and not s.endswith(RESERVED_SUFFIXES))
COORDINATE = st.floats(-5.0, 5.0, allow_nan=False)


@st.composite
def points_away(draw, origin):
    """A point at least 1 cm from ``origin`` (m)."""
    radius, angle = draw(st.floats(0.01, 2.0)), draw(st.floats(-math.pi, math.pi))
    return (origin[0] + radius * math.cos(angle), origin[1] + radius * math.sin(angle))


@st.composite
def trees(draw) -> Model:
    """A valid model of 1 to 6 bodies, each hanging from ground or an earlier body."""
    n = draw(st.integers(1, 6))
    names = draw(st.lists(NAMES, min_size=2 * n, max_size=2 * n, unique_by=str.lower))
    bodies, joints = [], []
    for i in range(n):
        at_child = (draw(COORDINATE), draw(COORDINATE))
        parent = GROUND if i == 0 else draw(st.sampled_from([GROUND, *names[:i]]))
        if parent == GROUND:
            at_parent = (draw(COORDINATE), draw(COORDINATE))
        else:
            at_parent = draw(points_away(joints[names.index(parent)].at_child))
        limits = tuple(sorted(draw(st.lists(st.floats(-6.0, 6.0), min_size=2, max_size=2, unique=True))))
        joints.append(Joint(names[n + i], "pin", parent, names[i], at_parent, at_child,
                            draw(st.floats(-6.3, 6.3)), draw(st.none() | st.just(limits))))
        end = draw(st.none() | points_away(at_child))
        bodies.append(Body(names[i], draw(st.floats(1e-3, 100.0)), (draw(COORDINATE), draw(COORDINATE)),
                           draw(st.floats(1e-4, 10.0)), end))
    loads = [Load(draw(st.sampled_from(names[:n])), (draw(COORDINATE), draw(COORDINATE)),
                  (draw(COORDINATE), draw(COORDINATE))) for _ in range(draw(st.integers(0, 3)))]
    description = draw(st.text(st.characters(blacklist_categories=("Cc", "Cs")), max_size=40).filter(
        lambda s: not s or s.strip()))
    return Model("tree", (draw(COORDINATE), draw(COORDINATE)), tuple(bodies), tuple(joints), tuple(loads), description)


@given(trees())
def test_a_tree_written_as_toml_and_as_json_reads_back_equal(tmp_path_factory, model):
    folder = tmp_path_factory.mktemp("trees")
    (folder / "tree.toml").write_text(to_toml(model), encoding="utf-8")
    (folder / "tree.json").write_text(json.dumps(to_dict(model)), encoding="utf-8")
    assert load_model(folder / "tree.toml") == model
    assert load_model(folder / "tree.json") == model


@given(trees(), st.randoms(use_true_random=False))
def test_joints_listed_in_any_order_are_put_in_topological_order(tmp_path_factory, model, random):
    data = to_dict(model)
    random.shuffle(data["joints"])
    path = tmp_path_factory.mktemp("shuffled") / "tree.json"
    path.write_text(json.dumps(data))
    loaded = load_model(path)
    placed = {GROUND}
    for joint in loaded.joints:
        assert joint.parent in placed
        placed.add(joint.child)
    assert set(loaded.joints) == set(model.joints)
    file_order = [joint["name"] for joint in data["joints"]]
    for body in (GROUND, *(b.name for b in model.bodies)):  # siblings keep their file order
        siblings = [loaded.joints[k].name for k in loaded.children(body)]
        assert siblings == sorted(siblings, key=file_order.index)


def test_the_first_child_in_the_file_gives_the_default_end():
    data = copy.deepcopy(BASE)
    data["bodies"].append({"name": "heel", "mass": 0.2, "com": [0.0, -0.02], "inertia": 0.001})
    data["joints"].insert(0, {"name": "subtalar", "parent": "shank", "child": "heel", "at_parent": [0.40, 0.05]})
    model = find_model_from(data)
    assert [j.name for j in model.joints] == ["hip", "knee", "subtalar", "ankle"]
    assert resolved_end(model, "shank") == (0.40, 0.05)
    assert resolved_end(model, "heel") == (0.0, -0.02)  # no child, no load: the centre of mass
    assert resolved_end(model, "foot") == (0.15, 0.0)  # its load


def find_model_from(data: dict) -> Model:
    from fdbench.multibody.model import model_from_dict

    return model_from_dict(copy.deepcopy(data), "test")


def test_a_load_or_centre_of_mass_at_the_joint_is_passed_over_for_the_end():
    data = copy.deepcopy(BASE)
    data["loads"][0]["at"] = [0.0, 0.0]
    data["bodies"][2]["com"] = [0.0, 0.0]
    model = find_model_from(data)
    assert resolved_end(model, "foot") == (1.0, 0.0)


# ---- with_changes ------------------------------------------------------------------------------


def test_with_changes_sets_the_value_each_path_names():
    arm = find_model("arm2")
    changed = with_changes(arm, [("forearm.mass", "1.1"), ("upper_arm.com.x", 0.14), ("gravity.y", "-9.7"),
                                 ("forearm.force.y", "-20"), ("elbow.at_parent.x", "0.31"), ("shoulder.offset", "0.1"),
                                 ("forearm.end.y", "0.01")])
    assert changed.body("forearm").mass == 1.1 and changed.body("upper_arm").com == (0.14, 0.0)
    assert changed.gravity == (0.0, -9.7) and changed.loads[0].force == (0.0, -20.0)
    assert changed.joints[1].at_parent == (0.31, 0.0) and changed.joints[0].offset == 0.1
    assert changed.body("forearm").end == (0.33, 0.01)  # the resolved default, one component changed
    assert resolved_end(changed, "upper_arm") == (0.31, 0.0)
    assert with_changes(arm, [("loads[0].at.x", "0.3")]).loads[0].at == (0.3, 0.0)
    assert with_changes(arm, []) == arm and arm.body("forearm").mass == 1.0  # the original is unchanged


@pytest.mark.parametrize("pair, words", [
    (("forearm.mas", "1"), ("forearm.mas=1", "did you mean 'forearm.mass'")),
    (("forearm.mass", "-1"), ("forearm.mass=-1", "positive")),
    (("forearm.mass", "heavy"), ("forearm.mass=heavy", "must be a number")),
    (("forearm.inertia", "nan"), ("forearm.inertia=nan", "finite")),
    (("gravity.y", -10**400), ("gravity.y=-1000", "finite")),
    (("elbow.at_parent.x", "0"), ("elbow.at_parent.x=0", "joints[1].at_parent", "zero length")),
])
def test_a_bad_change_names_the_pair(pair, words):
    with pytest.raises(ModelError) as error:
        with_changes(find_model("arm2"), [pair])
    for word in words:
        assert word in str(error.value)


# ---- the README's "Your own model" ------------------------------------------------------------


def readme_section() -> str:
    text = (ROOT / "README.md").read_text()
    start = text.index("\n## Your own model (file format)\n")
    return text[start:text.index("\n## ", start + 1)]


def test_the_readme_file_is_the_library_forearm(tmp_path):
    (body,) = re.findall(r"```toml\n(.*?)```", readme_section(), flags=re.DOTALL)
    (tmp_path / "forearm.toml").write_text(body)
    assert load_model(tmp_path / "forearm.toml") == find_model("forearm")


def test_the_readme_table_names_every_key():
    from fdbench.multibody.model import BODY_KEYS, FRAME_KEYS, JOINT_KEYS, LOAD_KEYS, MOTION_KEYS, TOP_KEYS
    from fdbench.multibody.actuators import ACTUATOR_KEYS
    from fdbench.multibody.muscles import MUSCLE_KEYS

    documented = set(re.findall(r"^\| `([a-z_.]+)` \|", readme_section(), flags=re.MULTILINE))
    keys = set(TOP_KEYS) | {f"{section}.{key}" for section, keys in
                            (("bodies", BODY_KEYS), ("joints", JOINT_KEYS), ("loads", LOAD_KEYS),
                             ("motions", MOTION_KEYS), ("frames", FRAME_KEYS), ("muscles", MUSCLE_KEYS),
                             ("actuators", ACTUATOR_KEYS))
                            for key in keys}
    assert documented == keys


def test_the_readme_example_message_is_what_fdbench_says(tmp_path, monkeypatch):
    data = copy.deepcopy(BASE)
    data["bodies"][1]["mass"] = -3.5
    shown = re.search(r"\(`(leg\.toml: .*?)`\)", " ".join(readme_section().split())).group(1)
    monkeypatch.chdir(tmp_path)
    Path("leg.toml").write_text(toml_text(data))
    result = invoke("models", "show", "leg.toml")
    assert_one_line_error(result)
    assert result.stderr.strip() == f"fdbench: error: {shown}"


def test_an_empty_model_name_is_an_unknown_name_not_the_current_folder():
    result = CliRunner().invoke(app, ["models", "show", ""])
    assert result.exit_code == 2 and "unknown model ''" in result.stderr and "directory" not in result.stderr


# ---- free joints and joint paths -------------------------------------------------------------------


def test_free_and_path_joints_read_back_equal_and_show(tmp_path):
    """A model with a free base and a knee on a path: its TOML and JSON read back to an equal Model,
    its coordinates are the free joint's three then the pins', with their kinds, and ``models show``
    lists them."""
    from helpers.multibody_strategies import models_with_paths_and_free_joints

    data = copy.deepcopy(BASE)
    joint_with(0, **FREE_HIP)(data)
    joint_with(1, path=KNEE_PATH | {"y_angles": [-2.0, 2.0], "y": [0.0, 0.01]})(data)
    model = find_model_from(data)
    assert model.coordinates == ("hip_tilt", "hip_tx", "hip_ty", "knee", "ankle")
    assert model.coordinate_kinds == ("angle", "translation", "translation", "angle", "angle")
    assert model.n_joints == 5 and model.joint_named("knee").path.angles_of_y == (-2.0, 2.0)
    for text, suffix in ((to_toml(model), ".toml"), (json.dumps(to_dict(model)), ".json")):
        path = tmp_path / f"walk{suffix}"
        path.write_text(text)
        assert load_model(path) == model
    shown = invoke("models", "show", tmp_path / "walk.toml")
    assert shown.exit_code == 0 and "hip_tilt, hip_tx, hip_ty, knee, ankle" in shown.output
    assert_models_round_trip = given(models_with_paths_and_free_joints())(
        lambda random_model: _reads_back(tmp_path, random_model))
    assert_models_round_trip()


def _reads_back(folder, model):
    path = folder / "random.toml"
    path.write_text(to_toml(model))
    assert load_model(path) == model
