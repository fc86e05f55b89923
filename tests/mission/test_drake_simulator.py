"""The Drake mission as a campaign simulator: declarations, reruns, divergence, specs."""

import math

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.campaign.drake_simulator import (  # noqa: E402
    FACTORY_PATH,
    DrakeMissionSimulator,
    paper_worst_cases,
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
    return build_simulator(SimulatorRecipe.create(FACTORY_PATH, {}))


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
    by_name = {p.name: p for p in simulator.parameters()}
    for region in paper_worst_cases():
        for name, value in region.perturbation.items():
            assert by_name[name].lower <= value <= by_name[name].upper


def test_rerun_reproduces_metrics_exactly(simulator):
    case = RunCase(
        3,
        12345,
        {"m_RH2": 26.0, "w1_SA1": 7.0, "Delta_mul_yy": 0.5},
        MissionWindow(250.0, 270.0, "event:capture"),
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
    diverging = DrakeMissionSimulator(divergence_limit=1e-4, check_interval=5.0)
    case = RunCase(0, 1, {"w0_y": 0.005}, MissionWindow(1050.0, 1070.0))
    with pytest.raises(SimulationDiverged, match="beyond"):
        diverging.run(case)


def test_bad_options_and_values_are_rejected(simulator):
    with pytest.raises(ValueError, match="unknown option"):
        DrakeMissionSimulator(control_rat=5.0)
    with pytest.raises(ValueError, match="m_RH2"):
        simulator.run(RunCase(0, 1, {"m_RH2": 1.0}, MissionWindow(0.0, 1.0)))
    with pytest.raises(ValueError, match="unknown parameter"):
        simulator.run(RunCase(0, 1, {"mass": 1.0}, MissionWindow(0.0, 1.0)))


@pytest.mark.parametrize("name", ["paper.toml", "paper_mc.toml", "heavy_target.toml"])
def test_paper_campaign_specs_load_and_plan(name):
    from oos_drake.campaign.samplers import make_plan
    from oos_drake.campaign.spec import load_spec

    spec = load_spec(CAMPAIGNS / name)
    plan = make_plan(spec)
    assert len(plan) == spec.n_runs
    width = plan["window_end [s]"] - plan["window_start [s]"]
    np.testing.assert_allclose(width, 80.0)
    if spec.sampler.kind == "mu-guided":
        assert len(spec.regions) == 3
        assert (plan["region"] >= 0).sum() > spec.n_runs / 2
        assert plan["weight"].max() <= 1.0 / spec.sampler.defensive_fraction + 1e-9


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
