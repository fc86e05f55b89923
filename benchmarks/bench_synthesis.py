"""Benchmark: one gamma evaluation over the model array vs one slycot ab13dd call per model.

Run ``python benchmarks/bench_synthesis.py [--plant lfr|drake|synthetic] [--models 200]
[--repeats 3] [--synthesis] [--workers 2]``.

The baseline (ab13dd, the routine behind MATLAB's ``norm(sys, inf)`` and python-control's
``hinfnorm``, one call per closed loop, tol 1e-10) is measured in the same run on the same closed
loops. The table gives CPU and wall times (best of ``--repeats``), the speed-ups on each and the
largest relative difference of the norms. Rows:

- ``modal``: per-model closed-loop eigendecomposition, modal frequency response, slope-secant
  peak refinement (:func:`peak_gain` without evaluator);
- ``loop, warm``: the synthesis path: closed-loop eigenvalues only (stability, grid), responses
  and reported values from the plant's modal form (:mod:`oos_drake.control.loop_response`, built
  once per plant array and reused for every gain: that build is excluded), golden-section
  refinement;
- ``loop, cold``: the same including that build;
- ``... 2 workers``: eigendecompositions split over 2 threads (wall time drops on 2 free cores;
  CPU time does not);
- ``+ Hamiltonian certificate``: every norm checked by the BBBS test.

It also prints the model-array build time and, with ``--synthesis``, the synthesis wall and CPU
time. Every computation uses one OpenBLAS thread per worker (see :mod:`oos_drake.blas`).

``--baseline REV``: ``oos synth``'s default synthesis (``--models`` configurations, 200 by
default, ``oos synth``'s options and executor with ``--workers`` processes) with ``oos_drake``
of this checkout and of the git revision ``REV`` (``git archive``, as
``benchmarks/bench_mussv.py``), each in a fresh process (``--repeat`` pairs, alternating which
goes first), and per checkout: gamma, the synthesis' CPU time (this process and its worker
processes, ``resource.getrusage``) and wall time, and the CPU ratio of this checkout to the
baseline (the median over the pairs). The machine is shared: read the CPU times; the wall
times depend on the load. Nothing else is run then. ``--json [--qp active-set]``: one such
synthesis in this process, printed as a JSON line (``--qp``: the bundle step's QP solver,
``SynthesisOptions.qp``; ``active-set`` is another design; ``--seed``: the restarts' seed).
``--profile FILE``: the same synthesis in this process under cProfile, with one worker (every
run in this process), the stats in ``FILE``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from slycot import ab13dd

from oos_drake.app.synth import baseline_for, make_plants
from oos_drake.blas import single_threaded_blas
from oos_drake.control.interconnection import weighted_interconnection
from oos_drake.control.loop_response import LoopResponse, LoopSigma
from oos_drake.control.synthesis import SynthesisOptions, synthesize
from oos_drake.robust.peak_gain import peak_gain


def ab13dd_all(M):
    out = np.empty(M.A.shape[0])
    for i in range(M.A.shape[0]):
        A, B, C, D = M.A[i], M.B[i], M.C[i], M.D[i]
        n, m, p = A.shape[0], B.shape[1], C.shape[0]
        out[i] = ab13dd("C", "I", "N", "D", n, m, p, A, np.eye(n), B, C, D, tol=1e-10)[0]
    return out


def best_of(fn, repeats):
    """Best wall and CPU time over ``repeats`` runs, and the last result."""
    walls, cpus, result = [], [], None
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        result = fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return min(walls), min(cpus), result


def default_synthesis(
    plant: str, models: int, workers: int, qp: str = "slsqp", seed: int | None = None
) -> dict:
    """``oos synth``'s synthesis (its defaults, ``workers`` processes; ``seed``: another seed of
    the restarts): gamma, CPU of this process and its children [s], wall time [s] (the model
    array's build excluded)."""
    import resource

    from oos_drake.app.synth import ControllerOptions
    from oos_drake.control.components import DesignSpecification
    from oos_drake.processes import make_executor
    from oos_drake.scenario.data import load_scenario

    scenario = load_scenario("paper")
    plants = make_plants(plant, models, scenario)
    K0 = baseline_for(plants, scenario.mission.first_docking_time)
    defaults = ControllerOptions()
    options = SynthesisOptions(
        restarts=defaults.restarts,
        max_iterations=defaults.max_iterations,
        worst_case_rounds=defaults.worst_case_rounds,
        seed=defaults.seed if seed is None else seed,
        workers=workers,
        working_set=defaults.working_set,
        qp=qp,
    )
    spec = DesignSpecification.from_requirements(scenario.control)

    def cpu():
        own = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime

    w, c = time.perf_counter(), cpu()
    with make_executor(workers) as executor:
        result = synthesize(plants, K0, spec=spec, options=options, executor=executor)
    return dict(gamma=result.gamma, cpu=cpu() - c, wall=time.perf_counter() - w)


def compare(args) -> None:
    """``--baseline``: this checkout and ``args.baseline`` in fresh processes, alternating."""
    import os
    import subprocess
    import sys

    from bench_mussv import baseline_checkout

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    paths = {"this checkout": root, f"baseline {args.baseline}": baseline_checkout(args.baseline)}
    cmd = [sys.executable, os.path.abspath(__file__), "--json", "--plant", args.plant]
    cmd += ["--models", str(args.models), "--workers", str(args.workers)]
    results = {name: [] for name in paths}
    for k in range(max(args.repeat, 1)):
        for name in list(paths)[:: 1 if k % 2 else -1]:  # the baseline first, then alternating
            env = dict(os.environ, PYTHONPATH=paths[name])
            res = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=paths[name])
            if res.returncode != 0:
                raise RuntimeError(f"{name} failed:\n{res.stderr[-3000:]}")
            results[name].append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(f"{name}: {results[name][-1]}", flush=True)
    base = results[f"baseline {args.baseline}"]
    print(
        f"oos synth's default synthesis, plant {args.plant}, {args.models} configurations, "
        f"{args.workers} worker(s); {max(args.repeat, 1)} run(s) per checkout"
    )
    for name, runs in results.items():
        ratio = float(np.median([r["cpu"] / b["cpu"] for r, b in zip(runs, base, strict=True)]))
        print(
            f"  {name:28s} gamma {runs[0]['gamma']:.6f}, "
            f"CPU {np.median([r['cpu'] for r in runs]):7.1f}"
            f" s, wall {np.median([r['wall'] for r in runs]):7.1f} s, CPU ratio to the baseline "
            f"{ratio:.3f}"
        )
    gammas = [runs[0]["gamma"] for runs in results.values()]
    print(f"  relative gamma difference {abs(gammas[0] - gammas[1]) / gammas[1]:.2e}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--plant", default="lfr", choices=["synthetic", "lfr", "drake"])
    parser.add_argument("--models", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2, help="threads of the 2-worker rows")
    parser.add_argument("--synthesis", action="store_true", help="also time a full synthesis")
    parser.add_argument(
        "--baseline",
        default=None,
        help="git revision: oos synth's default synthesis with this checkout and REV",
    )
    parser.add_argument("--repeat", type=int, default=1, help="pairs of runs with --baseline")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument(
        "--qp",
        default="slsqp",
        help="with --json: the bundle step's QP solver (SynthesisOptions.qp; 'active-set' "
        "changes the design)",
    )
    parser.add_argument(
        "--seed", type=int, default=None, help="with --json: the restarts' seed (oos synth's)"
    )
    parser.add_argument("--profile", default=None, help="cProfile stats file of one synthesis")
    args = parser.parse_args(argv)
    if args.json:  # one process of --baseline
        result = default_synthesis(args.plant, args.models, args.workers, args.qp, args.seed)
        print(json.dumps(result))
        return
    if args.baseline:
        compare(args)
        return
    if args.profile:
        import cProfile

        cProfile.runctx(
            "default_synthesis(plant, models, 1)",
            globals(),
            dict(plant=args.plant, models=args.models),
            args.profile,
        )
        return

    w, c = time.perf_counter(), time.process_time()
    from oos_drake.scenario.data import load_scenario

    plants = make_plants(args.plant, args.models, load_scenario("paper"))
    build_wall, build_cpu = time.perf_counter() - w, time.process_time() - c
    K0 = baseline_for(plants)
    nominal = plants.nominal()
    W = weighted_interconnection(nominal)
    K = K0 * np.array([20, 20, 20, 4, 4, 4])  # a stabilizing, non-trivial gain
    M = W.close(K)
    A, B, C, D = M.A, M.B, M.C, M.D
    loop = LoopResponse(nominal, W.spec)

    def loop_gamma(workers, cold=False):
        lp = LoopResponse(nominal, W.spec) if cold else loop
        return peak_gain(A, B, C, D, evaluator=LoopSigma(lp, K), workers=workers).gamma

    rows = []
    with single_threaded_blas():  # the synthesis' BLAS setting, for the baseline too
        ref_wall, ref_cpu, ref = best_of(lambda: ab13dd_all(M), args.repeats)
        cases = [
            ("modal (closed-loop eig + slope secant)", lambda: peak_gain(A, B, C, D).gamma),
            ("loop, warm (synthesis path)", lambda: loop_gamma(1)),
            ("loop, cold (incl. plant modal build)", lambda: loop_gamma(1, cold=True)),
            (f"loop, warm, {args.workers} workers", lambda: loop_gamma(args.workers)),
            (f"loop, cold, {args.workers} workers", lambda: loop_gamma(args.workers, cold=True)),
            (
                "loop, warm + Hamiltonian certificate",
                lambda: peak_gain(A, B, C, D, evaluator=LoopSigma(loop, K), certify=True).gamma,
            ),
        ]
        for label, fn in cases:
            wall, cpu, values = best_of(fn, args.repeats)
            finite = np.isfinite(ref) & np.isfinite(values)
            rel = np.max(np.abs(values[finite] - ref[finite]) / ref[finite])
            rows.append((label, wall, cpu, rel))

    print(
        f"plant={args.plant} models={A.shape[0]} closed-loop states={A.shape[-1]} "
        f"plant states={nominal.nstates}"
    )
    print(f"model array build: {build_wall:.2f} s wall, {build_cpu:.2f} s CPU")
    header = f"{'method':42s} {'wall [s]':>9s} {'CPU [s]':>9s} {'x wall':>7s} {'x CPU':>7s}"
    print(header + f" {'max rel. diff':>14s}")
    print(f"{'ab13dd, one call per model (baseline)':42s} {ref_wall:9.3f} {ref_cpu:9.3f}")
    for label, wall, cpu, rel in rows:
        print(
            f"{label:42s} {wall:9.3f} {cpu:9.3f} {ref_wall / wall:7.2f} {ref_cpu / cpu:7.2f} "
            f"{rel:14.2e}"
        )
    if args.synthesis:
        options = SynthesisOptions(workers=args.workers)
        w, c = time.perf_counter(), time.process_time()
        result = synthesize(plants, K0, options=options)
        wall, cpu = time.perf_counter() - w, time.process_time() - c
        print(
            f"synthesis ({args.workers} workers, {options.restarts} restarts, "
            f"{options.worst_case_rounds} worst-case rounds): gamma {result.gamma_start:.4g} -> "
            f"{result.gamma:.4g}, {len(result.models)} models in the final set, "
            f"{wall:.1f} s wall, {cpu:.1f} s CPU"
        )


if __name__ == "__main__":
    main()
