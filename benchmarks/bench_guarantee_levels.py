"""Level strategy and cost of the analysis' whole-axis guarantee, against the grid-only analysis.

Run: ``.venv/bin/python benchmarks/bench_guarantee_levels.py [--configurations 24]
[--tight 0.005,0.01,1] [--subsets total,mechanical] [--controller controller.json] [--eager]
[--before] [--perturb 1,2]``

The mission study of ``oos analyze`` at reduced size (``--configurations`` equally spaced
mission configurations of the paper's scenario, the analysis' grid, sweep and tightening
options, the make-run controller given by ``--controller``, default the baseline PD), all in
this process (one worker: CPU time is ``time.process_time``), back to back:

* ``grid only``: :func:`~oos_drake.analysis.stability.certified_sweep` without the guarantee;
* for each ``tight`` of ``--tight``: the same with the whole-axis guarantee
  (:func:`~oos_drake.analysis.stability.axis_guarantee` with ``gap`` the target gap, as the
  analysis calls it, and that ``tight``; ``tight = 1`` or more is the level of the code before
  the tight first level, ``(1 + gap)`` times the certified lower bound, since the first level
  is the smaller of the two).

``--eager``: each guarantee also with ``cover_axis(lazy=False)`` (every point's interval by
the Hamiltonian test: the cover before its lazy tests), same run, and the ratio of the two
guarantees' CPU; the counts of Hamiltonian interval tests are printed for both.

``--bands``: each guarantee also with ``cover_axis(bands=True)`` (scalings chosen for a whole
narrow gap tried before solving points in it), same run: its CPU, the ratio of the two
guarantees' CPU, the Hamiltonian tests, the band scalings tried, proved and their intervals'
mean width, and per subset its guaranteed level next to the default's.

``--before``: each guarantee also with ``mu_solver(converge=False)`` (the cover's solver before
the cold start and restarts of the points that raise the level), same run: its CPU, the ratio
of the two guarantees' CPU, and per subset its guaranteed level next to the new one.

``--perturb``: after the runs above, the guarantee (last ``tight``) again on the model array
with its LFR matrix multiplied entry by entry by ``1 + 1e-15 R`` (``R`` uniform in [-1, 1],
one run per seed), and per subset the guaranteed levels and certified lower bounds of all
the inputs and their relative spread (round-off reproducibility; with ``--before`` for both
solvers).

``--baseline REV``: the grid-only run and the guarantee of each ``tight`` with ``oos_drake``
of this checkout and of the git revision ``REV`` (``git archive``, as
``benchmarks/bench_mussv.py``), each in a fresh process (``--repeat`` pairs, alternating which
goes first; the shared machine's load changes between them), and per checkout the ratio of
the guarantee's CPU to its own grid-only CPU (the median over the repeats), the guaranteed
level and the certified lower bound of every subset. Nothing else is run then.

Printed: CPU of each run and its ratio to the grid-only run, the guarantee's own CPU (the
difference: the grid and the spike resolution are the same computation in every run), and
per subset the certified lower bound, the largest grid upper bound, the starting level, the
guaranteed level, its gap above the lower bound, the configurations whose level was raised or
whose cover fell back to the looser level, tested and solved points, and failures. Timings on
a shared machine are noisy: read the ratios of the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=24)
    parser.add_argument(
        "--tight",
        default="0.005,1",
        help="comma-separated tight values [-] ('default': each checkout's own TIGHT_GAP)",
    )
    parser.add_argument("--subsets", default="", help="comma-separated subsets (default: all)")
    parser.add_argument("--controller", default=None, help="controller JSON (default: baseline)")
    parser.add_argument(
        "--eager",
        action="store_true",
        help="also run every guarantee with cover_axis(lazy=False) (every point tested with the "
        "Hamiltonian: the code before the lazy tests) and print the ratio",
    )
    parser.add_argument(
        "--bands",
        action="store_true",
        help="also run every guarantee with cover_axis(bands=True) and print the ratio",
    )
    parser.add_argument(
        "--before",
        action="store_true",
        help="also run every guarantee with mu_solver(converge=False) (no cold start and "
        "restarts of the points that raise the level) and print the ratio and the levels",
    )
    parser.add_argument(
        "--perturb",
        default="",
        help="comma-separated seeds: the guarantee again with the LFR matrix times "
        "(1 + 1e-15 R), and the spread of the guaranteed levels",
    )
    parser.add_argument(
        "--baseline",
        default="",
        help="git revision: ratios and levels of this checkout and of REV, fresh processes",
    )
    parser.add_argument("--repeat", type=int, default=1, help="pairs of runs with --baseline")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.baseline:
        compare(args)
        return

    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop, mission_times
    from oos_drake.analysis.run import AnalysisOptions
    from oos_drake.analysis.stability import certified_sweep
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.blas import limit_blas_threads
    from oos_drake.scenario.data import load_scenario

    limit_blas_threads(1)
    scenario = load_scenario("paper")
    options = AnalysisOptions(configurations=args.configurations)
    times = mission_times(options.configurations, scenario)
    system = mission_closed_loop(scenario_controller(args.controller, scenario), times, scenario)
    named = uncertainty_subsets(system.system.uncertainty)
    wanted = [s for s in args.subsets.split(",") if s] or list(named)
    subsets = {k: named[k] for k in wanted}
    omega = options.grid()
    sweep = dataclasses.replace(options.sweep, n_jobs=1)

    import functools

    import oos_drake.robust.mu_intervals as mu_intervals

    counts = {"hamiltonian": 0, "bands": 0, "band intervals": 0, "band width": 0.0}
    dg_interval, cover_axis = mu_intervals.dg_interval, mu_intervals.cover_axis
    mu_solver = mu_intervals.mu_solver

    def counted_dg(*a, **k):
        counts["hamiltonian"] += 1
        out = dg_interval(*a, **k)
        if len(a) > 1 and any(a[1] is sc for sc in band_made):
            counts["band intervals"] += 1
            counts["band width"] += out[1] / out[0] - 1.0 if out[0] > 0 else 0.0
        return out

    band_made = []  # the scalings the bands gave (their intervals are counted)
    band = getattr(mu_intervals._MuSolver, "band", None)  # None: a checkout before the bands

    def counted_band(self, *a, **k):
        counts["bands"] += 1
        bound, sc = band(self, *a, **k)
        band_made.append(sc)
        return bound, sc

    # the analysis calls them through the module: counted here
    mu_intervals.dg_interval = counted_dg
    if band is not None:
        mu_intervals._MuSolver.band = counted_band

    def run(guarantee, tight=None, lazy=True, converge=True, model=system.system, bands=False):
        extra = {"bands": bands} if bands else {}  # a checkout before the bands has none
        mu_intervals.cover_axis = functools.partial(cover_axis, lazy=lazy, **extra)
        mu_intervals.mu_solver = functools.partial(mu_solver, converge=converge)
        for k in counts:
            counts[k] = 0
        band_made.clear()
        clock = time.process_time()
        out = certified_sweep(
            model,
            omega,
            subsets,
            times=times,
            options=sweep,
            tighten=options.tighten,
            critical_iterations=options.certify_iterations,
            progress=False,
            time_budget=options.spike_budget,
            guarantee=guarantee,
            guarantee_gap=options.tighten.target_gap,
            guarantee_tight=tight,
        )
        return out, time.process_time() - clock

    _, base = run(False)
    if args.json:  # one process of --baseline: CPU and levels as one JSON line
        import json

        out = {"grid": base, "runs": {}}
        for key, tight in _tights(args.tight):
            study, cpu = run(True, tight)
            out["runs"][key] = {
                "cpu": cpu,
                "levels": {
                    name: [g.mu_upper, study.certificates[name].mu_lower]
                    for name, g in study.guarantees.items()
                },
            }
        print(json.dumps(out))
        return
    print(
        f"{times.size} mission configurations, {omega.size} frequencies, "
        f"target gap {options.tighten.target_gap}; grid only: CPU {base:.1f} s"
    )
    head = (
        f"{'tight':>6s} {'subset':15s} {'lower':>9s} {'grid up':>9s} {'start':>9s} "
        f"{'guaranteed':>10s} {'gap [%]':>7s} {'raised':>6s} {'fell back':>9s} "
        f"{'tested':>6s} {'solved':>6s} {'fail':>4s}"
    )
    for label, tight in _tights(args.tight):
        if args.eager:
            _, eager = run(True, tight, lazy=False)
            tests = counts["hamiltonian"]
        if args.bands:
            band_study, banded = run(True, tight, bands=True)
            band_counts = dict(counts)
        if args.before:
            old_study, old = run(True, tight, converge=False)
        study, cpu = run(True, tight)
        print(
            f"tight {label}: CPU {cpu:.1f} s = {cpu / base:.2f} x grid only; "
            f"guarantee {cpu - base:.1f} s; Hamiltonian tests {counts['hamiltonian']}"
        )
        if args.eager:
            print(
                f"  eager (lazy=False, same run): CPU {eager:.1f} s = {eager / base:.2f} x grid "
                f"only; guarantee {eager - base:.1f} s; Hamiltonian tests {tests}; guarantee "
                f"lazy / eager {(cpu - base) / max(eager - base, 1e-9):.2f}"
            )
        if args.bands:
            n = max(band_counts["band intervals"], 1)
            print(
                f"  bands (bands=True, same run): CPU {banded:.1f} s = {banded / base:.2f} x grid "
                f"only; guarantee {banded - base:.1f} s; guarantee bands / default "
                f"{(banded - base) / max(cpu - base, 1e-9):.2f}; Hamiltonian tests "
                f"{band_counts['hamiltonian']}; bands tried {band_counts['bands']}, their "
                f"intervals {band_counts['band intervals']} (mean width "
                f"{100 * band_counts['band width'] / n:.2f} %)"
            )
            for name, g in band_study.guarantees.items():
                print(
                    f"  {name:15s} guaranteed with bands {g.mu_upper:.9g} default "
                    f"{study.guarantees[name].mu_upper:.9g}"
                )
        if args.before:
            print(
                f"  before (converge=False, same run): CPU {old:.1f} s = {old / base:.2f} x grid "
                f"only; guarantee {old - base:.1f} s; guarantee now / before "
                f"{(cpu - base) / max(old - base, 1e-9):.2f}"
            )
            for name, g in old_study.guarantees.items():
                print(
                    f"  {name:15s} guaranteed before {g.mu_upper:.9g} now "
                    f"{study.guarantees[name].mu_upper:.9g} (lower "
                    f"{old_study.certificates[name].mu_lower:.9g} / "
                    f"{study.certificates[name].mu_lower:.9g})"
                )
        print(head)
        for name, g in study.guarantees.items():
            lower = study.certificates[name].mu_lower
            print(
                f"{label:>6s} {name:15s} {lower:9.5g} {np.max(g.grid_upper):9.5g} "
                f"{g.floor:9.5g} {g.mu_upper:10.5g} {100 * (g.mu_upper - lower) / g.mu_upper:7.2f} "
                f"{g.raised:6d} {int(g.fell_back.sum()):9d} {int(g.points.sum()):6d} "
                f"{int(g.solved.sum()):6d} {len(g.failures):4d}"
            )

    seeds = [int(k) for k in args.perturb.split(",") if k]
    if seeds:
        from oos_drake.lfr.core import LFR

        lfr = system.system
        for converge in (False, True) if args.before else (True,):
            studies = {"M": run(True, tight, converge=converge)[0]}
            for seed in seeds:
                R = np.random.default_rng(seed).uniform(-1.0, 1.0, lfr._M.shape)
                model = LFR(
                    np.array(lfr._M) * (1 + 1e-15 * R),
                    lfr._n,
                    lfr._blocks,
                    input_names=lfr._input_names,
                    output_names=lfr._output_names,
                )
                studies[f"seed {seed}"] = run(True, tight, converge=converge, model=model)[0]
            print(f"round-off (M times 1 + 1e-15 R), converge={converge}, tight {label}:")
            for name in subsets:
                up = np.array([st.guarantees[name].mu_upper for st in studies.values()])
                lo = np.array([st.certificates[name].mu_lower for st in studies.values()])
                print(
                    f"  {name:15s} guaranteed {' '.join(f'{u:.9g}' for u in up)} (spread "
                    f"{up.max() / up.min() - 1:.2e}); lower {' '.join(f'{v:.9g}' for v in lo)} "
                    f"(spread {lo.max() / lo.min() - 1:.2e})"
                )


def _tights(text: str) -> list:
    """``--tight``: ``(label, value)`` pairs; ``default`` is None (the checkout's TIGHT_GAP)."""
    out = []
    for t in text.split(","):
        t = t.strip()
        out.append(("default", None) if t == "default" else (str(float(t)), float(t)))
    return out


def compare(args) -> None:
    """``--baseline``: this checkout and ``args.baseline`` in fresh processes, alternating."""
    import json
    import os
    import subprocess
    import sys

    from bench_mussv import baseline_checkout

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    paths = {"this checkout": root, f"baseline {args.baseline}": baseline_checkout(args.baseline)}
    cmd = [sys.executable, os.path.abspath(__file__), "--json"]
    cmd += ["--configurations", str(args.configurations), "--tight", args.tight]
    cmd += ["--subsets", args.subsets]
    cmd += ["--controller", args.controller] if args.controller else []
    results = {name: [] for name in paths}
    for k in range(max(args.repeat, 1)):
        for name in list(paths)[:: 1 if k % 2 else -1]:  # the baseline first, then alternating
            env = dict(os.environ, PYTHONPATH=paths[name])
            res = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"{name} failed:\n{res.stderr[-3000:]}")
            results[name].append(json.loads(res.stdout.strip().splitlines()[-1]))
    print(
        f"{args.configurations} mission configurations, controller {args.controller or 'baseline'};"
        f" {max(args.repeat, 1)} run(s) per checkout, CPU seconds, one process each"
    )
    for key, _ in _tights(args.tight):
        print(f"tight {key}:")
        for name, runs in results.items():
            grid = [r["grid"] for r in runs]
            cpu = [r["runs"][key]["cpu"] for r in runs]
            ratio = float(np.median([c / g for c, g in zip(cpu, grid, strict=True)]))
            print(
                f"  {name:28s} grid only {np.median(grid):6.1f} s, guaranteed "
                f"{np.median(cpu):6.1f} s: ratio {ratio:.2f} (runs: "
                f"{', '.join(f'{c / g:.2f}' for c, g in zip(cpu, grid, strict=True))})"
            )
        print(f"    {'subset':15s} " + " ".join(f"{n[:22]:>34s}" for n in results))
        print(f"    {'':15s} " + " ".join(f"{'guaranteed  lower  gap [%]':>34s}" for _ in results))
        for sub in results["this checkout"][0]["runs"][key]["levels"]:
            cells = []
            for runs in results.values():
                up, lo = runs[0]["runs"][key]["levels"][sub]
                cells.append(f"{up:>12.6g} {lo:>10.6g} {100 * (up - lo) / lo:>9.2f}")
            print(f"    {sub:15s} " + " ".join(f"{c:>34s}" for c in cells))


if __name__ == "__main__":
    main()
