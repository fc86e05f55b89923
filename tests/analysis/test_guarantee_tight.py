"""``oos analyze --guarantee-tight`` and the ``guarantee fell back`` column of the peaks table.

The option is the ``tight`` of :func:`~oos_drake.analysis.stability.axis_guarantee` (the first
level of the whole-axis covers, relative to the largest bound found); a configuration whose
cover does not close at that level is covered again from ``(1 + target gap)`` times the
certified lower bound. The column says whether that happened.

The fallback is forced for real, cheaply: the first cover of each configuration gets a tiny
budget (``max_rounds=0``: its seeds and prior points only, no point added), which does not
always close on the closed-form example below; a cover at the fallback level has its normal
budget. Whether each configuration fell back is read off the sequence of covers the analysis
asked for (a cover at the fallback level right after the configuration's first one), not off
the result's own bookkeeping.
"""

import control
import numpy as np
import pytest

from oos_drake.analysis import stability
from oos_drake.analysis.models import ModelArray
from oos_drake.analysis.run import AnalysisOptions, _certify, _Studies, guaranteed_table
from oos_drake.analysis.stability import TIGHT_GAP, SweepOptions
from oos_drake.app.analyze import analysis_options, pipeline_analysis_options
from oos_drake.app.main import build_parser, main
from oos_drake.lfr import feedback, ureal, usubs
from oos_drake.robust import mu_intervals

GAINS = np.array([0.8, 1.0, 1.2])
GAP = 0.03  # the analysis' target gap (the fallback level is (1 + GAP) x the lower bound)


def _array():
    """``k a / ((s+1)(s+2)(s+3))`` in unit feedback, ``k = 40 +- 10``: unstable from
    ``k a = 60`` (Routh), so ``mu = 10 / (60 / a - 40)`` per configuration (closed form)."""
    k = ureal("k", 40.0, plusminus=10.0)
    a = ureal("a", 1.0, range=(0.1, 2.0))
    loop = usubs(feedback(k * a * control.tf(1, [1, 6, 11, 6]), 1), {"a": GAINS})
    return ModelArray(loop, GAINS, "gain [-]", "mission")


OMEGA = 2 * np.pi * np.geomspace(0.05, 5.0, 9)
SWEEP = SweepOptions(n_jobs=1, converge_passes=1, converge_iterations=60)


def _options(**kwargs):
    return AnalysisOptions(sweep=SWEEP, progress=False, guarantee=True, **kwargs)


def _study(options, monkeypatch, starve=False):
    """The analysis' certified sweep of :func:`_array` (through :class:`_Studies`, as
    :func:`~oos_drake.analysis.run.compute_analysis` runs it) -> ``(study, the tight
    axis_guarantee got, the floors of the covers asked for)``."""
    seen, floors = {}, []
    real_guarantee, real_cover = stability.axis_guarantee, mu_intervals.cover_axis

    def recorder(pool, subsets, slack=None, gap=None, tight=None):
        seen["tight"], seen["gap"] = tight, gap
        (sub,) = subsets.values()
        seen["fallback"] = (1 + gap) * sub.lower  # the level of a fallback (documented)
        return real_guarantee(pool, subsets, slack=slack, gap=gap, tight=tight)

    def cover(real, solve, seeds, *, floor, **kwargs):
        floors.append(floor)
        if starve and floor < seen["fallback"]:  # a first level: a tiny budget
            kwargs["max_rounds"] = 0
        return real_cover(real, solve, seeds, floor=floor, **kwargs)

    monkeypatch.setattr(stability, "axis_guarantee", recorder)
    monkeypatch.setattr(mu_intervals, "cover_axis", cover)
    study = _Studies(options, OMEGA)(_array().system, {"k": ["k"]}, GAINS, "test")
    return study, seen, floors


def test_the_option_reaches_axis_guarantee(monkeypatch):
    args = build_parser().parse_args(["analyze", "--out", "x", "--guarantee-tight", "0.2"])
    options = analysis_options(args, _scenario())
    assert options.guarantee_tight == 0.2
    options = AnalysisOptions(
        sweep=SWEEP, progress=False, guarantee_tight=options.guarantee_tight
    )  # the CLI's value, on the small example
    _, seen, _ = _study(options, monkeypatch)
    assert (seen["tight"], seen["gap"]) == (0.2, options.tighten.target_gap)


def test_the_default_is_unchanged_from_the_cli_to_the_pipeline():
    scenario = _scenario()
    args = build_parser().parse_args(["analyze", "--out", "x"])
    assert analysis_options(args, scenario).guarantee_tight == TIGHT_GAP == 0.015
    pipeline = pipeline_analysis_options(scenario, quick=True, workers=1)
    assert pipeline.guarantee_tight == TIGHT_GAP
    assert AnalysisOptions().guarantee_tight == TIGHT_GAP


@pytest.mark.parametrize("value", ["-0.01", "nan", "inf"])
def test_bad_values_exit_2_in_one_line_and_write_nothing(tmp_path, capsys, value):
    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), "--guarantee-tight", value]) == 2
    message = capsys.readouterr().err.strip().splitlines()
    assert len(message) == 1 and "guarantee_tight" in message[0], message
    assert list(tmp_path.iterdir()) == []


def test_a_non_number_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["analyze", "--out", "x", "--guarantee-tight", "one"])
    assert stop.value.code == 2
    assert "--guarantee-tight" in capsys.readouterr().err


@pytest.mark.parametrize("starve", [False, True])
def test_the_column_says_exactly_when_a_cover_fell_back(monkeypatch, starve):
    study, seen, floors = _study(_options(), monkeypatch, starve=starve)
    g = study.guarantees["k"]
    fallback = seen["fallback"]
    assert g.floor < fallback  # a fallback level exists: (1 + gap) lower > first level
    # the covers asked for, in order: each configuration's first level, then the fallback
    # level right after it if that configuration fell back
    fell = []
    for floor in floors:
        if floor == fallback:
            assert fell and not fell[-1], floors
            fell[-1] = True
        else:
            fell.append(False)
    assert len(fell) == GAINS.size and any(fell) == starve, floors
    rows, _, _ = _certify(_array(), study, {"k": ["k"]}, configuration_label=str)
    assert "guarantee fell back" in rows.columns
    assert rows["guarantee fell back"].iloc[0] == any(fell)
    per_configuration = guaranteed_table("mission", study, "gain [-]", GAINS)
    assert per_configuration["cover fell back"].tolist() == fell
    # a fallback still proves a bound on the whole axis, above the closed-form peak
    exact = 10.0 / (60.0 / GAINS - 40.0)
    assert g.covered and np.all(g.levels >= exact * (1 - 1e-9))
    assert np.all(g.levels[fell] >= fallback * (1 - 1e-12))


def _scenario():
    from oos_drake.scenario.data import load_scenario

    return load_scenario("paper")
