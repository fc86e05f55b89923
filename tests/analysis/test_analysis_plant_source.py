"""``oos analyze --plant drake``: closed loops from the Drake twin's LFRs equal the TITOP ones."""

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.analysis.models import (  # noqa: E402
    docking_closed_loop,
    mission_closed_loop,
    mission_times,
)
from oos_drake.analysis.subsets import uncertainty_subsets  # noqa: E402
from oos_drake.lfr import usubs  # noqa: E402
from oos_drake.scenario.data import load_scenario  # noqa: E402

PAPER = load_scenario("paper")
OMEGA = 2 * np.pi * np.geomspace(0.005, 5.0, 60)


@pytest.fixture(scope="module")
def controller():
    from oos_drake.analysis.controller import scenario_controller

    return scenario_controller(None, PAPER)  # the baseline PD


def _compare(drake, titop, rng):
    assert drake.system.occurrences == titop.system.occurrences
    # what each block is (unit, quantity) travels with it: the same subsets, hence the same
    # studies and tables (without quantities the twin's blocks fell out of modal/mechanical)
    for name, spec in titop.system.uncertainty.items():
        ours = drake.system.uncertainty[name]
        assert (ours.unit, ours.quantity) == (spec.unit, spec.quantity), name
    assert uncertainty_subsets(drake.system.uncertainty) == uncertainty_subsets(
        titop.system.uncertainty
    )
    assert drake.system.batch_shape == titop.system.batch_shape
    deltas = {n: rng.uniform(-1, 1) for n, spec in titop.system.uncertainty.items()
              if spec.kind == "ureal"}  # fmt: skip
    a = usubs(drake.system, deltas, normalized=True)
    b = usubs(titop.system, deltas, normalized=True)
    # remaining blocks (Delta_add, Delta_mul: ultidyn) at zero: nominal of the rest
    Ha, Hb = a.nominal.freqresp(OMEGA), b.nominal.freqresp(OMEGA)
    error = np.abs(Ha - Hb).max() / np.abs(Hb).max()
    assert error < 1e-8, error


def test_mission_loops_from_drake_equal_the_titop_loops(controller):
    rng = np.random.default_rng(1)
    times = mission_times(4, PAPER)  # free target, arm-held, docked, tilted arrays
    drake = mission_closed_loop(controller, times, PAPER, source="drake")
    titop = mission_closed_loop(controller, times, PAPER)
    _compare(drake, titop, rng)


@pytest.mark.parametrize("phase", ["7", "8"])
def test_docking_loops_from_drake_equal_the_titop_loops(controller, phase):
    rng = np.random.default_rng(2)
    stiffness = np.geomspace(0.1, 1e5, 4)
    drake = docking_closed_loop(controller, phase, stiffness, scenario=PAPER, source="drake")
    titop = docking_closed_loop(controller, phase, stiffness, scenario=PAPER)
    _compare(drake, titop, rng)


def test_unknown_plant_source_is_refused(controller):
    with pytest.raises(ValueError, match="plant source must be one of"):
        mission_closed_loop(controller, [0.0], PAPER, source="simulink")


def test_drake_and_titop_realizations_give_the_same_mu_upper_bound(controller):
    """The D-G bound depends on M(j omega) only, not on the realization: on the Drake and
    TITOP closed loops (different state coordinates and channel bases: the matrices differ,
    mu does not) the peak upper bound of the total subset around the mission's critical
    frequency, as the whole-axis guarantee computes it (long runs where a point decides the
    level), agrees within 0.5 % (issue 18), configuration by configuration. (With the grid's
    budget alone the two differ by up to 7 %, both 10-20 % above the converged value.)"""
    from oos_drake.analysis.stability import _analysis_model
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.robust.mu_intervals import Realization, mu_solver

    times = mission_times(4, PAPER)[2:]  # docked, tilted arrays (where the mission's peak is)
    omega = 2 * np.pi * np.linspace(0.78, 0.86, 5)  # around the critical 0.82 Hz
    peaks = {}
    for source in ("drake", "lfr"):
        loop = mission_closed_loop(controller, times, PAPER, source=source).system
        members = uncertainty_subsets(loop.uncertainty)["total"]
        for model in range(len(times)):
            A, Bw, Cz, Dzw, blk, _, _ = _analysis_model(loop, model, members)
            real = Realization(A, Bw, Cz, Dzw)
            upper, _, _ = mu_solver(real, blk, polish_above=0.0)(omega)
            peaks[source, model] = float(np.max(upper))
    for model in range(len(times)):
        d, t = peaks["drake", model], peaks["lfr", model]
        assert abs(d - t) <= 0.005 * t, (model, d, t)


def test_grid_bounds_on_the_drake_loops_are_as_tight_as_on_the_titop_loops(controller):
    """The analysis' grid optimizer (cold start, then the converged passes of
    ``_converge_model``) on the total subset, same frequency grid: on the twin's LFRs the
    bounds stay close to those on the TITOP LFRs point by point and their peak is not higher
    (0.5 %). Before the twin's modal frequencies were affine and its channels canonical, the
    same optimizer stopped up to 2.45 times higher on the twin (issue 18's spike)."""
    from oos_drake.analysis.run import AnalysisOptions
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.lfr_analysis import (
        delta_channel_response,
        model_matrices,
        subset_parts,
    )
    from oos_drake.robust.sweep import SweepOptions, _converge_model, model_grid

    times = mission_times(4, PAPER)[3:]  # tilted arrays (the mission's peak)
    omega = AnalysisOptions().grid()
    bounds = {}
    for source in ("drake", "lfr"):
        loop = mission_closed_loop(controller, times, PAPER, source=source).system
        A, Bw, Cz, Dzw = model_matrices(loop)
        zr, wc, blk = subset_parts(loop, uncertainty_subsets(loop.uncertainty))["total"]
        for model in range(len(times)):
            grid = model_grid(A[model], omega)
            M = delta_channel_response(A[model], Bw[model], Cz[model], Dzw[model], grid)
            M = M[:, zr][:, :, wc]
            bounds[source, model] = _converge_model(M, parse_blk(blk), SweepOptions())[0]
    for model in range(len(times)):
        d, t = bounds["drake", model], bounds["lfr", model]
        assert d.max() <= 1.005 * t.max(), (model, d.max(), t.max())
        assert np.all(d <= 1.25 * t), (model, (d / t).max())
