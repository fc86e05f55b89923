"""The Drake mission as a campaign simulator: declarations, reruns, divergence, specs."""

import math

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.campaign.drake_simulator import (  # noqa: E402
    FACTORY_PATH,
    DrakeMissionSimulator,
)
from oos_drake.campaign.simulator import (  # noqa: E402
    MissionWindow,
    RunCase,
    SimulationDiverged,
    Simulator,
    SimulatorRecipe,
    build_simulator,
)
from oos_drake.campaign.spec import SPEC_DIRECTORY  # noqa: E402

CAMPAIGNS = SPEC_DIRECTORY

#: Uncertain blocks of the scenario LFR (oos_drake.scenario.model.DELTA_GROUPS) that the
#: nonlinear simulation must disperse under the same names.
LFR_BLOCKS = (
    ["m_RH2", "Jxx_RH2", "Jyy_RH2", "Jzz_RH2"]
    + [f"w1_SA{k}" for k in range(1, 5)]
    + [f"{q}_SM{k}" for k in (1, 2) for q in ("k_shear", "k_tors", "d_shear", "d_tors")]
)


@pytest.fixture(scope="module")
def simulator():
    return build_simulator(SimulatorRecipe.create(FACTORY_PATH, {"scenario": "paper"}))


def test_declarations_cover_every_uncertain_block(simulator):
    assert isinstance(simulator, Simulator)
    names = [p.name for p in simulator.parameters()]
    assert set(LFR_BLOCKS) <= set(names)
    assert {"Delta_mul_xx", "Delta_mul_yz", "Delta_add", "noise_seed"} <= set(names)
    assert len(names) == len(set(names))
    from oos_drake.scenario.model import DELTA_GROUPS

    real_blocks = {n for n in DELTA_GROUPS if not n.startswith(("tau_", "delta_C"))}
    assert real_blocks <= set(names)
    for p in simulator.parameters():
        assert p.lower <= p.nominal <= p.upper
    assert simulator.events() == {"capture": 255.0, "docking": 880.0, "tilt": 1100.0}
    assert simulator.duration() == 1500.0
    assert set(simulator.metric_signals().values()) <= set(simulator.signal_units())


def test_rerun_reproduces_metrics_exactly(simulator):
    case = RunCase(
        3,
        12345,
        {"m_RH2": 26.0, "w1_SA1": 7.0, "Delta_mul_yy": 0.5},
        MissionWindow(250.0, 270.0, "event:capture"),
        frequency=0.7,
    )
    first, second = simulator.run(case), simulator.run(case)
    assert dict(first.metrics) == dict(second.metrics)
    assert first.timeseries.equals(second.timeseries)
    assert set(first.metrics) == set(simulator.metric_units())
    units = simulator.signal_units()
    assert list(first.timeseries.columns) == ["time [s]"] + [f"{s} [{u}]" for s, u in units.items()]
    # the capture happened: SM1 carries a force after 255 s, none before
    ts = first.timeseries
    assert ts.loc[ts["time [s]"] < 255.0, "F_SM1 [N]"].max() == 0.0
    assert ts.loc[ts["time [s]"] > 256.0, "F_SM1 [N]"].max() > 0.0
    assert all(math.isfinite(v) for v in first.metrics.values())


def test_divergence_is_reported():
    diverging = DrakeMissionSimulator("paper", divergence_limit=1e-4, check_interval=5.0)
    case = RunCase(0, 1, {"w0_y": 0.005}, MissionWindow(1050.0, 1070.0))
    with pytest.raises(SimulationDiverged, match="beyond"):
        diverging.run(case)


def test_bad_options_and_values_are_rejected(simulator):
    with pytest.raises(ValueError, match="unknown option"):
        DrakeMissionSimulator("paper", control_rat=5.0)
    with pytest.raises(ValueError, match="m_RH2"):
        simulator.run(RunCase(0, 1, {"m_RH2": 1.0}, MissionWindow(0.0, 1.0)))
    with pytest.raises(ValueError, match="unknown parameter"):
        simulator.run(RunCase(0, 1, {"mass": 1.0}, MissionWindow(0.0, 1.0)))


#: Synthetic regions (a test input, not results): LTI perturbations at three frequencies, one
#: of them infinite (an ill-posed peak), with mu_upper values that make region 1 the peak.
SYNTHETIC_REGIONS = (
    (0.0889, 0.2, {"Delta_add": 1.0, "w1_SA1": 6.5}),
    (0.8247, 0.4, {"Delta_mul_xx": 0.9, "Delta_mul_yz": -1.0, "m_RH2": 27.0}),
    (math.inf, 0.1, {"Delta_add": -1.0, "Jxx_RH2": 2.9}),
)


@pytest.fixture(scope="module")
def synthetic_worst_cases(simulator, tmp_path_factory):
    from oos_drake.campaign.worst_cases import WorstCaseRegion, write_worst_cases

    regions = [
        WorstCaseRegion(i, f"synthetic {i}", 300.0 + 100 * i, f, mu, mu, ",".join(p), p)
        for i, (f, mu, p) in enumerate(SYNTHETIC_REGIONS)
    ]
    path = tmp_path_factory.mktemp("worst_cases") / "worst_cases.parquet"
    return write_worst_cases(regions, simulator.parameters(), path)


@pytest.mark.parametrize("name", ["paper.toml", "paper_mc.toml"])
def test_paper_campaign_specs_load_and_plan(name, synthetic_worst_cases, tmp_path):
    from oos_drake.campaign.runner import plan_campaign

    spec, plan = plan_campaign(CAMPAIGNS / name, synthetic_worst_cases)
    assert len(plan) == spec.n_runs
    width = plan["window end [s]"] - plan["window start [s]"]
    np.testing.assert_allclose(width, 80.0)
    if spec.sampler.kind == "mu-guided":
        assert len(spec.regions) == 3
        assert (plan["region"] >= 0).sum() > spec.n_runs / 2
        assert plan["weight"].max() <= 1.0 / spec.sampler.defensive_fraction + 1e-9
        # every run is realized at the frequency of the region of its window
        frequencies = {f"region:{i}": f for i, (f, _, _) in enumerate(SYNTHETIC_REGIONS)}
        np.testing.assert_array_equal(
            plan["frequency [Hz]"], plan["window"].map(frequencies).to_numpy(float)
        )
    else:  # not tied to a region: the analysis' peak (largest mu_upper)
        assert (plan["frequency [Hz]"] == SYNTHETIC_REGIONS[1][0]).all()


def test_paper_phases_covers_the_whole_timeline(synthetic_worst_cases):
    """paper_phases.toml: every run simulates one whole phase of the mission; the phases, read
    from the scenario's events, tile [0, duration] and get runs in proportion to their
    durations (largest remainders); pointing applies in every phase, stated in the spec."""
    import tomllib

    from oos_drake.campaign.runner import plan_campaign
    from oos_drake.scenario.data import scenario_path

    spec, plan = plan_campaign(CAMPAIGNS / "paper_phases.toml", synthetic_worst_cases)
    mission = tomllib.loads(scenario_path("paper").read_text())["mission"]
    events = sorted(
        [mission["first_docking_time"], mission["second_docking_time"], mission["tilt_start_time"]]
    )
    edges = [0.0, *events, spec.info.duration]
    windows = plan.groupby("window")[["window start [s]", "window end [s]"]].first()
    np.testing.assert_array_equal(np.sort(windows.to_numpy(), axis=0), np.c_[edges[:-1], edges[1:]])
    counts = plan.groupby("window start [s]").size().sort_index().to_numpy()
    share = np.diff(edges) / edges[-1] * spec.n_runs
    assert counts.sum() == spec.n_runs and np.all(np.abs(counts - share) < 1)
    (ape,) = [r for r in spec.requirements if r.metric == "ape"]
    assert sorted(ape.spans) == list(zip(edges[:-1], edges[1:], strict=True))
    assert ape.max == 0.0079


@pytest.mark.parametrize("name", ["paper", "paper_mc", "heavy_target"])
def test_shipped_specs_state_where_pointing_applies(name):
    """The pointing requirement names its phases (every one: the arm's motion included)."""
    import tomllib

    document = tomllib.loads((CAMPAIGNS / f"{name}.toml").read_text())
    phases = document["requirements"]["ape"]["phases"]
    assert phases == ["start-capture", "capture-docking", "docking-tilt", "tilt-end"]


@pytest.mark.parametrize("name", ["paper", "paper_mc"])
def test_paper_campaigns_without_worst_cases_are_refused(name, tmp_path, capsys):
    """Through the CLI: exit 2, one line naming the missing worst_cases.parquet, nothing written
    (no stand-in regions, no stand-in frequency)."""
    from oos_drake.app.campaign import main

    out = tmp_path / "out"
    assert main(["campaign", "run", name, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "worst_cases.parquet" in err and "--worst-cases" in err
    assert not out.exists()
    missing = tmp_path / "no_analysis" / "worst_cases.parquet"
    args = ["campaign", "run", name, "--out", str(out), "--worst-cases", str(missing)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(missing) in err
    assert not out.exists()


def _allpass_response(fsw, perturbation, frequency_hz):
    """Response at ``frequency_hz`` of the flight software's realized all-pass: the transfer
    ``sat(u) -> a_mul`` of its stage-2 matrix divided by ``sat(u) -> T_rw`` (the all-pass filters
    T_rw), evaluated on the unit circle from the matrix the update uses."""
    M = fsw._output_stage(perturbation)
    n2 = M.shape[1] - 6
    A, B = M[:n2, :n2], M[:n2, n2 : n2 + 3]
    z = np.exp(2j * np.pi * frequency_hz * fsw.design.period)
    state = np.linalg.solve(z * np.eye(n2) - A, B)

    def transfer(rows):
        return M[rows, :n2] @ state + M[rows, n2 : n2 + 3]

    T_rw = transfer(slice(n2, n2 + 3))
    a_mul = transfer(slice(n2 + 6, n2 + 9))
    a_add = transfer(slice(n2 + 9, n2 + 12))
    return a_mul @ np.linalg.inv(T_rw), a_add @ np.linalg.inv(T_rw)


def test_region_lti_perturbation_is_realized_at_the_region_frequency(
    simulator, synthetic_worst_cases
):
    """From the plan row to the flight software: a run of region r carries r's frequency, and
    the discrete all-pass the flight software applies equals a(j 2 pi f_r) = (p - j w)/(p + j w)
    at w = p = 2 pi f_r, i.e. -j (closed form), whatever the region; at infinite frequency it is
    the static 1 (the documented decision for ill-posed peaks)."""
    from oos_drake.campaign.runner import case_from_plan_row, plan_campaign

    spec, plan = plan_campaign(CAMPAIGNS / "paper.toml", synthetic_worst_cases)
    fsw = simulator.simulation.handles.flight_software
    for region, (frequency_hz, _, _) in enumerate(SYNTHETIC_REGIONS):
        row = plan[plan["region"] == region].iloc[0]
        case = case_from_plan_row(spec, row)
        assert case.frequency == frequency_hz
        context, _, _ = simulator.simulation.initial_context(
            dict(case.values),
            case.seed,
            case.window.start,
            case.window.end,
            perturbation_frequency_hz=case.frequency,
        )
        parameter = fsw.GetMyContextFromRoot(context).get_numeric_parameter(0).get_value()
        assert parameter[10] == frequency_hz
        probe = 0.8247 if math.isinf(frequency_hz) else frequency_hz
        expected = np.eye(3) * (1.0 if math.isinf(frequency_hz) else -1j)
        for response in _allpass_response(fsw, parameter, probe):
            np.testing.assert_allclose(response, expected, atol=1e-9)
        # the other regions' frequencies are not where this run's all-pass is -j
        for other, _, _ in SYNTHETIC_REGIONS:
            if other != frequency_hz and math.isfinite(frequency_hz) and math.isfinite(other):
                off = _allpass_response(fsw, parameter, other)[0][0, 0]
                assert abs(off + 1j) > 0.1


@pytest.mark.slow
def test_whole_mission_runs_with_every_event(simulator):
    result = simulator.simulation.run({}, seed=1)
    ts = result.timeseries
    assert ts["time [s]"].iloc[-1] == pytest.approx(1500.0)
    assert result.metrics["max_tracking_error"] < 1e-4  # motion-driven joints follow the timeline
    # SM1 carries the target between capture and release, SM2 from the docking on
    between = ts[(ts["time [s]"] > 300) & (ts["time [s]"] < 870)]
    after = ts[ts["time [s]"] > 900]
    assert between["F_SM1 [N]"].max() > 0 and between["F_SM2 [N]"].max() == 0
    assert after["F_SM1 [N]"].max() == 0 and after["F_SM2 [N]"].max() > 0
    # the arrays tilt from 1100 s: their modes are excited then
    assert ts.loc[ts["time [s]"] > 1100, "q1_SA1 [rad]"].abs().max() > 0
    assert result.metrics["ape"] < 0.5


def test_start_hook_gives_the_run_context_and_its_state_log(mission):
    """``on_start`` receives the run's root context before the first step; ``state_log`` then
    reads the logged plant states: one sample per ``1 / log_rate`` over the window, starting at
    the dispersed initial attitude, with the integrator statistics in the result."""
    contexts = []
    phi0 = {"phi0_x": 2e-3, "phi0_y": -1e-3, "phi0_z": 5e-4}
    result = mission.run(phi0, seed=3, start=300.0, end=305.0, on_start=contexts.append)
    assert len(contexts) == 1
    times, states = mission.state_log(contexts[0])
    np.testing.assert_allclose(times, 300.0 + np.arange(6.0) / mission.options.log_rate)
    q = mission.handles.hub_joint.position_start()
    np.testing.assert_allclose(states[q : q + 3, 0], list(phi0.values()), atol=1e-15)
    # the same samples as the run's own time series
    np.testing.assert_allclose(
        states[q : q + 3].T, result.timeseries[["phi_x [rad]", "phi_y [rad]", "phi_z [rad]"]]
    )
    stats = result.statistics
    assert stats["integrator_num_steps_taken"] == result.steps > 0
    assert stats["integrator_num_derivative_evaluations"] >= result.steps
