"""Benchmark: systune vs today's static-gain synthesis on the same problem; the bundle QP solvers.

Run ``python benchmarks/bench_systune.py [--configurations 2] [--modes 1] [--iterations 300]``,
or ``python benchmarks/bench_systune.py --scenario [--configurations 200] [--margins]
[--iterations 150] [--restarts 2] [--workers 2]``.

``--scenario``: ``oos synth``'s two designs of the paper's scenario, each run twice in the same
process. The default synthesis (:func:`~oos_drake.control.synthesis.synthesize`, ``oos
synth``'s options, ``--workers`` processes; CPU time includes the workers') with the bundle QP
solvers ``qp="slsqp"`` (the default, SciPy's SLSQP) and ``qp="active-set"`` (exact). With
``--margins`` the margins design (:func:`~oos_drake.control.requirements.tune_to_requirements`:
soft weighted gain, hard >= 6 dB and >= 30 deg at the wheel input on the 10 Hz sampled loop;
``--margins-only``: without the static-gain rows), first as in the earlier sessions (each goal
decomposes its own closed loop and inverts its own bilinear image, ``shared_modes=False``, one
thread: the baseline), then with one shared decomposition and inverse per evaluation in
``--workers`` threads (the default; a discrete loop's bilinear image keeps its eigenvectors).
Both rows use the one closed-loop solve per active peak of session 15 (the earlier code solved
twice), so the ratio understates the gain over the earlier code. Prints wall and CPU times,
the ratio of the second row to the first and gamma of each with their difference (wall times
mean little on a loaded machine: compare CPU).

Default mode:

Both tune the static 3x6 gain ``[K_p K_d]`` of the paper's weighted interconnection
(:mod:`oos_drake.control.interconnection`) around synthetic flexible plants at nominal
parameters, from the baseline gain, one start, no worst-case search, every configuration in
the model set: :func:`oos_drake.control.synthesis.synthesize` (the modal fast path of
:mod:`~oos_drake.control.loop_response`) and :func:`oos_drake.control.systune.systune` with a
:class:`~oos_drake.control.tunable.TunableGain` and one soft
:class:`~oos_drake.control.goals.WeightedGain` from the disturbances to the errors (generic
LU solves, no modal fast path). The table gives wall and CPU time, the ratio, gamma of each
(certified norms, all models) and their relative difference.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from oos_drake.blas import single_threaded_blas
from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.goals import WeightedGain
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    weighted_interconnection,
)
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.control.synthesis import SynthesisOptions, synthesize
from oos_drake.control.systune import SystuneOptions, systune
from oos_drake.control.tunable import TunableGain


def _cpu() -> float:
    """CPU time of this process and of its finished child processes (executor workers) [s]."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def _timed(function):
    wall, cpu = time.perf_counter(), _cpu()
    out = function()
    return out, time.perf_counter() - wall, _cpu() - cpu


def scenario(args) -> None:
    """``--scenario``: baseline (SLSQP) and active-set QP on ``oos synth``'s designs."""
    import dataclasses

    from oos_drake.control.baseline import baseline_for
    from oos_drake.control.components import DesignSpecification
    from oos_drake.control.plants import scenario_plants
    from oos_drake.control.requirements import tune_to_requirements
    from oos_drake.processes import make_executor
    from oos_drake.scenario.data import load_scenario

    paper = load_scenario("paper")
    plants = scenario_plants(args.configurations, paper)
    K0 = baseline_for(plants, paper.mission.first_docking_time)
    spec = DesignSpecification.from_requirements(paper.control)
    rows = []
    for qp in () if args.margins_only else ("slsqp", "active-set"):
        options = SynthesisOptions(
            workers=args.workers, qp=qp, restarts=args.restarts, max_iterations=args.iterations
        )

        def run(options=options):
            with make_executor(args.workers) as executor:
                return synthesize(plants, K0, spec=spec, options=options, executor=executor)

        result, wall, cpu = _timed(run)
        rows.append(("static gain", qp, wall, cpu, result.gamma, ""))
    if args.margins:
        requirements = dataclasses.replace(
            paper.control, rate_hz=10.0, gain_margin_db=6.0, phase_margin_deg=30.0
        )
        for baseline in (True, False):
            qp = "baseline" if baseline else "shared"
            options = SystuneOptions(
                restarts=args.restarts,
                max_iterations=args.iterations,
                shared_modes=not baseline,
                workers=1 if baseline else args.workers,
            )
            with single_threaded_blas():
                result, wall, cpu = _timed(
                    lambda options=options: tune_to_requirements(
                        plants, K0, spec, requirements, options
                    )
                )
            margins = result.goals[1].details
            rows.append(
                (
                    "margins hard",
                    qp,
                    wall,
                    cpu,
                    result.soft,
                    f"{result.status}, GM {margins['gain_margin_db']:.3f} dB, "
                    f"PM {margins['phase_margin_deg']:.3f} deg",
                )
            )
    print(f"{plants.size} configurations of the paper's scenario, {args.workers} worker(s)")
    print(f"{'design':14s} {'path':11s} {'wall [s]':>9s} {'cpu [s]':>9s} {'gamma':>12s}")
    for design, qp, wall, cpu, gamma, note in rows:
        print(f"{design:14s} {qp:11s} {wall:9.1f} {cpu:9.1f} {gamma:12.8f} {note}")
    for base, new in zip(rows[::2], rows[1::2], strict=True):
        difference = new[4] - base[4]
        print(
            f"{base[0]}: {new[1]} / {base[1]} wall {new[2] / base[2]:.2f}, "
            f"cpu {new[3] / base[3]:.2f}; gamma difference {difference:+.2e} "
            f"(relative {difference / base[4]:+.2e})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=None)
    parser.add_argument("--modes", type=int, default=1)
    parser.add_argument("--iterations", type=int, default=None, help="300 (--scenario: 150)")
    parser.add_argument("--restarts", type=int, default=2, help="with --scenario")
    parser.add_argument("--scenario", action="store_true", help="oos synth's designs, QP solvers")
    parser.add_argument("--margins", action="store_true", help="with --scenario: margins design")
    parser.add_argument("--workers", type=int, default=2, help="with --scenario: processes")
    parser.add_argument(
        "--margins-only", action="store_true", help="with --margins: skip the static-gain rows"
    )
    args = parser.parse_args()
    if args.scenario:
        args.configurations = args.configurations or 200
        args.iterations = args.iterations or 150
        scenario(args)
        return
    args.configurations = args.configurations or 2
    args.iterations = args.iterations or 300
    plants = synthetic_flexible_plants(args.configurations, modes=args.modes, uncertain=False)
    K0 = baseline_gains(inertia_from_plant(plants.evaluate([1]))[0])
    N, P = plants.size, len(plants.parameters)
    nominal = np.broadcast_to(plants.nominal_values, (N, P))
    system = weighted_interconnection(plants.evaluate(np.arange(N), nominal)).system
    with single_threaded_blas():
        synthesis, synthesis_wall, synthesis_cpu = _timed(
            lambda: synthesize(
                plants,
                K0,
                options=SynthesisOptions(
                    restarts=0,
                    max_iterations=args.iterations,
                    worst_case_rounds=0,
                    working_set=0,
                ),
            )
        )
        tuned, tuned_wall, tuned_cpu = _timed(
            lambda: systune(
                system,
                TunableGain("K", MEASUREMENTS, CONTROLS, initial=K0),
                [WeightedGain(DISTURBANCES, ERRORS)],
                options=SystuneOptions(max_iterations=args.iterations),
            )
        )
    print(
        f"{N} configurations, {args.modes} flexible mode(s), {args.iterations} iterations, "
        f"start gamma {synthesis.gamma_start:.6g}"
    )
    print(f"{'method':12s} {'wall [s]':>9s} {'cpu [s]':>9s} {'gamma':>12s}")
    print(f"{'synthesize':12s} {synthesis_wall:9.2f} {synthesis_cpu:9.2f} {synthesis.gamma:12.8f}")
    print(f"{'systune':12s} {tuned_wall:9.2f} {tuned_cpu:9.2f} {tuned.soft:12.8f}")
    print(
        f"systune / synthesize: wall {tuned_wall / synthesis_wall:.2f}, "
        f"cpu {tuned_cpu / synthesis_cpu:.2f}; gamma relative difference "
        f"{(tuned.soft - synthesis.gamma) / synthesis.gamma:+.2e}"
    )


if __name__ == "__main__":
    main()
