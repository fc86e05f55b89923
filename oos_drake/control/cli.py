"""``oos synth``: multi-model structured H-infinity synthesis of the attitude controller."""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pandas as pd

from oos_drake.cli import add_loop_arguments, loop_specification
from oos_drake.control.baseline import TUNING_TIME_S, baseline_gains, inertia_from_plant
from oos_drake.control.components import DesignSpecification
from oos_drake.control.plants import PlantArray, from_lfr, synthetic_flexible_plants
from oos_drake.control.report import write_synthesis
from oos_drake.control.synthesis import SynthesisOptions, synthesize

MISSION_DURATION_S = 1500.0


def scenario_plants(configurations: int) -> PlantArray:
    """The paper's model array: the scenario LFR substituted at equally spaced mission times."""
    try:
        from oos_drake.scenario.model import build_mission_model, mission_values
    except ModuleNotFoundError as exc:
        raise ValueError(
            "--plant lfr needs the scenario model (oos_drake.scenario.model), which is not "
            "available; use --plant synthetic"
        ) from exc
    times = mission_times(configurations)
    model = build_mission_model()
    return from_lfr(model, mission_values(times), pd.DataFrame({"time_s": times}), source="lfr")


def mission_times(configurations: int) -> np.ndarray:
    """The synthesis configurations: ``configurations`` equally spaced mission times [s]."""
    if configurations < 1:
        raise ValueError(f"--configurations must be >= 1, got {configurations}")
    return np.linspace(0.0, MISSION_DURATION_S, configurations)


def drake_plants(configurations: int) -> PlantArray:
    """The same model array from the Drake twin (imports pydrake lazily): nominal
    linearizations, and LFRs extracted per configuration for the worst-case search."""
    try:
        from oos_drake.multibody.synthesis_plants import drake_plant_array
    except ModuleNotFoundError as exc:
        raise ValueError(f"--plant drake needs pydrake ({exc}); use --plant lfr") from exc
    return drake_plant_array(mission_times(configurations))


def make_plants(kind: str, configurations: int) -> PlantArray:
    """Plant array for ``--plant`` (``lfr``, ``drake`` or ``synthetic``)."""
    if kind == "lfr":
        return scenario_plants(configurations)
    if kind == "drake":
        return drake_plants(configurations)
    if kind == "synthetic":
        return synthetic_flexible_plants(configurations)
    raise ValueError(f"--plant must be lfr, drake or synthetic, got {kind!r}")


def baseline_for(plants: PlantArray) -> np.ndarray:
    """Baseline gain tuned on the configuration closest to the first docking (t = 255 s)."""
    table = plants.configurations
    if "time_s" in table:
        k = int(np.argmin(np.abs(table["time_s"].to_numpy() - TUNING_TIME_S)))
    else:
        k = 0
    J = inertia_from_plant(plants.evaluate([k]))[0]
    return baseline_gains(J)


def run_synth(args) -> int:
    """Run the synthesis and write the outputs; exit status 0."""
    wall, cpu = time.perf_counter(), time.process_time()
    plants = make_plants(args.plant, args.configurations)
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
    K0 = baseline_for(plants)
    spec = loop_specification(DesignSpecification(), args)
    result = synthesize(plants, K0, spec=spec, options=options, progress=print)
    paths = write_synthesis(args.out, result, plants, options)
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
    parser.add_argument("--out", required=True, help="output directory")
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
    parser.add_argument(
        "--workers",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help="threads for the per-model eigendecompositions",
    )
    add_loop_arguments(parser)
    parser.set_defaults(func=run_synth)
