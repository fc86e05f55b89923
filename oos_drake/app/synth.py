"""``oos synth``: multi-model structured H-infinity synthesis of the attitude controller.

``scenario_plants``, ``mission_times`` (:mod:`oos_drake.control.plants`) and ``baseline_for``
(:mod:`oos_drake.control.baseline`) are imported here for the callers that know them from here.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from oos_drake.app.args import (
    add_loop_arguments,
    add_out_argument,
    add_parallel_arguments,
    add_scenario_argument,
    loop_specification,
)
from oos_drake.control.baseline import baseline_for
from oos_drake.control.components import DesignSpecification
from oos_drake.control.plants import (
    PlantArray,
    mission_times,
    scenario_plants,
    synthetic_flexible_plants,
)
from oos_drake.control.report import write_synthesis
from oos_drake.control.synthesis import SynthesisOptions, synthesize
from oos_drake.processes import check_workers, make_executor

__all__ = ["baseline_for", "drake_plants", "make_plants", "mission_times", "scenario_plants"]


def drake_plants(configurations: int, scenario) -> PlantArray:
    """The same model array from the Drake twin (imports pydrake lazily): nominal
    linearizations, and LFRs extracted per configuration for the worst-case search."""
    try:
        from oos_drake.multibody.synthesis_plants import drake_plant_array
    except ModuleNotFoundError as exc:
        raise ValueError(f"--plant drake needs pydrake ({exc}); use --plant lfr") from exc
    return drake_plant_array(mission_times(configurations, scenario), scenario)


def make_plants(kind: str, configurations: int, scenario) -> PlantArray:
    """Plant array for ``--plant`` (``lfr``, ``drake`` or ``synthetic``) of ``scenario``."""
    if kind == "lfr":
        return scenario_plants(configurations, scenario)
    if kind == "drake":
        return drake_plants(configurations, scenario)
    if kind == "synthetic":
        return synthetic_flexible_plants(configurations)
    raise ValueError(f"--plant must be lfr, drake or synthetic, got {kind!r}")


def run_synth(args) -> int:
    """Run the synthesis and write the outputs; exit status 0."""
    from oos_drake.scenario.data import load_scenario, scenario_record

    check_workers(args.workers)  # before the model array is built
    wall, cpu = time.perf_counter(), time.process_time()
    scenario = load_scenario(args.scenario)
    spec = loop_specification(DesignSpecification.from_requirements(scenario.control), args)
    plants = make_plants(args.plant, args.configurations, scenario)
    print(
        f"model array: {plants.size} configurations from {plants.source!r}, "
        f"{len(plants.parameters)} real parameter(s), built in {time.perf_counter() - wall:.1f} s "
        f"({time.process_time() - cpu:.1f} s CPU)"
    )
    options = SynthesisOptions(
        restarts=args.restarts,
        max_iterations=args.max_iterations,
        worst_case_rounds=args.worst_case_rounds,
        seed=args.seed,
        workers=args.workers,
    )
    K0 = baseline_for(plants, scenario.mission.first_docking_time)
    if scenario.control.has_tuning_goals or scenario.control.structure != "static":
        return _run_tuning(args, scenario, spec, plants, K0)
    # the restarts run as executor tasks; spawned workers when this process holds Drake threads
    method = "spawn" if args.plant == "drake" else None
    with make_executor(args.workers, args.scheduler, method=method) as executor:
        result = synthesize(
            plants, K0, spec=spec, options=options, progress=print, executor=executor
        )
    record = scenario_record(scenario)
    paths = write_synthesis(args.out, result, plants, options, scenario_record=record)
    print(f"scenario: {scenario.name} ({scenario.source})")
    active = result.models[result.models["active"]]
    print(
        f"gamma = {result.gamma:.6g} (baseline {result.gamma_start:.6g}), "
        f"{len(active)} active model(s), {result.wall_time_s:.1f} s"
    )
    if plants.statistics is not None:
        print(f"models: {plants.statistics()}")
    print(f"K_p [N m/rad] =\n{np.array2string(result.K[:, :3], precision=5)}")
    print(f"K_d [N m s/rad] =\n{np.array2string(result.K[:, 3:], precision=5)}")
    for name, path in paths.items():
        print(f"  {name}: {path}")
    return 0


def _run_tuning(args, scenario, spec, plants, K0) -> int:
    """``oos synth`` with the ``[control]`` goals (:func:`tune_to_requirements`); exit status
    0 (``ok``) or 1 (``infeasible``: written, with the best values reached)."""
    from oos_drake.control.report import tuning_record, write_tuning
    from oos_drake.control.requirements import tune_to_requirements, tuning_specification
    from oos_drake.control.systune import SystuneOptions
    from oos_drake.scenario.data import scenario_record

    requirements = scenario.control
    options = SystuneOptions(
        restarts=args.restarts,
        max_iterations=args.max_iterations,
        seed=args.seed,
        workers=args.workers,
    )
    start = time.perf_counter()
    result = tune_to_requirements(plants, K0, spec, requirements, options)
    elapsed = time.perf_counter() - start
    record = tuning_record(
        result, requirements, K0, plants, tuning_specification(spec, requirements), options
    )
    record["wall_time_s"] = elapsed
    paths = write_tuning(args.out, record, scenario_record=scenario_record(scenario))
    print(f"scenario: {scenario.name} ({scenario.source})")
    print(
        f"structure {requirements.structure}: status {result.status}, "
        f"{plants.size} configurations, {elapsed:.1f} s"
    )
    for goal in result.goals:
        details = ", ".join(f"{k} = {v:.4g}" for k, v in goal.details.items())
        print(
            f"  {goal.kind} {goal.name}: {goal.value:.6g} "
            f"({'met' if goal.met else 'NOT met'}; {details})"
        )
    if requirements.structure == "static":
        K = np.asarray(result.parameters["K"]["D"])
        print(f"K_p [N m/rad] =\n{np.array2string(K[:, :3], precision=5)}")
        print(f"K_d [N m s/rad] =\n{np.array2string(K[:, 3:], precision=5)}")
    for name, path in paths.items():
        print(f"  {name}: {path}")
    if result.status != "ok":
        print(
            "INFEASIBLE: the hard goals are NOT all met; controller.json holds the best values "
            "reached with status 'infeasible'"
        )
        return 1
    return 0


def register(subparsers) -> None:
    """Add ``oos synth``."""
    parser = subparsers.add_parser(
        "synth",
        help="structured H-infinity synthesis of the 3x6 attitude gain over the mission",
        description="Multi-model structured H-infinity synthesis (paper section 3): tunes the "
        "static gain K = [K_p, K_d] from the baseline over the configurations and the real "
        "uncertainty, and writes controller.json, closed_loop.npz/.mat and models.parquet/.csv.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    add_out_argument(parser)
    parser.add_argument(
        "--plant",
        default="lfr",
        choices=["lfr", "drake", "synthetic"],
        help="source of the model array: lfr (TITOP LFR substitution), drake (the Drake twin: "
        "nominal linearizations, worst cases substituted into LFRs extracted by ulinearize; "
        "same configurations and real parameters), synthetic (test plants)",
    )
    parser.add_argument(
        "--configurations", type=int, default=200, help="equally spaced mission configurations"
    )
    parser.add_argument("--restarts", type=int, default=2, help="random restarts")
    parser.add_argument(
        "--max-iterations",
        type=int,
        default=150,
        help="optimizer iterations per run (total, metric restarts included)",
    )
    parser.add_argument(
        "--worst-case-rounds",
        type=int,
        default=4,
        help="rounds of worst-case search over the real uncertainty",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of restarts and samples")
    add_scenario_argument(parser)
    add_parallel_arguments(
        parser,
        workers=min(2, os.cpu_count() or 1),
        help="worker processes of the independent optimizer runs (start point and random "
        "restarts), and threads of the per-model eigendecompositions of a single run",
    )
    add_loop_arguments(parser)
    parser.set_defaults(func=run_synth)
