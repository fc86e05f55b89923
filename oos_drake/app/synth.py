"""``oos synth``: multi-model structured H-infinity synthesis of the attitude controller.

The command names the source of the model array (``--plant``); the control package builds the
array (:func:`oos_drake.control.plants.make_plants`), from the Drake twin's LFRs for
``--plant drake`` (:func:`drake_plants`). ``scenario_plants``, ``mission_times``
(:mod:`oos_drake.control.plants`) and ``baseline_for`` (:mod:`oos_drake.control.baseline`) are
imported here for the callers that know them from here.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from oos_drake.app.args import (
    add_loop_arguments,
    add_out_argument,
    add_parallel_arguments,
    add_scenario_argument,
    loop_specification,
)
from oos_drake.control import plants as plant_arrays
from oos_drake.control.baseline import baseline_for
from oos_drake.control.components import DesignSpecification
from oos_drake.control.plants import (
    PLANTS,
    lfr_source_plants,
    mission_times,
    scenario_plants,
)
from oos_drake.control.report import write_synthesis
from oos_drake.control.synthesis import SynthesisOptions, SynthesisResult, synthesize
from oos_drake.control.systune import SystuneOptions
from oos_drake.processes import check_scheduler, check_workers, make_executor

__all__ = [
    "ControllerOptions",
    "ControllerResult",
    "baseline_for",
    "between_plants",
    "compute_controller",
    "controller",
    "controller_options",
    "drake_plants",
    "make_plants",
    "mission_times",
    "pipeline_controller_options",
    "scenario_plants",
    "write_controller_result",
]

#: ``oos synth --workers``' default.
DEFAULT_WORKERS = min(2, os.cpu_count() or 1)


def drake_plants(times, scenario):
    """The model array of the Drake twin at mission ``times`` [s] (imports pydrake lazily): the
    twin's nominal linearizations and, for the worst-case search, the LFRs it extracts per
    configuration (:class:`~oos_drake.multibody.synthesis_plants.DrakePlantSource`), made into
    a plant array by :func:`source_plants`."""
    try:
        from oos_drake.multibody.synthesis_plants import PADDING_POLE, DrakePlantSource
    except ModuleNotFoundError as exc:
        raise ValueError(f"--plant drake needs pydrake ({exc}); use --plant lfr") from exc
    return source_plants(DrakePlantSource(times, scenario), PADDING_POLE)


def source_plants(source, padding_pole: float):
    """The plant array of a Drake plant source (``DrakePlantSource``: its nominal LFRs and,
    lazily, each configuration's uncertain LFR), padded to one order with poles at
    ``padding_pole`` [rad/s] (:func:`~oos_drake.control.plants.lfr_source_plants`)."""
    import pandas as pd

    return lfr_source_plants(
        pd.DataFrame({"time [s]": source.times}),
        source.nominal,
        source.lfr,
        source.parameters,
        padding_pole=padding_pole,
        source="drake",
        statistics=source.statistics,
    )


def make_plants(kind: str, configurations: int, scenario):
    """The model array (a :class:`~oos_drake.control.plants.PlantArray`) for ``--plant``
    (``lfr``, ``drake`` or ``synthetic``) of ``scenario``
    (:func:`~oos_drake.control.plants.make_plants`)."""
    return plant_arrays.make_plants(kind, configurations, scenario, drake=_drake(scenario))


def between_plants(plants, options, scenario):
    """The configurations between those of ``plants`` where the hard goals are checked
    (:func:`~oos_drake.control.plants.between_plants` with ``options.check_density`` and
    ``options.plant``); None with ``check_density`` 1 or a single configuration."""
    return plant_arrays.between_plants(
        plants, options.check_density, options.plant, scenario, drake=_drake(scenario)
    )


def _drake(scenario):
    return lambda times: drake_plants(times, scenario)


@dataclass(frozen=True)
class ControllerOptions:
    """Options of the controller stage (:func:`controller`): what ``oos synth``'s arguments
    hold (:func:`controller_options`) and ``oos run`` passes
    (:func:`pipeline_controller_options`). Checked when made: a bad value is a one-line
    ``ValueError`` naming the option, raised before anything is built or written.

    Attributes
    ----------
    plant : str
        Source of the model array (``--plant``): ``"lfr"``, ``"drake"`` or ``"synthetic"``.
    configurations : int
        Equally spaced mission configurations (``--configurations``), at least 1.
    restarts : int
        Random restarts besides the start point (``--restarts``), at least 0.
    max_iterations : int
        Optimizer iterations per run (``--max-iterations``), at least 0 (0: the baseline).
    worst_case_rounds : int
        Rounds of worst-case search over the real uncertainty (``--worst-case-rounds``),
        at least 0.
    working_set : int
        Configurations in the optimizer's initial working set (``--working-set``), at least 0
        (0: all). Every configuration is checked after each tuning and the violators (of the
        weighted gain, of a hard ``[control]`` goal, unstable) join the set, so the result
        holds on all ``configurations``.
    seed : int
        Seed of the restarts and samples (``--seed``).
    workers : int
        Worker processes of the optimizer runs and threads of a run (``--workers``), at least 1.
    scheduler : str or None
        Where the runs execute (``--scheduler``; None: local processes).
    sampled : bool
        The sampled loop (``--sampled``; False: the continuous loop).
    delay_s : float or None
        Computation delay of the sampled loop [s] (``--delay``; None: the specification's).
    hard_surplus : float
        Relative surplus the tuning keeps on the hard ``[control]`` goals (``--hard-surplus``,
        :attr:`~oos_drake.control.systune.SystuneOptions.hard_surplus`), at least 0.
    check_density : int
        The hard ``[control]`` goals are also checked on ``check_density - 1`` configurations
        evenly spaced between each pair of neighbouring ``configurations``
        (``--check-density``; 1: none), never tuned on; a goal missed there makes the design
        ``infeasible``. At least 1.
    """

    plant: str = "lfr"
    configurations: int = 200
    restarts: int = 2
    max_iterations: int = 150
    worst_case_rounds: int = 4
    working_set: int = 25
    seed: int = 0
    workers: int = DEFAULT_WORKERS
    scheduler: str | None = None
    sampled: bool = False
    delay_s: float | None = None
    hard_surplus: float = SystuneOptions.hard_surplus
    check_density: int = 2

    def __post_init__(self):
        if self.plant not in PLANTS:
            raise ValueError(f"--plant must be lfr, drake or synthetic, got {self.plant!r}")
        for option, value, least in (
            ("--configurations", self.configurations, 1),
            ("--restarts", self.restarts, 0),
            ("--max-iterations", self.max_iterations, 0),
            ("--worst-case-rounds", self.worst_case_rounds, 0),
            ("--working-set", self.working_set, 0),
            ("--hard-surplus", self.hard_surplus, 0),
            ("--check-density", self.check_density, 1),
        ):
            if not value >= least:
                raise ValueError(f"{option} {value}: must be at least {least}")
        check_workers(self.workers)
        check_scheduler(self.scheduler)
        loop_specification(DesignSpecification(), self.loop())  # --delay without --sampled, < 0

    def loop(self) -> argparse.Namespace:
        """The loop model as :func:`~oos_drake.app.args.loop_specification` reads it."""
        return argparse.Namespace(sampled=self.sampled, delay=self.delay_s)


@dataclass(frozen=True)
class ControllerResult:
    """Outcome of the controller stage (:func:`compute_controller`); written by
    :func:`write_controller_result`.

    Attributes
    ----------
    scenario : Scenario
        The scenario the controller is designed on.
    options : ControllerOptions
    plants : oos_drake.control.plants.PlantArray
        The model array designed on.
    K0 : numpy.ndarray, shape (3, 6)
        Baseline (start) gain [N m/rad, N m s/rad].
    spec : DesignSpecification
        The design specification (loop model included).
    solver_options : SynthesisOptions or SystuneOptions
        The optimizer's options (recorded in ``controller.json``).
    result : SynthesisResult or TuningResult
        :func:`~oos_drake.control.synthesis.synthesize`'s (static gain, no ``[control]``
        goals) or :func:`~oos_drake.control.requirements.tune_to_requirements`'s.
    wall_time_s : float
        Wall time of the optimization [s].
    """

    scenario: object
    options: ControllerOptions
    plants: object
    K0: np.ndarray
    spec: DesignSpecification
    solver_options: object
    result: object
    wall_time_s: float

    @property
    def tuned(self) -> bool:
        """True when the ``[control]`` goals were tuned (a ``TuningResult``)."""
        return not isinstance(self.result, SynthesisResult)

    @property
    def status(self) -> str:
        """``"ok"``, or ``"infeasible"`` (tuned: a hard goal NOT met)."""
        return self.result.status if self.tuned else "ok"


def controller_options(args) -> ControllerOptions:
    """The :class:`ControllerOptions` of ``oos synth``'s arguments ``args``."""
    return ControllerOptions(
        plant=args.plant,
        configurations=args.configurations,
        restarts=args.restarts,
        max_iterations=args.max_iterations,
        worst_case_rounds=args.worst_case_rounds,
        working_set=args.working_set,
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
        sampled=args.sampled,
        delay_s=args.delay,
        hard_surplus=args.hard_surplus,
        check_density=args.check_density,
    )


def pipeline_controller_options(
    *, quick: bool, workers: int, scheduler: str | None = None
) -> ControllerOptions:
    """The controller options of ``oos run``: ``oos synth``'s defaults, 40 configurations with
    ``quick`` (what ``oos synth --workers N [--scheduler S] [--configurations 40]`` builds)."""
    configurations = 40 if quick else ControllerOptions.configurations
    return ControllerOptions(
        configurations=configurations, workers=workers, scheduler=scheduler or None
    )


def compute_controller(scenario, options: ControllerOptions) -> ControllerResult:
    """Design the attitude controller of ``scenario``: the multi-model structured H-infinity
    synthesis of the static gain, or the tuning to the scenario's ``[control]`` goals (a
    dynamic structure or tuning goals). Prints the model array and the optimizer's progress;
    writes nothing.

    Parameters
    ----------
    scenario : Scenario
    options : ControllerOptions

    Returns
    -------
    ControllerResult
    """
    wall, cpu = time.perf_counter(), time.process_time()
    spec = loop_specification(
        DesignSpecification.from_requirements(scenario.control), options.loop()
    )
    plants = make_plants(options.plant, options.configurations, scenario)
    print(
        f"model array: {plants.size} configurations from {plants.source!r}, "
        f"{len(plants.parameters)} real parameter(s), built in {time.perf_counter() - wall:.1f} s "
        f"({time.process_time() - cpu:.1f} s CPU)"
    )
    # The optimizer's start point: the baseline PD tuned on the model array's own
    # configuration nearest the first docking (control.baseline.baseline_for), not the
    # controller baseline (scenario_baseline_gains, the one derivation the analysis and the
    # Drake mission use): with --plant drake/synthetic the array is not the scenario's LFR,
    # and on the LFR its nearest grid point is not exactly the docking time. Kept on purpose:
    # starting from scenario_baseline_gains was measured to move the synthesized gamma by
    # 1.9e-4, i.e. `make run` results would change.
    K0 = baseline_for(plants, scenario.mission.first_docking_time)
    if scenario.control.has_tuning_goals or scenario.control.structure != "static":
        from oos_drake.control.requirements import tune_to_requirements, tuning_specification

        solver = SystuneOptions(
            restarts=options.restarts,
            max_iterations=options.max_iterations,
            seed=options.seed,
            workers=options.workers,
            working_set=options.working_set,
            hard_surplus=options.hard_surplus,
        )
        between = between_plants(plants, options, scenario)
        start = time.perf_counter()
        result = tune_to_requirements(
            plants, K0, spec, scenario.control, solver, progress=print, between=between
        )
        elapsed = time.perf_counter() - start
        spec = tuning_specification(spec, scenario.control)
        return ControllerResult(scenario, options, plants, K0, spec, solver, result, elapsed)
    solver = SynthesisOptions(
        restarts=options.restarts,
        max_iterations=options.max_iterations,
        worst_case_rounds=options.worst_case_rounds,
        seed=options.seed,
        workers=options.workers,
        working_set=options.working_set,
    )
    # the restarts run as executor tasks; spawned workers when this process holds Drake threads
    method = "spawn" if options.plant == "drake" else None
    with make_executor(options.workers, options.scheduler, method=method) as executor:
        result = synthesize(
            plants, K0, spec=spec, options=solver, progress=print, executor=executor
        )
    return ControllerResult(scenario, options, plants, K0, spec, solver, result, result.wall_time_s)


def write_controller_result(controller: ControllerResult, out) -> dict[str, Path]:
    """Write the controller stage's files in ``out`` (created): ``controller.json``,
    ``closed_loop.npz``/``.mat`` (the loops ``d -> e``), and for the synthesis
    ``models.parquet``/``.csv``, ``runs.csv``, ``worst_cases.csv``
    (:func:`oos_drake.control.report.write_synthesis`,
    :func:`~oos_drake.control.report.write_tuning`); return name -> path."""
    from oos_drake.control.report import tuning_closed_loop_arrays, tuning_record, write_tuning
    from oos_drake.control.requirements import performance_closed_loops
    from oos_drake.scenario.data import scenario_record

    record = scenario_record(controller.scenario)
    if not controller.tuned:
        return write_synthesis(
            out,
            controller.result,
            controller.plants,
            controller.solver_options,
            scenario_record=record,
        )
    tuned = tuning_record(
        controller.result,
        controller.scenario.control,
        controller.K0,
        controller.plants,
        controller.spec,
        controller.solver_options,
    )
    tuned["wall_time_s"] = controller.wall_time_s
    requirements, plants = controller.scenario.control, controller.plants
    loops = performance_closed_loops(plants, controller.result, controller.spec, requirements)
    arrays = tuning_closed_loop_arrays(controller.result, plants, loops)
    names = [p.name for p in plants.parameters]
    return write_tuning(out, tuned, scenario_record=record, loops=arrays, parameter_names=names)


def controller(scenario, options: ControllerOptions, out) -> ControllerResult:
    """The controller stage: design the controller (:func:`compute_controller`), write it in
    ``out`` (:func:`write_controller_result`), print the result.

    Parameters
    ----------
    scenario : Scenario
    options : ControllerOptions
    out : Path
        The output folder (created).

    Returns
    -------
    ControllerResult
        ``.status`` ``"infeasible"``: written, with the best values reached.
    """
    designed = compute_controller(scenario, options)
    paths = write_controller_result(designed, out)
    print(f"scenario: {scenario.name} ({scenario.source})")
    plants, result = designed.plants, designed.result
    if not designed.tuned:
        active = result.models[result.models["active"]]
        print(
            f"gamma = {result.gamma:.6g} (baseline {result.gamma_start:.6g}), "
            f"{len(active)} active model(s), {result.wall_time_s:.1f} s"
        )
        if plants.statistics is not None:
            print(f"models: {plants.statistics()}")
        _print_gain(result.K)
    else:
        requirements = scenario.control
        print(
            f"structure {requirements.structure}: status {result.status}, goals checked on "
            f"{result.models_checked} configurations (tuned on {len(result.working_set)}) and "
            f"{result.models_verified - result.models_checked} between them, "
            f"{designed.wall_time_s:.1f} s"
        )
        for goal in result.goals:
            details = ", ".join(f"{k} = {v:.4g}" for k, v in goal.details.items())
            print(
                f"  {goal.kind} {goal.name}: {goal.value:.6g} "
                f"({'met' if goal.met else 'NOT met'}; {details})"
            )
        for goal in result.verified:
            details = ", ".join(f"{k} = {v:.4g}" for k, v in goal.details.items())
            print(f"  between: {goal.kind} {goal.name}: {goal.value:.6g} ({details})")
        if requirements.structure == "static":
            _print_gain(np.asarray(result.parameters["K"]["D"]))
    for name, path in paths.items():
        print(f"  {name}: {path}")
    if designed.status != "ok":
        print(
            "INFEASIBLE: the hard goals are NOT all met; controller.json holds the best values "
            "reached with status 'infeasible'"
        )
    return designed


def _print_gain(K) -> None:
    print(f"K_p [N m/rad] =\n{np.array2string(K[:, :3], precision=5)}")
    print(f"K_d [N m s/rad] =\n{np.array2string(K[:, 3:], precision=5)}")


def run_synth(args) -> int:
    """``oos synth``: :func:`controller` with the command line's options; exit status 0, or 1
    when the ``[control]`` goals' tuning is infeasible (written, with the best values
    reached)."""
    from oos_drake.scenario.data import load_scenario

    options = controller_options(args)  # checked before the model array is built
    scenario = load_scenario(args.scenario)
    return 0 if controller(scenario, options, args.out).status == "ok" else 1


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
        choices=list(PLANTS),
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
    parser.add_argument(
        "--working-set",
        type=int,
        default=25,
        help="configurations in the optimizer's initial working set (0: all); every "
        "configuration is checked after each tuning and the violators (weighted gain, hard "
        "[control] goals, stability) join the set, so the result holds on all of them",
    )
    parser.add_argument(
        "--hard-surplus",
        type=float,
        default=SystuneOptions.hard_surplus,
        help="relative surplus the tuning keeps on the hard [control] goals (each tuned to "
        "<= 1/(1 + surplus)) so that they hold between the checked configurations",
    )
    parser.add_argument(
        "--check-density",
        type=int,
        default=2,
        help="the hard [control] goals are also checked on check_density - 1 configurations "
        "between each pair of neighbouring ones (1: none); a goal missed there: infeasible",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of restarts and samples")
    add_scenario_argument(parser)
    add_parallel_arguments(
        parser,
        workers=DEFAULT_WORKERS,
        help="worker processes of the independent optimizer runs (start point and random "
        "restarts), and threads of the per-model eigendecompositions of a single run",
    )
    add_loop_arguments(parser)
    parser.set_defaults(func=run_synth)
