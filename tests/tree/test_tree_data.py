"""Tree schema (version 2): the shipped trees, hand-computed inertias and every bad input."""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pytest
from tree_documents import boom_document, shipped_document

from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH, ScenarioError, load_scenario
from oos_drake.scenario.tree import load_tree, parse_tree, shipped_trees


def test_shipped_trees_load():
    assert shipped_trees() == ["flexible_satellite", "geo_satellite", "servicer_7dof"]
    flexible = load_tree("flexible_satellite")
    assert [b.name for b in flexible.bodies] == ["HUB", "SA1", "SA2"]
    assert flexible.children("HUB") == ("SA1", "SA2") and flexible.control.controlled_body == "HUB"
    geo = load_tree("geo_satellite")
    assert [b.name for b in geo.bodies if b.kind == "flexible"] == [
        "SA_N", "SA_S", "REFL_E", "REFL_W"
    ]  # fmt: skip
    reflector = geo.body("REFL_E")
    assert [m.mode for m in reflector.uncertainty] == [1, 2, 3]
    assert reflector.uncertainty[1].range_hz == (1.3, 1.8)
    assert geo.operating_angles() == {"SA_N": 0.5, "SA_S": -0.5}


def test_control_section_is_schema_1s():
    """A tree's ``[control]`` minus ``controlled_body`` is a schema-1 ``[control]``: the tree
    whose section is the paper's carries the paper's requirements, field for field."""
    with open(DEFAULT_SCENARIO_PATH, "rb") as stream:
        paper_control = tomllib.load(stream)["control"]
    document = shipped_document("flexible_satellite")
    document["control"] = {"controlled_body": "HUB", **paper_control}
    tree = parse_tree(document)
    assert tree.control.requirements == load_scenario("paper").control
    # the shipped flexible_satellite's is the paper's but for its roll-off, below its arrays'
    # first mode (0.5 Hz)
    shipped = load_tree("flexible_satellite").control.requirements
    assert dataclasses.replace(shipped, rolloff_cutoff_hz=0.7) == load_scenario("paper").control
    assert shipped.rolloff_cutoff_hz == 0.2
    geo = load_tree("geo_satellite").control.requirements
    assert (geo.flight_software_rate_hz, geo.pointing_requirement) == (8.0, 0.0017)


def test_residual_mass_by_hand():
    """D_P0 = D_P - L^T L with D_P written out from mass, P->S and inertia at S."""
    array = load_tree("flexible_satellite").body("SA1")
    m, (x, y, z) = 25.0, (0.0, 2.2, 0.0)
    S = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])  # skew(P->S)
    D_P = np.block([[m * np.eye(3), -m * S], [m * S, np.diag([34.0, 5.4, 39.3]) - m * S @ S]])
    L = np.array(
        [[0, 0, 3.2763, 9.2331, 0, 0], [-2.1720, 0, 0, 0, 0, 6.3305], [0, 0, 0, 0, 0.7348, 0]]
    )
    np.testing.assert_allclose(array.residual_mass, D_P - L.T @ L, rtol=0, atol=1e-12)
    assert np.linalg.eigvalsh(array.residual_mass).min() > 1.0


def test_arrays_are_read_only():
    body = load_tree("geo_satellite").body("HUB")
    with pytest.raises(ValueError):
        body.inertia[0, 0] = 1.0


def _bodies(document):
    return {b["name"]: b for b in document["bodies"]}


def _cycle(d):
    # HUB stays the root; SA1 -> BOOM -> PANEL ... make BOOM hang on PANEL's sibling chain
    bodies = _bodies(d)
    bodies["BOOM"]["parent"] = "SKEWED_RIGID"
    d["bodies"].append(
        {"name": "SKEWED_RIGID", "kind": "rigid", "parent": "BOOM", "mass": 1.0,
         "inertia": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], "joint": {"type": "fixed"}}
    )  # fmt: skip


def _duplicate(d):
    d["bodies"].append(dict(_bodies(d)["SKEWED"]))


def _not_positive_definite(d):
    _bodies(d)["PANEL"]["participation"][0] = [0.0, 0.0, 3.2763, 20.0, 0.0, 0.0]


BAD_INPUTS = {
    "cycle": (_cycle, r"^BOOM: parent: the tree has a cycle \(BOOM -> SKEWED_RIGID -> BOOM\)$"),
    "missing parent": (
        lambda d: _bodies(d)["PANEL"].update(parent="BOMO"),
        r"^PANEL: parent 'BOMO' is not a body \(did you mean 'BOOM'\?\)$",
    ),
    "unknown parent": (
        lambda d: _bodies(d)["PANEL"].update(parent="MAST"),
        r"^PANEL: parent 'MAST' is not a body$",
    ),
    "duplicate": (_duplicate, r"^SKEWED: name: two bodies have this name$"),
    "port on missing body": (
        lambda d: d["ports"]["TIP"].update(body="BOM"),
        r"^ports\.TIP: body 'BOM' is not a body \(did you mean 'BOOM'\?\)$",
    ),
    "residual mass": (
        _not_positive_definite,
        r"^PANEL: participation: residual mass D_P - L\^T L is not positive definite",
    ),
    "controlled body missing": (
        lambda d: d["control"].update(controlled_body="HUBB"),
        r"^control: controlled_body 'HUBB' is not a body \(did you mean 'HUB'\?\)$",
    ),
    "controlled body not root": (
        lambda d: d["control"].update(controlled_body="BOOM"),
        r"^control: controlled_body 'BOOM' must be the tree's root 'HUB'",
    ),
    "two roots": (
        lambda d: _bodies(d)["BOOM"].pop("parent") and _bodies(d)["BOOM"].pop("joint"),
        r"^BOOM: parent: the tree needs exactly one root",
    ),
    "unknown key": (
        lambda d: _bodies(d)["BOOM"].update(masss=1.0),
        r"^BOOM: unknown key 'masss'",
    ),
    "misspelt key": (
        lambda d: _bodies(d)["BOOM"].update(mas=_bodies(d)["BOOM"].pop("mass")),
        r"^BOOM: unknown key 'mas' \(did you mean 'mass'\?\)$",
    ),
    "bad joint type": (
        lambda d: _bodies(d)["BOOM"]["joint"].update(type="prismatic"),
        r"^BOOM\.joint: type must be one of",
    ),
    "angle out of limits": (
        lambda d: _bodies(d)["BOOM"]["joint"].update(lower=-0.5, upper=0.5),
        r"^BOOM\.joint: angle 0\.9 rad out of its limits \[-0\.5, 0\.5\]$",
    ),
    "uncertain mode that does not exist": (
        lambda d: _bodies(d)["PANEL"]["uncertainty"].update(w7={"percent": 5.0}),
        r"^PANEL\.uncertainty\.w7: mode 7 does not exist \(3 modes in frequencies_hz\)$",
    ),
    "range without the nominal": (
        lambda d: _bodies(d)["PANEL"]["uncertainty"].update(w3={"range_hz": [3.3, 3.5]}),
        r"^PANEL\.uncertainty\.w3: range_hz \[3\.3, 3\.5\] must contain the nominal 3\.2 Hz",
    ),
    "appendage with a child": (
        lambda d: _bodies(d)["SKEWED"].update(parent="PANEL"),
        r"^SKEWED: parent 'PANEL' is a flexible appendage",
    ),
    "control field missing": (
        lambda d: d["control"].pop("torque_limit"),
        r"^control: missing key 'torque_limit'$",
    ),
    "control field bad": (
        lambda d: d["control"]["rolloff"].update(cutoff_hz=6.0),
        r"^control\.rolloff\.cutoff_hz: 6 Hz must be below the flight software's Nyquist",
    ),
    "control unknown key": (
        lambda d: d["control"].update(pointing=1.0),
        r"^control: unknown key 'pointing' \(allowed: actuators, controlled_body, ",
    ),
    "schema version 1": (
        lambda d: d.update(schema_version=1),
        r"^tree: schema_version must be 2, got 1",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_one_line_naming_body_and_field(case):
    edit, pattern = BAD_INPUTS[case]
    document = boom_document()
    parse_tree(boom_document())  # the unedited document is valid
    edit(document)
    with pytest.raises(ScenarioError, match=pattern) as error:
        parse_tree(document)
    assert "\n" not in str(error.value)


def test_table_form_of_bodies():
    """``[bodies.NAME]`` tables give the same tree as ``[[bodies]]`` entries."""
    document = shipped_document("geo_satellite")
    document["bodies"] = {b.pop("name"): b for b in document["bodies"]}
    tree = parse_tree(document)
    assert [b.name for b in tree.bodies] == [b.name for b in load_tree("geo_satellite").bodies]


def test_arm_expands_into_its_links():
    tree = load_tree("servicer_7dof")
    links = [f"A{i}" for i in range(1, 8)]
    assert [tree.body(n).parent for n in links] == ["HUB"] + links[:-1]
    assert all(tree.body(n).joint.type == "revolute" for n in links)
    assert tree.ports["GRASP"].body == "A7"
    np.testing.assert_array_equal(tree.ports["GRASP"].p_B_D, [0.0, 0.0, 0.126])


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda arm: arm["links"][2]["joint"].update(type="fixed"),
         r"^A3: joint: every arm link needs a revolute joint$"),
        (lambda arm: arm["links"][4].update(parent="HUB"),
         r"^A5: kind and parent of an arm link are implied$"),
        (lambda arm: arm.update(links=[]),
         r"^ARM: links: an arm needs a non-empty list"),
        (lambda arm: arm["links"][6]["joint"].update(lower=-4.0),
         r"^A7\.joint: limits must satisfy -pi <= lower < upper <= pi"),
    ],
)  # fmt: skip
def test_bad_arm(edit, pattern):
    document = shipped_document("servicer_7dof")
    edit(next(b for b in document["bodies"] if b["name"] == "ARM"))
    with pytest.raises(ScenarioError, match=pattern):
        parse_tree(document)
