"""A schema-2 tree through the pipeline's stages (:mod:`oos_drake.scenario.tree_scenario`).

Fast: the adapter against the file's own numbers (the TOML read here, not by the package) and
closed forms. Slow: ``oos run`` on ``flexible_satellite`` at reduced sizes, its controller
checked by eigenvalues and its gamma by a dense frequency sweep, its validation by the twin.
"""

from __future__ import annotations

import json
import math
import pickle
import re
import tomllib

import numpy as np
import pandas as pd
import pytest
from reduced_run import assert_stable_at_range_corners, reduce_run_stages, sweep_peak

from oos_drake.scenario.data import load_scenario, scenario_path


@pytest.fixture(scope="module")
def flexible():
    return load_scenario("flexible_satellite")


@pytest.fixture(scope="module")
def geo():
    return load_scenario("geo_satellite")


def _document(name):
    return tomllib.loads(scenario_path(name).read_text(encoding="utf-8"))


def test_shipped_tree_names_resolve_and_load_as_trees(flexible):
    from oos_drake.scenario.tree_scenario import TreeScenario

    assert scenario_path("flexible_satellite").parent.name == "trees"
    assert isinstance(flexible, TreeScenario)
    assert flexible.name == "flexible_satellite"
    assert load_scenario("flexible_satellite") is flexible  # cached per file version
    assert pickle.loads(pickle.dumps(flexible)) is flexible  # a worker gets the same file's


def test_mission_span_and_control_are_the_files():
    document = _document("flexible_satellite")
    scenario = load_scenario("flexible_satellite")
    assert scenario.mission.t_start == 0.0
    assert scenario.mission.t_end == sum(p["duration"] for p in document["mission"]["phases"])
    assert scenario.mission.docking_phases == ()
    control = document["control"]
    assert scenario.control.pointing_requirement == control["pointing_requirement"]
    assert scenario.control.rolloff_cutoff_hz == control["rolloff"]["cutoff_hz"]
    assert scenario.controlled_body == control["controlled_body"]


def test_mission_values_are_tan_quarter_angles_of_the_smooth_slew(flexible):
    """Observation at the file's 0.3 rad for 600 s, then a 400 s cubic slew to 1.2 rad."""
    from oos_drake.scenario.model import mission_values

    times = np.array([0.0, 300.0, 700.0, 800.0, 1000.0, 1600.0])
    s = np.clip((times - 600.0) / 400.0, 0.0, 1.0)
    angle = 0.3 + (3 * s**2 - 2 * s**3) * (1.2 - 0.3)
    values = mission_values(times, flexible)
    assert sorted(values) == ["tau_SA1", "tau_SA2"]
    for name in values:
        np.testing.assert_allclose(values[name], np.tan(angle / 4), rtol=0, atol=1e-15)


def test_synthesis_plants_static_gain_is_the_inverse_rigid_inertia(flexible):
    """Each configuration's ``T -> wdot`` static gain is the inverse of the rotational Schur
    complement of the whole tree's rigid spatial inertia at the hub's centre of mass (a
    closed form over the bodies, at the timeline's angles)."""
    from oos_drake.control.plants import scenario_plants
    from oos_drake.scenario.tree_model import rigid_inertia_at_root

    plants = scenario_plants(4, flexible)
    nominal = plants.nominal()
    for k, t in enumerate(plants.configurations["time [s]"]):
        M = rigid_inertia_at_root(flexible.tree, flexible.timeline.angles(t))
        J = M[3:, 3:] - M[3:, :3] @ np.linalg.solve(M[:3, :3], M[:3, 3:])
        A, B, C, D = nominal.A[k], nominal.B[k], nominal.C[k], nominal.D[k]
        G0 = D - C @ np.linalg.solve(A, B)
        np.testing.assert_allclose(G0 @ J, np.eye(3), atol=1e-9)


def _declared(document):
    """The uncertain blocks a tree file declares, read from its TOML: name -> (low, high)
    in the block's unit (mode frequencies [rad/s], masses [kg])."""
    declared = {}
    for body in document["bodies"]:
        for key, entry in body.get("uncertainty", {}).items():
            mode = int(key[1:])
            nominal = 2 * math.pi * body["frequencies_hz"][mode - 1]
            if "percent" in entry:
                p = entry["percent"] / 100
                declared[f"w{mode}_{body['name']}"] = (nominal * (1 - p), nominal * (1 + p))
            else:
                low, high = entry["range_hz"]
                declared[f"w{mode}_{body['name']}"] = (2 * math.pi * low, 2 * math.pi * high)
        if body.get("mass_uncertainty_percent", 0.0) > 0:
            p = body["mass_uncertainty_percent"] / 100
            declared[f"m_{body['name']}"] = (body["mass"] * (1 - p), body["mass"] * (1 + p))
        for axis, percent in zip("xyz", body.get("inertia_uncertainty_percent", []), strict=False):
            if percent > 0:
                value = body["inertia"]["xyz".index(axis)]["xyz".index(axis)]
                p = percent / 100
                declared[f"J{axis}{axis}_{body['name']}"] = (value * (1 - p), value * (1 + p))
    return declared


@pytest.mark.parametrize("name", ["flexible_satellite", "geo_satellite"])
def test_synthesis_parameters_are_the_files_declared_uncertainty(name):
    from oos_drake.control.plants import scenario_plants

    declared = _declared(_document(name))
    plants = scenario_plants(2, load_scenario(name))
    got = {p.name: (p.lower, p.upper) for p in plants.parameters}
    assert sorted(got) == sorted(declared)
    for block, (low, high) in declared.items():
        np.testing.assert_allclose(got[block], (low, high), rtol=1e-12, err_msg=block)


def test_analysis_subsets_follow_the_trees_blocks(geo):
    """``geo_satellite``: the modal subset is exactly the declared mode frequencies (REFL_E
    with three), the mechanical one the declared masses and inertias."""
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop
    from oos_drake.analysis.subsets import uncertainty_subsets

    declared = _declared(_document("geo_satellite"))
    assert {"w1_REFL_E", "w2_REFL_E", "w3_REFL_E"} <= set(declared)
    closed = mission_closed_loop(scenario_controller(None, geo), [0.0, 500.0], geo)
    subsets = uncertainty_subsets(closed.system.uncertainty)
    assert subsets["modal"] == sorted(n for n in declared if n.startswith("w"))
    mechanical = sorted(n for n in declared if not n.startswith("w"))
    assert subsets.get("mechanical", []) == mechanical
    assert not any(n.startswith("tau_") for n in subsets["total"])  # scheduled, substituted


def test_what_a_tree_lacks_is_one_line_naming_it(flexible, tmp_path, capsys):
    from oos_drake.app.main import main
    from oos_drake.scenario.tree_scenario import unsupported_stages

    with pytest.raises(ValueError, match=r"schema-2 tree.*schema-1 `arm`"):
        flexible.arm  # noqa: B018
    assert not hasattr(flexible, "hubs")
    assert unsupported_stages(scenario_path("paper")) == {}
    assert set(unsupported_stages(scenario_path("flexible_satellite"))) == {"model figures"}
    # capture, docking and tip waypoints run every stage (the twin welds the target)
    assert set(unsupported_stages(scenario_path("servicer_7dof"))) == {"model figures"}
    out = tmp_path / "figures"
    assert main(["model", "figures", "--out", str(out), "--scenario", "flexible_satellite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "schema-2 tree" in err
    assert not out.exists()
    with pytest.raises(ValueError, match="not available for a schema-2 tree"):
        load_scenario("flexible_satellite", {"bodies.0.mass": 1.0})


def test_analysis_docking_default_is_the_scenarios_phases(flexible):
    from oos_drake.app.analyze import _docking_phases

    assert _docking_phases(None, load_scenario("paper")) == ("7", "8")
    assert _docking_phases(None, flexible) == ()
    assert _docking_phases("7", flexible) == ("7",)


@pytest.mark.slow
def test_oos_run_on_a_tree_end_to_end(tmp_path, monkeypatch, capsys):
    """``oos run --scenario flexible_satellite --quick`` at reduced sizes (each stage's
    options appended: synthesis and analysis on 4 configurations, a coarse grid)."""
    import oos_drake.app.pipeline as pipeline
    from oos_drake.app.main import build_parser

    reduce_run_stages(monkeypatch)
    out = tmp_path / "out"
    # the shipped campaign (the default spec of this scenario) with 6 runs
    spec = tmp_path / "campaign.toml"
    shipped = pipeline.default_campaign(scenario_path("flexible_satellite"))
    assert shipped.name == "flexible_satellite.toml"
    text = shipped.read_text().replace("n_runs = 48", "n_runs = 6")
    spec.write_text(
        text.replace(
            'scenario = "flexible_satellite"', f'scenario = "{scenario_path("flexible_satellite")}"'
        )
    )
    argv = ["run", "--scenario", "flexible_satellite", "--quick", "--out", str(out)]
    argv += ["--campaign", str(spec)]
    assert pipeline.run_pipeline(build_parser().parse_args(argv)) == 0
    printed = capsys.readouterr().out
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["skipped"]) == {"model figures"}
    for stage in timings["skipped"]:
        assert f"[oos run] {stage}: SKIPPED for this scenario: " in printed
        assert re.search(rf"\n  {stage} +SKIPPED: ", printed)
    # the campaign on the tree's twin along its mission: every run simulated
    (campaign,) = out.glob("campaign-*")
    runs = pd.read_parquet(campaign / "runs.parquet")
    assert len(runs) == 6 and (runs["status"] == "ok").all()
    # the confirmation on the tree's own twin: every certified peak confirmed, the twin's
    # boundary and oscillation frequency those of the sampled-data loop
    # (tests/tree/test_tree_confirm.py checks those against eig): the modal peak (0.23 Hz at
    # these sizes) and the slow ones (0.0125 Hz here: their runs last eight periods,
    # ConfirmOptions.for_frequency)
    from oos_drake.analysis.confirm import AGREEMENT

    confirmation = pd.read_parquet(out / "confirm" / "confirmation.parquet")
    peaks = pd.read_parquet(out / "analysis" / "stability_peaks.parquet")
    assert len(confirmation) == int((peaks["mu lower [-]"] > 0).sum()) >= 1
    assert "modal" in set(confirmation["subset"])
    for _, row in confirmation.iterrows():
        assert row["status"] == "confirmed", row
        assert row["alpha nonlinear [-]"] == pytest.approx(
            row["alpha linear sampled [-]"], rel=AGREEMENT
        ), row
        assert row["oscillation frequency [Hz]"] == pytest.approx(
            row["frequency linear sampled [Hz]"], rel=AGREEMENT
        ), row
    assert (out / "report.html").is_file()

    # the twin: every configuration of the timeline within 1e-6 (its own Drake model)
    validation = (out / "validate" / "validate.txt").read_text()
    errors = [float(m) for m in re.findall(r"^t=\S+ s \S+\s+(\S+)", validation, re.M)]
    assert len(errors) >= 5 and max(errors) <= 1e-6

    # the controller: every synthesis closed loop stable (eigenvalues) and its gamma the
    # largest singular value over a dense frequency sweep (second method)
    record = json.loads((out / "controller" / "controller.json").read_text())
    loops = np.load(out / "controller" / "closed_loop.npz")
    assert np.linalg.eigvals(loops["A"]).real.max() < 0
    peak = sweep_peak(loops)
    assert peak <= record["gamma"] * (1 + 1e-6)
    assert peak >= record["gamma"] * (1 - 1e-3)

    # the analysis' closed loops (another interconnection: sensors, wheel, roll-off, the
    # Delta_add/Delta_mul channels) with the synthesized gain: stable at every analyzed
    # configuration, nominal and at the corners of the declared frequency ranges
    scenario = load_scenario("flexible_satellite")
    assert_stable_at_range_corners(
        out / "controller" / "controller.json",
        scenario,
        np.linspace(0.0, scenario.mission.t_end, 4),
    )
    summary = json.loads((out / "analysis" / "summary.json").read_text())
    assert summary["scenario"]["name"] == "flexible_satellite"
    assert summary["docking"] == {}
