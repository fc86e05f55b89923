"""Docking studies of a tree (issue 30): each docking event of a tree's mission is an
``oos analyze`` docking study, as schema 1's phases 7 and 8 (the target on its spring-damper,
the configuration frozen at the event, the stiffness swept).

Checked against independent computations: schema 1's own docking models
(:func:`oos_drake.scenario.model.build_docking_model`, assembled by another code path from the
schema-1 file) on the converted paper, and Drake's linearization of the tree's twin with the
target on ``LinearBushingRollPitchYaw`` force elements (one per spring-damper, the closed loop
of phase 8 included) on the converted paper and on a small tree written here.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from tree_documents import rotation, shipped_document

from oos_drake.lfr import usubs
from oos_drake.scenario.data import load_scenario
from oos_drake.scenario.tree_migration import tree_document_from_v1

OMEGA = 2 * np.pi * np.logspace(-2.5, 1.3, 120)


def docking_document() -> dict:
    """Hub + one flexible array on its drive + a rigid target docked to the hub by an
    uncertain spring-damper (stiffness +-30 %, damping +-20 %); no arm. Both ports turned:
    the target hangs at a skewed attitude."""
    document = shipped_document("flexible_satellite")
    hub, array = document["bodies"][0], document["bodies"][1]
    target = {
        "name": "CLIENT",
        "kind": "rigid",
        "free": True,
        "mass": 80.0,
        "inertia": [[9.0, 0.3, -0.2], [0.3, 11.0, 0.1], [-0.2, 0.1, 7.5]],
        "p_B_G": [0.05, -0.03, 0.35],
        "mass_uncertainty_percent": 15.0,
    }
    document["name"] = "docking_pair"
    document["bodies"] = [hub, array, target]
    document["ports"] = {
        "DOCK": {"body": "HUB", "p_B_D": [0.2, -0.1, -0.6], "R_B_D": rotation([1, 0, 0], np.pi)},
        "C_RING": {
            "body": "CLIENT",
            "p_B_D": [0.0, 0.1, 0.8],
            "R_B_D": rotation([0.3, 1.0, -0.2], 0.8),
        },
    }
    document["mission"] = {
        "interpolation": "smooth",
        "phases": [
            {"name": "approach", "duration": 300.0, "joints": {"SA1": 0.8}},
            {
                "name": "soft_dock",
                "duration": 400.0,
                "joints": {"SA1": 1.1},
                "docked": {
                    "ports": ["DOCK", "C_RING"],
                    "k_shear": 2.0e4,
                    "k_tors": 6.0e3,
                    "d_shear": 150.0,
                    "d_tors": 40.0,
                    "stiffness_percent": 30.0,
                    "damping_percent": 20.0,
                },
            },
            {"name": "hold", "duration": 200.0, "docked": {
                "ports": ["DOCK", "C_RING"], "k_shear": 2.0e4, "k_tors": 6.0e3,
                "d_shear": 150.0, "d_tors": 40.0}},
        ],
    }  # fmt: skip
    return document


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    path = tmp_path_factory.mktemp("docking") / "docking_pair.toml"
    path.write_text(tomli_w.dumps(docking_document()))
    return load_scenario(path)


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    path = tmp_path_factory.mktemp("paper") / "paper_tree.toml"
    path.write_text(tomli_w.dumps(tree_document_from_v1("paper")[0]))
    return load_scenario(path)


def test_docking_events_are_the_docked_phases_that_start_a_docking(pair, converted):
    """A docked phase whose previous phase holds the target at the same ports continues the
    docking (no study); the converted paper's events are schema 1's phases 7 (255 s) and 8
    (880 s, SM2 docking while SM1 still holds the target); the servicer's berthing releases
    its capture."""
    events = pair.mission.docking_phases
    assert [(e.name, e.time, e.spring_dampers) for e in events] == [("soft_dock", 300.0, ("DOCK",))]
    paper = load_scenario("paper")
    times = {p.name: p.time for p in paper.mission.docking_phases}
    events = converted.mission.docking_phases
    assert [(e.time, e.spring_dampers) for e in events] == [
        (times["7"], ("SM1",)),
        (times["8"], ("SM2", "SM1")),
    ]
    servicer = load_scenario("servicer_7dof")
    (berthed,) = servicer.mission.docking_phases
    assert berthed.name == "berthed" and "capture GRASP-T_GRASP released" in berthed.description
    with pytest.raises(ValueError, match=r"'hold' is not a docking event \(docking phases: "):
        pair.docking_plant("hold", [1.0e3])


def _schema1_docking(phase: str, paper):
    from oos_drake.scenario.model import build_docking_model, configuration_values
    from oos_drake.scenario.timeline import mission_timeline

    cfg = mission_timeline(paper).docking_phases[phase].configuration
    values = configuration_values(cfg.alpha, cfg.theta, cfg.delta_C1, cfg.delta_C2)
    model = build_docking_model(phase, paper)
    return usubs(model, {k: v for k, v in values.items() if k in model.uncertainty})


def _tree_docking(event, scenario):
    from oos_drake.scenario.tree import docked_tree
    from oos_drake.scenario.tree_model import build_tree_model, tree_values

    docking, held = scenario.docking_event(event.name)
    tree = docked_tree(scenario.tree, docking, held)
    values = tree_values(tree, scenario.timeline.angles(event.time))
    return usubs(build_tree_model(tree), values)


def _draw(blocks, rng) -> dict:
    """A value of every real block, uniform in its range."""
    return {
        name: float(rng.uniform(*spec.range))
        for name, spec in blocks.items()
        if spec.kind == "ureal"
    }


@pytest.mark.parametrize("index, phase", [(0, "7"), (1, "8")])
def test_converted_paper_docking_models_are_schema_1s(converted, index, phase):
    """Phase 7 (J7-D2 through SM1) and 8 (D1-D3 through SM2, SM1 holding: the closed loop):
    the tree's docking model at its event has schema 1's blocks with their occurrences
    (spring-dampers ``k_shear_SM1`` ... included) and the same responses at random values of
    every block (spring-dampers included); the study's plants (``docking_plant``: the stiffness
    swept, the rest at the file's values) are schema 1's at 0.1, 30 and 1e5 N/m."""
    from oos_drake.analysis.models import docking_plant

    paper = load_scenario("paper")
    event = converted.mission.docking_phases[index]
    ours, theirs = _tree_docking(event, converted), _schema1_docking(phase, paper)
    assert ours.occurrences == theirs.occurrences
    assert {n: (b.nominal, b.range) for n, b in ours.uncertainty.items()} == {
        n: (b.nominal, b.range) for n, b in theirs.uncertainty.items()
    }
    rng = np.random.default_rng(30 + index)
    for _ in range(3):
        values = _draw(theirs.uncertainty, rng)
        a = np.asarray(usubs(ours, values).nominal.freqresp(OMEGA))
        b = np.asarray(usubs(theirs, values).nominal.freqresp(OMEGA))
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    stiffness = [0.1, 30.0, 1.0e5]
    ours = docking_plant(event.name, stiffness, scenario=converted)
    theirs = docking_plant(phase, stiffness, scenario=paper)
    assert sorted(ours.uncertainty) == sorted(theirs.uncertainty)
    values = {k: np.full(3, v) for k, v in _draw(theirs.uncertainty, rng).items()}
    a = np.asarray(usubs(ours, values).nominal.freqresp(OMEGA))
    b = np.asarray(usubs(theirs, values).nominal.freqresp(OMEGA))
    for k in range(3):
        assert np.abs(a[k] - b[k]).max() <= 1e-10 * np.abs(b[k]).max()


def _twin_vs_plant(scenario, event, stiffness, values=None, also_values=None):
    """Drake's linearization of the docked twin (one bushing per spring-damper, the swept one
    at ``stiffness``) vs the study's plant at ``stiffness`` with ``values`` substituted."""
    from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems
    from oos_drake.multibody.tree_plant import build_docked_diagram, linearize_tree

    values = values or {}
    docking, held = scenario.docking_event(event.name)
    swept = dataclasses.replace(docking, k_shear=stiffness, k_tors=stiffness)
    suffix = f"_{docking.label}"
    given = {k.removesuffix(suffix): v for k, v in values.items() if k.endswith(suffix)}
    swept = dataclasses.replace(swept, **given)
    angles = scenario.timeline.angles(event.time)
    drake = linearize_tree(build_docked_diagram(scenario.tree, swept, angles, also=held), angles)
    plant = scenario.docking_plant(event.name, [stiffness])
    titop = usubs(plant, {k: np.array([v]) for k, v in values.items()}).nominal
    return compare_systems(event.name, drake, titop.model(0).to_ss(), VALIDATION_OMEGA)


@pytest.mark.drake
@pytest.mark.parametrize("index", [0, 1])
@pytest.mark.parametrize("stiffness", [1.0e3, 1.0e5])
def test_converted_paper_docking_plants_match_the_twin_on_its_bushings(converted, index, stiffness):
    """Phase 7: one bushing J7-D2; phase 8: the D1-D3 bushing at the swept stiffness and the
    J7-D2 one at its rigid values, both on the target (a closed kinematic loop): Drake's
    linearization equals the study's plant, the same minimal order (24 + 24 modes of the
    welded pair + 12 of the target's six coordinates on its springs)."""
    pytest.importorskip("pydrake")
    event = converted.mission.docking_phases[index]
    result = _twin_vs_plant(converted, event, stiffness)
    assert result.passed and result.max_relative_error <= 1e-8, result
    assert result.n_states == (60, 60), result


@pytest.mark.drake
def test_own_tree_docking_plant_matches_the_twin(pair):
    """A tree written here (hub, one array, a target on a skewed docking ring, no arm): the
    study's plant at two swept stiffnesses, its declared-uncertain damping, the target's mass
    and the array's first mode at random values in their ranges, equals Drake's linearization
    of the twin with the same numbers in its bushing and its SDF (6 array states + 12 of the
    target's coordinates)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems
    from oos_drake.multibody.tree_plant import build_docked_diagram, linearize_tree
    from oos_drake.multibody.tree_twin import tree_with_values

    (event,) = pair.mission.docking_phases
    plant = pair.docking_plant(event.name, [1.0])
    assert sorted(plant.uncertainty) == ["d_shear_DOCK", "d_tors_DOCK", "m_CLIENT", "w1_SA1"]
    rng = np.random.default_rng(7)
    docking, held = pair.docking_event(event.name)
    angles = pair.timeline.angles(event.time)
    assert held == () and angles["SA1"] == pytest.approx(0.8)
    for stiffness in (3.0e3, 4.0e4):
        values = _draw(plant.uncertainty, rng)
        tree = tree_with_values(pair.tree, {k: values[k] for k in ("m_CLIENT", "w1_SA1")})
        spring = dataclasses.replace(
            docking,
            k_shear=stiffness,
            k_tors=stiffness,
            d_shear=values["d_shear_DOCK"],
            d_tors=values["d_tors_DOCK"],
        )
        drake = linearize_tree(build_docked_diagram(tree, spring, angles), angles)
        titop = usubs(
            pair.docking_plant(event.name, [stiffness]),
            {k: np.array([v]) for k, v in values.items()},
        ).nominal.model(0)
        result = compare_systems("own", drake, titop.to_ss(), VALIDATION_OMEGA)
        assert result.passed and result.max_relative_error <= 1e-8, result
        assert result.n_states == (6 + 12, 6 + 12), result


def test_oos_analyze_studies_a_trees_docking(pair, tmp_path, capsys):
    """``oos analyze`` on the tree written here: by default its docking event is a study
    (``docking-soft_dock``: the stiffness sweep table and a certified total peak); an unknown
    ``--docking`` phase is one line naming the tree's phases, exit status 2, nothing written."""
    import pandas as pd

    from oos_drake.app.main import main

    common = ["analyze", "--scenario", str(pair.source), "--configurations", "3",
              "--points-per-decade", "3", "--docking-points", "3", "--no-sensitivity",
              "--no-time-check", "--performance-models", "1", "--performance-points", "4",
              "--spike-budget", "5", "--iterations", "15", "--grid-only", "--workers", "1",
              "--quiet"]  # fmt: skip
    bad = tmp_path / "bad"
    assert main([*common, "--out", str(bad), "--docking", "berthed"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "unknown docking phase 'berthed' (phases: soft_dock)" in err
    assert not bad.exists()
    out = tmp_path / "analysis"
    assert main([*common, "--out", str(out)]) == 0
    sweep = pd.read_parquet(out / "docking_soft_dock.parquet")
    np.testing.assert_allclose(
        np.unique(sweep["stiffness [N/m or N m/rad]"]), np.geomspace(0.1, 1.0e5, 3)
    )
    peaks = pd.read_parquet(Path(out) / "stability_peaks.parquet")
    row = peaks[peaks["study"] == "docking-soft_dock"]
    assert list(row["subset"]) == ["total"]
    assert 0 < float(row["mu lower [-]"].iloc[0]) <= float(row["mu upper [-]"].iloc[0])


@pytest.mark.drake
@pytest.mark.parametrize("time", [500.0, 1200.0])
def test_open_loop_twin_welds_a_target_with_its_own_drives(converted, time):
    """The converted paper's target has two array drives (SA3, SA4): the open-loop twin welds it
    at J7 (500 s) or D1 (1200 s) with those joints locked at their file angles, against the
    switched mission LFR with every real block at a random value in its range (the target's
    mass, inertias and array modes written into its own SDF)."""
    pytest.importorskip("pydrake")
    from oos_drake.multibody.cross_check import VALIDATION_OMEGA, compare_systems
    from oos_drake.multibody.tree_plant import linearize_tree
    from oos_drake.multibody.tree_twin import mating_at, open_loop_twin, tree_with_values

    model = converted.mission_model()
    blocks = {n: b for n, b in model.uncertainty.items() if b.quantity not in ("angle", "switch")}
    assert {"m_RH2", "w1_SA3", "w1_SA4"} <= set(blocks)
    rng = np.random.default_rng(int(time))
    values = _draw(blocks, rng)
    scheduled = {n: float(v[0]) for n, v in converted.mission_values([time]).items()}
    titop = usubs(model, values | scheduled).nominal.to_ss()
    mating = mating_at(converted.timeline, time)
    assert mating == (("J7", "D2") if time < 880 else ("D1", "D3"))
    handles = open_loop_twin(tree_with_values(converted.tree, values), mating)
    assert {"SA3", "SA4"} <= set(handles.revolute_joints)
    drake = linearize_tree(handles, converted.timeline.angles(time))
    result = compare_systems(f"t = {time}", drake, titop, VALIDATION_OMEGA)
    assert result.passed and result.max_relative_error <= 1e-8, result
    assert result.n_states == (48, 48), result
