"""Cost of the whole-axis guarantee (robust.mu_intervals) against the grid-only bounds.

Run: ``.venv/bin/python benchmarks/bench_axis_guarantee.py [--mission 50:70] [--subset total]``

For the examples of the tests (lightly damped oscillators with real parameters, two modes, a
third-order loop whose crossing frequency moves), ``robstab`` and ``wcgain`` with
``guaranteed=False`` (grid only) and ``guaranteed=True`` in the same run: wall time, the ratio,
the bounds and the number of frequencies the cover solved. Timings on a shared machine are
noisy: read the ratios of the same run. The analysis' own ratio is in the ``guarantee`` entry of
each study's timing detail of ``summary.json`` (``oos analyze``), beside ``grid`` and
``tighten+certify``.

``--mission FIRST:LAST``: the analysis' covers (:mod:`oos_drake.analysis.stability`) of the
consecutive mission configurations ``FIRST .. LAST - 1`` of 330 (make-run controller
``--controller``, default the baseline PD), one subset, all at the level ``1.03`` times the
largest lower bound found on the grid, or ``--level`` (give the analysis' level,
``(1 + target gap)`` times its certified lower bound: the grid's power-iteration lower bound
can be far below mu with real parameters, and then covers raise their level one by one), in
this process, CPU time (``time.process_time``), solved points, tested points and the largest
level of: ``alone`` (each configuration its own cover, grid scalings then solves), ``1 range``
(each cover continued from the previous one's essential scalings: a task of the analysis),
and, for ``R`` in ``--ranges`` (default 2,4,8), the configurations cut into ``R`` contiguous
ranges, each continued (range after range). Ratios are against ``1 range, reference`` of the
same run: the same as ``1 range`` with every solved point above the floor polished
(``mu_solver(lazy_polish=False)``, the solver before it polished only above the level
already reached). On
a slice this short the ranges are short too: at full size a range's cold start costs
relatively more.
"""

from __future__ import annotations

import argparse
import time

import control
import numpy as np

from oos_drake.lfr import as_lfr, feedback, ureal
from oos_drake.robust import robstab, wcgain


def second_order(k, c):
    integ = as_lfr(control.tf(1, [1, 0]))
    return feedback(integ * feedback(integ, c), k)


def cases():
    yield (
        "oscillator 10 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.2, plusminus=0.1)),
    )
    yield (
        "oscillator 1 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.02, plusminus=0.01)),
    )
    yield (
        "oscillator 0.3 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.006, plusminus=0.003)),
    )
    yield (
        "two modes",
        second_order(ureal("k1", 1, plusminus=0.3), ureal("c1", 0.01, plusminus=0.005))
        + second_order(ureal("k2", 9, plusminus=3), ureal("c2", 0.03, plusminus=0.01)),
    )


def timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def mission(first, last, subset, controller, level=None, ranges=(2, 4, 8)):
    """Covers of consecutive mission configurations, alone and continued (see the docstring)."""
    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.run import AnalysisOptions
    from oos_drake.analysis.stability import _analysis_model, _range_covers
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_intervals import SLACK, Realization
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound
    from oos_drake.robust.sweep import model_grid

    limit_blas_threads(1)
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario("paper")
    times = mission_times(330, scenario)[first:last]
    system = mission_closed_loop(scenario_controller(controller, scenario), times, scenario).system
    members = uncertainty_subsets(system.uncertainty)[subset]
    grid = AnalysisOptions().grid()
    problems, lower = [], 0.0
    for j in range(times.size):
        A, Bw, Cz, Dzw, blk, _, _ = _analysis_model(system, j, members)
        w = model_grid(A, grid)
        M = Realization(A, Bw, Cz, Dzw).response(w)
        up = mu_upper_bound(M, parse_blk(blk), max_iter=100)
        lo = mu_lower_bound(M, parse_blk(blk), start_inputs=up.worst_input)
        lower = max(lower, float(np.max(lo.lower)))
        problems.append((A, Bw, Cz, Dzw, w, up.params, up.upper, lo.lower))
    floor = 1.03 * lower if level is None else level
    configurations = []  # as axis_guarantee gives them to its tasks
    for A, Bw, Cz, Dzw, w, params, up, lo in problems:
        peaks = np.unique([np.argmax(up), np.argmax(lo)])
        seeds = (w[peaks], up[peaks])  # solved where above the level (_range_covers)
        configurations.append((A, Bw, Cz, Dzw, seeds, w, params, up))
    print(f"mission configurations {first}..{last - 1}, subset {subset}, level {floor:.5g}")
    head = ("CPU [s]", 8), ("ratio", 6), ("solved", 7), ("tested", 7), ("max level", 10)
    print(f"{'covers':22s} " + " ".join(f"{h:>{n}s}" for h, n in head))

    def cut(n_ranges):
        edges = np.linspace(0, len(configurations), n_ranges + 1).round().astype(int)
        return [configurations[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]

    def run(name, parts, lazy_polish=True):
        clock = time.process_time()
        out = [_range_covers(blk, floor, SLACK, r, lazy_polish) for r in parts]
        seconds = time.process_time() - clock
        rows = [o for part in out for o in part]
        base = results.setdefault("1 range, reference", seconds)
        print(
            f"{name:22s} {seconds:8.2f} {seconds / base:6.2f} {sum(o[3] for o in rows):7d} "
            f"{sum(o[1] for o in rows):7d} {max(o[0] for o in rows):10.5g}"
        )

    results = {}
    # the reference: every point above the floor polished (mu_solver(lazy_polish=False),
    # the code before the solver polished to the level reached); then the default
    run("1 range, reference", cut(1), lazy_polish=False)
    run("1 range", cut(1))
    run("alone", cut(len(configurations)))
    for n_ranges in ranges:
        run(f"{n_ranges} ranges", cut(n_ranges))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", default=None, help="FIRST:LAST mission configurations")
    parser.add_argument("--subset", default="total")
    parser.add_argument("--controller", default=None, help="controller JSON (default: baseline)")
    parser.add_argument("--level", type=float, default=None, help="level of every cover [-]")
    parser.add_argument("--ranges", default="2,4,8", help="numbers of ranges to time")
    args = parser.parse_args()
    if args.mission:
        first, last = (int(x) for x in args.mission.split(":"))
        ranges = [int(x) for x in args.ranges.split(",")]
        mission(first, last, args.subset, args.controller, args.level, ranges)
        return
    print(
        f"{'case':18s} {'fn':8s} {'grid [s]':>9s} {'guar [s]':>9s} {'ratio':>6s} "
        f"{'grid upper':>11s} {'guar upper':>11s} {'lower':>10s} {'points':>6s}"
    )
    for name, sys in cases():
        for fn in (wcgain, robstab):
            grid, t0 = timed(fn, sys, guaranteed=False)
            guar, t1 = timed(fn, sys)
            if fn is robstab:  # report mu (1 / margin)
                gu, uu, lo = 1 / grid.lower, 1 / guar.lower, 1 / guar.upper
            else:
                gu, uu, lo = grid.upper, guar.upper, guar.lower
            print(
                f"{name:18s} {fn.__name__:8s} {t0:9.2f} {t1:9.2f} {t1 / t0:6.2f} "
                f"{gu:11.5g} {uu:11.5g} {lo:10.5g} {guar.guarantee.omega.size:6d}"
            )


if __name__ == "__main__":
    main()
