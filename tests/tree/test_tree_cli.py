"""``oos tree ...`` and ``oos validate`` of a tree, through the ``oos`` entry point in-process:
bad input -> one line naming body and field, exit 2, nothing written; shipped trees validate."""

from __future__ import annotations

import re

import pytest
import tomli_w
from tree_documents import boom_document, shipped_document

from oos_drake.app.main import main


def _write(tmp_path, document):
    path = tmp_path / "tree.toml"
    path.write_bytes(tomli_w.dumps(document).encode())
    return path


def test_bad_tree_exits_2_and_writes_nothing(tmp_path, capsys):
    document = boom_document()
    document["control"]["controlled_body"] = "HBU"
    out = tmp_path / "sdf"
    assert main(["tree", "sdf", str(_write(tmp_path, document)), str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (
        "oos tree: error: control: controlled_body 'HBU' is not a body (did you mean 'HUB'?)\n"
    )
    assert not out.exists()


def test_cycle_exits_2(tmp_path, capsys):
    document = boom_document()
    document["bodies"][0]["parent"] = "BOOM"
    document["bodies"][0]["joint"] = {"type": "fixed"}
    assert main(["tree", "check", str(_write(tmp_path, document))]) == 2
    assert capsys.readouterr().err.startswith("oos tree: error: HUB: parent: the tree has a cycle")


def test_validate_bad_tree_exits_2_naming_body_and_field(tmp_path, capsys):
    document = shipped_document("flexible_satellite")
    document["bodies"][1]["mass"] = -25.0
    assert main(["validate", "--scenario", str(_write(tmp_path, document))]) == 2
    captured = capsys.readouterr()
    assert captured.err == "oos validate: error: SA1: mass must be > 0, got -25\n"
    assert captured.out == ""


def test_validate_bad_mission_exits_2(tmp_path, capsys):
    document = shipped_document("flexible_satellite")
    document["mission"]["phases"][1]["joints"]["SA2"] = 3.5
    assert main(["validate", "--scenario", str(_write(tmp_path, document))]) == 2
    assert capsys.readouterr().err.startswith(
        "oos validate: error: mission.array_slew.joints: SA2 = 3.5 rad out of its limits"
    )


@pytest.mark.drake
def test_sdf_written_for_a_valid_tree(tmp_path):
    pytest.importorskip("pydrake")
    out = tmp_path / "sdf"
    assert main(["tree", "sdf", str(_write(tmp_path, boom_document())), str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "appendage_PANEL.sdf", "appendage_SKEWED.sdf", "spacecraft.sdf"
    ]  # fmt: skip


def _rows(out: str) -> dict[str, float]:
    """``configuration label -> max relative error`` from the validate table."""
    rows = re.findall(
        r"^(t=\S+ s \S+(?: \[\S+\])?)\s+(\S+)\s+\S+\s+\S+\s+\S+\s+(PASS|FAIL)$", out, re.M
    )
    return {label: float(error) for label, error, _ in rows}


@pytest.mark.drake
@pytest.mark.parametrize(
    ("name", "times"),
    [
        ("flexible_satellite", [0, 400, 600, 800, 1000, 1200, 1600]),
        ("servicer_7dof", [0, 300, 600, 700, 900, 1200]),
    ],
)
def test_validate_shipped_tree_on_its_timeline(name, times, capsys):
    """Every configuration of the timeline (5 evenly spaced instants + phase boundaries)."""
    pytest.importorskip("pydrake")
    assert main(["validate", "--scenario", name, "--frequencies", "100"]) == 0
    out = capsys.readouterr().out
    rows = _rows(out)
    assert [float(label.split()[0][2:]) for label in rows] == times
    assert max(rows.values()) <= 1e-6
    assert f"all {len(times)} configurations pass" in out
    if name == "servicer_7dof":  # the target captured, then docked: checked so
        assert "t=900 s grasp_hold [GRASP+T_GRASP]" in rows
        assert "t=1200 s berthed [DOCK~T_DOCK]" in rows


@pytest.mark.drake
def test_validate_fails_when_the_twin_differs(tmp_path, capsys, monkeypatch):
    """A wrong twin (parsed from the SDF of a tree whose SA1 modes are 1 % higher) fails with
    exit 1: the check compares two models, it does not compare the LFR with itself."""
    pytest.importorskip("pydrake")
    import dataclasses

    from oos_drake.multibody import tree_plant
    from oos_drake.multibody.tree_sdf import write_tree_sdf
    from oos_drake.scenario.tree import parse_tree

    document = shipped_document("flexible_satellite")
    document.pop("mission")
    tree = parse_tree(document)
    shifted = dataclasses.replace(
        tree.body("SA1"), frequencies_hz=tree.body("SA1").frequencies_hz * 1.01
    )
    bodies = tuple(shifted if b.name == "SA1" else b for b in tree.bodies)
    write_tree_sdf(dataclasses.replace(tree, bodies=bodies), tmp_path / "wrong")
    build = tree_plant.build_tree_diagram
    monkeypatch.setattr(
        tree_plant, "build_tree_diagram", lambda tree, sdf=None: build(tree, tmp_path / "wrong")
    )
    assert main(["validate", "--scenario", str(_write(tmp_path, document))]) == 1
    assert "FAILED: 1 of 1 configurations (t=0 s )" in capsys.readouterr().out


@pytest.mark.drake
def test_the_trees_validation_is_computed_apart_from_printing(tmp_path, capsys, monkeypatch):
    """:func:`~oos_drake.app.tree.compute_tree_validation` writes and prints nothing; its
    report is what ``oos validate --scenario TREE`` prints (wall times aside), its results the
    table's rows, its status the command's; the validation stage writes the same report
    (``validate.txt``; the tree's report is no longer a captured printout)."""
    pytest.importorskip("pydrake")
    from oos_drake.app.multibody import ValidateOptions, validate
    from oos_drake.app.tree import compute_tree_validation

    assert main(["validate", "--scenario", "flexible_satellite", "--frequencies", "20"]) == 0
    printed = capsys.readouterr().out
    monkeypatch.chdir(tmp_path)
    options = ValidateOptions(frequencies=20)
    header = []
    result = compute_tree_validation("flexible_satellite", options, progress=header.append)
    assert list(tmp_path.iterdir()) == [] and capsys.readouterr().out == ""
    untimed = re.compile(r"\d+\.\d s\b")
    assert untimed.sub("T", result.text) == untimed.sub("T", printed)
    assert printed.startswith("\n".join(header) + "\n") and len(header) == 1
    assert result.status == 0 and [r.label for r in result.results] == list(_rows(printed))
    assert [r.max_relative_error for r in result.results] == pytest.approx(
        list(_rows(printed).values()), rel=1e-3
    )
    folder = tmp_path / "stage"
    folder.mkdir()
    staged = validate("flexible_satellite", options, folder).results
    assert [(r.label, r.passed) for r in staged] == [(r.label, r.passed) for r in result.results]
    assert untimed.sub("T", (folder / "validate.txt").read_text()) == untimed.sub("T", printed)
    capsys.readouterr()
