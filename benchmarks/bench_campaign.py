"""Campaign machinery benchmark: simulator speed, parallel efficiency, mu-guided vs Monte Carlo.

Run as a script (short by default; the machine is shared)::

    .venv/bin/python benchmarks/bench_campaign.py              # all three parts
    .venv/bin/python benchmarks/bench_campaign.py --runs 24 --rate 50
    .venv/bin/python benchmarks/bench_campaign.py --write-demo-worst-cases \
        campaigns/demo_worst_cases.parquet

1. Speed of one whole-mission run of the cheap ``flexible-attitude`` simulator (x real time).
2. Parallel efficiency ``T(1 worker) / (2 T(2 workers))`` of the local process pool, both pools
   warm (workers started and simulators built before timing), same cases, interleaved repeats
   (best of each) in the same run; the in-process executor is the baseline row.
3. ``mu-guided`` against ``monte-carlo`` with the same number of runs on ``campaigns/demo.toml``:
   worst APE found, requirement violations, and the two estimates of P(APE violation).

The worst cases used in part 3 stand in for the robust analysis' file: a vertex search of the
cheap simulator (noise-free runs at the corners of the dispersion box, normal laws at +-3 std:
the box a mu analysis covers), whose three worst corners (differing in at least three blocks)
become regions with ``mu_upper`` := worst APE / requirement.
"""

from __future__ import annotations

import argparse
import itertools
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.campaign.distributions import Fixed, TruncatedNormal
from oos_drake.campaign.executors import InlineExecutor, ProcessPoolExecutor
from oos_drake.campaign.runner import case_from_plan_row, run_campaign
from oos_drake.campaign.samplers import make_plan
from oos_drake.campaign.simulator import (
    MissionWindow,
    RunCase,
    SimulationDiverged,
    SimulatorRecipe,
    build_simulator,
)
from oos_drake.campaign.spec import load_spec
from oos_drake.campaign.worst_cases import WorstCaseRegion, write_worst_cases

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "campaigns" / "demo.toml"


def simulator_speed(rate: float) -> float:
    """Real-time factor of one whole-mission run (mission seconds per wall second)."""
    recipe = SimulatorRecipe.create("flexible-attitude", {"control_rate": rate})
    sim = build_simulator(recipe)
    values = {p.name: p.nominal for p in sim.parameters()}
    window = MissionWindow(0.0, sim.duration())
    sim.run(RunCase(0, 0, values, window))  # warm-up
    start = time.perf_counter()
    repeats = 3
    for seed in range(repeats):
        sim.run(RunCase(0, seed, values, window))
    elapsed = (time.perf_counter() - start) / repeats
    print(
        f"one {sim.duration():.0f} s mission at {rate:g} Hz: {elapsed * 1e3:.1f} ms "
        f"({sim.duration() / elapsed:.0f}x real time)"
    )
    return sim.duration() / elapsed


def parallel_efficiency(n_runs: int, rate: float, repeats: int = 3) -> float:
    """Time the same cases on 1 and 2 warm pool workers; print the table; return efficiency."""
    spec = load_spec(DEMO)
    # log at 10 Hz whatever the control rate: the driver process shares the 2 cores
    options = {"control_rate": rate, "log_every": max(1, int(round(rate / 10)))}
    recipe = SimulatorRecipe.create("flexible-attitude", options)
    plan = make_plan(spec).head(n_runs).copy()
    plan["window_start [s]"], plan["window_end [s]"] = 0.0, 300.0  # whole mission
    cases = [case_from_plan_row(spec, row) for _, row in plan.iterrows()]
    executors = {
        "in-process": InlineExecutor(),
        "pool, 1 worker": ProcessPoolExecutor(1),
        "pool, 2 workers": ProcessPoolExecutor(2),
    }
    for executor in executors.values():
        executor.start(recipe)
    # interleaved repeats, best of each: the machine is shared, so load comes and goes
    timings = {label: np.inf for label in executors}
    for _ in range(repeats):
        for label, executor in executors.items():
            start = time.perf_counter()
            results = list(executor.run(recipe, cases))
            timings[label] = min(timings[label], time.perf_counter() - start)
            assert len(results) == n_runs
    for executor in executors.values():
        executor.close()
    rows = [
        {"executor": label, "runs": n_runs, "best wall [s]": t, "runs/s": n_runs / t}
        for label, t in timings.items()
    ]
    efficiency = timings["pool, 1 worker"] / (2 * timings["pool, 2 workers"])
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.3f}".format))
    print(
        f"parallel efficiency 2 workers vs 1: {100 * efficiency:.0f}% "
        f"(speed-up {timings['pool, 1 worker'] / timings['pool, 2 workers']:.2f}x, "
        f"best of {repeats} interleaved repeats; load average now "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )
    return efficiency


def vertex_worst_cases(n_regions: int = 3) -> tuple[WorstCaseRegion, ...]:
    """Stand-in worst cases: the worst corners of the demo dispersion box (noise-free runs)."""
    spec = load_spec(DEMO)
    recipe = SimulatorRecipe.create(
        spec.simulator.name,
        {**spec.simulator.option_dict, "star_tracker_noise": 0.0, "gyro_noise": 0.0},
    )
    sim = build_simulator(recipe)
    nominal = {p.name: p.nominal for p in sim.parameters()}
    corners = {}
    for name, dist in spec.dispersions.items():
        if isinstance(dist, Fixed) or dist.kind == "choice":
            continue
        if isinstance(dist, TruncatedNormal):
            low = max(dist.low, dist.mean - 3 * dist.std)
            high = min(dist.high, dist.mean + 3 * dist.std)
        else:
            low, high = dist.support
        corners[name] = (low, high)
    window = spec.window.resolve(spec.info)
    limit = next(r.max for r in spec.requirements if r.metric == "ape")
    scored = []
    for combination in itertools.product(*corners.values()):
        values = {**nominal, **dict(zip(corners, combination, strict=True))}
        try:
            ape = sim.run(RunCase(0, 0, values, window)).metrics["ape"]
        except SimulationDiverged:
            ape = np.inf
        scored.append((ape, dict(zip(corners, combination, strict=True))))
    scored.sort(key=lambda item: -item[0])
    chosen: list[tuple[float, dict]] = []
    for ape, perturbation in scored:  # worst first, corners differing in >= 3 blocks
        if all(sum(perturbation[k] != other[k] for k in perturbation) >= 3 for _, other in chosen):
            chosen.append((ape, perturbation))
        if len(chosen) == n_regions:
            break
    regions = []
    for index, (ape, perturbation) in enumerate(chosen):
        ratio = float(min(ape / limit, 1e3))
        regions.append(
            WorstCaseRegion(
                index,
                "capture",
                spec.info.events["capture"],
                float(perturbation.get("f_array", np.nan)),
                ratio,
                ratio,
                ",".join(perturbation),
                perturbation,
            )
        )
    return tuple(regions)


def guided_vs_monte_carlo(n_runs: int, worst_cases: Path) -> None:
    """Same number of runs with both samplers; print the worst APE and violations found."""
    text = DEMO.read_text().replace("n_runs = 200", f"n_runs = {n_runs}")
    text = text.replace('keep = "all"', 'keep = "none"')
    mu_text = text.replace(
        'sampler = "latin-hypercube"',
        f'sampler = {{ kind = "mu-guided", worst_cases = "{worst_cases}", '
        "defensive_fraction = 0.3, spread = 0.05 }",
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, spec_text in (
            ("monte-carlo", text.replace('"latin-hypercube"', '"monte-carlo"')),
            ("mu-guided", mu_text),
        ):
            path = Path(tmp) / f"{label}.toml"
            path.write_text(spec_text)
            start = time.perf_counter()
            run_campaign(path, Path(tmp) / label, workers=2, progress=False)
            elapsed = time.perf_counter() - start
            runs = pd.read_parquet(Path(tmp) / label / "runs.parquet")
            violated = ~runs["pass_ape"]
            w = runs["weight"].to_numpy()
            estimate = float(np.mean(w * violated))
            se = float(np.std(w * violated, ddof=1) / np.sqrt(len(runs)))
            rows.append(
                {
                    "sampler": label,
                    "runs": len(runs),
                    "worst APE [rad]": runs["ape [rad]"].max(),
                    "APE violations": int(violated.sum()),
                    "P(APE > 0.0079 rad)": estimate,
                    "se": se,
                    "wall [s]": elapsed,
                }
            )
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=16, help="runs for the efficiency test")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved timing repeats")
    parser.add_argument("--rate", type=float, default=50.0, help="control rate [Hz] (run cost)")
    parser.add_argument(
        "--compare-runs",
        type=int,
        default=100,
        help="runs per sampler for mu-guided vs Monte Carlo",
    )
    parser.add_argument(
        "--write-demo-worst-cases",
        type=Path,
        default=None,
        help="write the stand-in worst cases to this path and exit",
    )
    args = parser.parse_args()
    if args.write_demo_worst_cases:
        regions = vertex_worst_cases()
        spec = load_spec(DEMO)
        write_worst_cases(regions, spec.info.parameters, args.write_demo_worst_cases)
        print(pd.read_parquet(args.write_demo_worst_cases).to_string(index=False))
        return
    print("== 1. simulator speed")
    simulator_speed(10.0)
    simulator_speed(args.rate)
    print("\n== 2. parallel efficiency (local process pool, warm workers)")
    parallel_efficiency(args.runs, args.rate, args.repeats)
    print("\n== 3. mu-guided vs Monte Carlo, same number of runs (campaigns/demo.toml)")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "worst_cases.parquet"
        write_worst_cases(vertex_worst_cases(), load_spec(DEMO).info.parameters, path)
        guided_vs_monte_carlo(args.compare_runs, path)


if __name__ == "__main__":
    main()
