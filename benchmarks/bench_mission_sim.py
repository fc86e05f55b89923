"""Drake mission simulation benchmark: speed, where the time goes, integrators, parallel pools.

Run as a script (the machine is shared: the default is short)::

    .venv/bin/python benchmarks/bench_mission_sim.py                 # parts 1, 3, 4
    .venv/bin/python benchmarks/bench_mission_sim.py --profile       # + part 2
    .venv/bin/python benchmarks/bench_mission_sim.py --skip-full --runs 6

1. One whole 1500 s mission with all 24 flexible modes, the arm, the captured and docked target,
   the 10 Hz flight software: wall time and processor time of this process, as multiples of
   real time and as **processor seconds per simulated second** (the figure that other jobs on a
   shared machine inflate least), with the integrator's work (steps, derivative evaluations,
   Newton-Raphson iterations). One OpenBLAS thread, as in a campaign worker.
2. ``--profile``: where the processor time of that run goes. The cost of one time-derivative
   evaluation of the diagram (the MultibodyPlant's articulated-body algorithm with the joint
   PDs and bushings) and of one flight-software update (the Python ``LeafSystem``) are measured
   in isolation and multiplied by the counts of the run; the remainder is the integrator's own
   work (Newton solves, factorizations) and the simulator's event handling. A cProfile of a
   window lists the Python functions.
3. Integrator choice on the same 2 s window before the capture: Radau3 (the default: fixed steps
   of one control period, Newton tolerance 1e-7) against the explicit Runge-Kutta 3 with error
   control (baseline measured in the same run); the explicit integrator is limited by the stiff
   joint PDs and bushings. ``--accuracy-study`` adds the attitude error of Radau3 settings
   against a converged reference on three windows (arm motion, capture, second docking).
   ``--window-start-study`` compares windows that start with the hub at rest with the mission
   run from t = 0. ``--pointing-by-phase`` runs the nominal mission from t = 0 against the
   APE requirement, phase by phase (largest logged attitude error, logged samples above it).
   ``--candidates`` runs whole missions with cheaper settings against today's options in the
   same process (speed-up, APE, largest attitude difference against the requirement).

   Why the default stays (issue 32, measured on the shared 2-core machine, load ~7): of one
   derivative evaluation (56 us), the MultibodyPlant alone takes 52 us; the trajectory
   sources, joint-PD gains and adder the rest (at most 8 % to gain there). pydrake exposes no
   Newton, Jacobian or error-estimate setting of the implicit integrators, and Radau3 runs its
   implicit-trapezoid error estimate (3 Newton iterations a step) also in fixed-step mode.
   Whole mission (``--candidates``): a Newton tolerance of 1e-6 is 1.11x faster but moves the
   attitude by 2.5e-4 rad (3 % of the requirement; the accuracy study: 9x today's error while
   the arm moves); ``radau1`` (implicit Euler, first order) is 1.69x faster, 1.1e-4 rad
   (1.4 %) from today's run, but 10-15x today's error against the reference (0.76 % of the
   peak while the arm moves, the accuracy test allows 0.2 %) and it damps the arrays' first
   modes numerically (damping ratio ~0.19 at 0.65 Hz, ~0.31 at 1.29 Hz with 0.1 s steps,
   against 0.001 and 0.007 for Radau3). Drake's ``cenic`` integrator needs a SceneGraph;
   with one its convex solver fails to factorize at the first step.

4. Parallel efficiency of the campaign's process pool with this simulator, 2 workers against 1,
   on wall time and on processor time (``bench_campaign.parallel_efficiency``).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import sys
import time

import numpy as np
import pandas as pd

from oos_drake.blas import limit_blas_threads
from oos_drake.multibody.mission import MissionOptions, make_mission_diagram
from oos_drake.multibody.mission_sim import MissionSimulation
from oos_drake.scenario.data import load_scenario


def _simulation(options: MissionOptions) -> MissionSimulation:
    """The paper's mission with ``options``."""
    return MissionSimulation(make_mission_diagram(options, scenario=load_scenario("paper")))


# bench_campaign (part 4) is a sibling script; its pool workers import it by name
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def _row(case: str, duration: float, result) -> dict:
    s = result.statistics
    return {
        "case": case,
        "sim [s]": duration,
        "wall [s]": result.wall_time,
        "cpu [s]": result.cpu_time,
        "cpu/sim [ms/s]": 1e3 * result.cpu_time / duration,
        "x RT (wall)": duration / result.wall_time,
        "x RT (cpu)": duration / result.cpu_time,
        "steps": result.steps,
        "f evals": int(s.get("integrator_num_derivative_evaluations", 0)),
        "NR iters": int(s.get("integrator_num_newton_raphson_iterations", 0)),
        "APE [rad]": result.metrics["ape"],
    }


def full_mission(simulation: MissionSimulation) -> tuple[dict, object]:
    """Time one whole mission; return the table row and the result."""
    result = simulation.run({}, seed=1)
    case = "full mission 0-1500 s, radau3 fixed 0.1 s steps, 10 Hz FSW"
    return _row(case, simulation.duration, result), result


def derivative_cost(simulation: MissionSimulation, n: int = 2000) -> float:
    """Processor time of one time-derivative evaluation of the mission diagram [s].

    At a mid-mission state (arm holding the target), cycling through 50 perturbed states so
    that every evaluation recomputes the plant's kinematics and articulated-body caches.
    """
    context, _, _ = simulation.initial_context({}, 1, 300.0, 310.0)
    diagram = simulation.handles.diagram
    derivatives = diagram.AllocateTimeDerivatives()
    x0 = context.get_continuous_state_vector().CopyToVector()
    rng = np.random.default_rng(0)
    states = [x0 + 1e-4 * rng.standard_normal(x0.size) for _ in range(50)]
    best = np.inf
    for _ in range(3):
        start = time.process_time()
        for i in range(n):
            context.SetContinuousState(states[i % 50])
            diagram.CalcTimeDerivatives(context, derivatives)
        best = min(best, (time.process_time() - start) / n)
    return best


def update_cost(simulation: MissionSimulation, n: int = 3000) -> float:
    """Processor time of one flight-software update (the Python discrete update) [s]."""
    context, _, _ = simulation.initial_context({}, 1, 300.0, 310.0)
    diagram = simulation.handles.diagram
    best = np.inf
    for _ in range(3):
        start = time.process_time()
        for i in range(n):
            context.SetTime(300.0 + 1e-6 * i)  # invalidates the cached update
            diagram.EvalUniquePeriodicDiscreteUpdate(context)
        best = min(best, (time.process_time() - start) / n)
    return best


def profile(simulation: MissionSimulation, result) -> None:
    """Print where the processor time of the whole-mission run goes (part 2)."""
    s = result.statistics
    evals = s["integrator_num_derivative_evaluations"]
    samples = simulation.duration * simulation.options.control_rate
    f_cost, u_cost = derivative_cost(simulation), update_cost(simulation)
    rows = [
        {
            "part": "plant + joint PDs: time derivatives (C++)",
            "count": int(evals),
            "each [us]": 1e6 * f_cost,
            "cpu [s]": evals * f_cost,
        },
        {
            "part": "flight software update (Python LeafSystem)",
            "count": int(samples),
            "each [us]": 1e6 * u_cost,
            "cpu [s]": samples * u_cost,
        },
    ]
    rest = result.cpu_time - sum(r["cpu [s]"] for r in rows)
    rows.append(
        {
            "part": "integrator linear algebra, events, logging (rest)",
            "count": int(result.steps),
            "each [us]": 1e6 * rest / result.steps,
            "cpu [s]": rest,
        }
    )
    table = pd.DataFrame(rows)
    table["share"] = table["cpu [s]"] / result.cpu_time
    print(f"\nwhere the {result.cpu_time:.1f} s of processor time of the whole mission go")
    print(table.to_string(index=False, float_format="{:.3g}".format))
    newton = s["integrator_num_newton_raphson_iterations"] / result.steps
    newton_error = s["integrator_num_error_estimator_newton_raphson_iterations"] / result.steps
    print(
        "integrator work per step: "
        f"{evals / result.steps:.1f} derivative evaluations, {newton:.1f} Newton-Raphson "
        f"iterations ({newton_error:.1f} of them for the error estimate); "
        f"{int(s['integrator_num_jacobian_evaluations'])} "
        f"Jacobians and {int(s['integrator_num_iteration_matrix_factorizations'])} "
        "factorizations in the whole run"
    )
    profiler = cProfile.Profile()
    profiler.enable()
    simulation.run({}, seed=1, start=250.0, end=350.0)
    profiler.disable()
    stream = io.StringIO()
    pstats.Stats(profiler, stream=stream).sort_stats("tottime").print_stats(8)
    print("cProfile of the window 250-350 s (Python view; AdvanceTo is the C++ simulator):")
    print("\n".join(stream.getvalue().splitlines()[4:]))


def integrators(start: float = 100.0, end: float = 102.0) -> list[dict]:
    """Radau3 against RK3 on the same window."""
    rows = []
    for name in ("radau3", "runge_kutta3"):
        simulation = _simulation(MissionOptions(integrator=name))
        result = simulation.run({}, seed=1, start=start, end=end, log=False)
        mode = "fixed steps" if simulation.options.fixed_step else "error control"
        rows.append(_row(f"window {start:g}-{end:g} s, {name}, {mode}", end - start, result))
    return rows


def accuracy_study(windows=((400.0, 440.0), (250.0, 275.0), (870.0, 900.0))) -> None:
    """Attitude error of integrator settings against a converged reference.

    Windows: the arm moving the captured target (400-440 s), the SM1 stiffness ramp of the
    capture (250-275 s) and the second docking (870-900 s, SM2 up then SM1 down). Reference:
    fixed Radau3 steps of 12.5 ms (1.6 ms in the ramps), Newton tolerance 1e-9 (it agrees with
    error-controlled Radau3 at 1e-8 on the arm-motion window, and with 25 ms steps to 0.05 %).
    """
    settings = (
        ("default: fixed 0.1 s, 1e-7, ramps 4 substeps", {}),
        ("fixed 0.1 s, 1e-6", {"accuracy": 1e-6}),
        ("fixed 0.1 s, 1e-7, ramps 16 substeps", {"ramp_substeps": 16}),
        ("fixed 0.1 s, 1e-7, no ramp substeps", {"ramp_substeps": 1}),
        ("session 1: error control 1e-5", {"error_control": True, "accuracy": 1e-5}),
        ("fixed 0.1 s, 3e-7", {"accuracy": 3e-7}),
        ("radau1 (first order) fixed 0.1 s, 1e-7", {"integrator": "radau1"}),
    )
    rows = []
    for start, end in windows:

        def attitude(start=start, end=end, **options):
            simulation = _simulation(MissionOptions(log_rate=10.0, **options))
            result = simulation.run({}, seed=1, start=start, end=end)
            phi = result.timeseries[[f"phi_{a} [rad]" for a in "xyz"]].to_numpy()
            return result, phi

        reference, phi_ref = attitude(max_step=0.0125, accuracy=1e-9, ramp_substeps=64)
        peak = np.abs(phi_ref).max()
        for label, options in settings:
            result, phi = attitude(**options)
            error = np.abs(phi - phi_ref).max()
            rows.append(
                {
                    "window [s]": f"{start:g}-{end:g}",
                    "setting": label,
                    "max |phi - phi_ref| [rad]": error,
                    "relative to peak": error / peak,
                    "APE error": abs(result.metrics["ape"] / reference.metrics["ape"] - 1),
                    "cpu/sim [ms/s]": 1e3 * result.cpu_time / (end - start),
                    "steps": result.steps,
                }
            )
    table = pd.DataFrame(rows)
    # speed against today's settings (the default row of the same window, same run)
    default = table.groupby("window [s]")["cpu/sim [ms/s]"].transform("first")
    table["speed vs default"] = default / table["cpu/sim [ms/s]"]
    print("integrator settings against a converged reference (10 Hz logging)")
    print(table.to_string(index=False, float_format="{:.3g}".format))


CANDIDATES = (("accuracy 1e-6", {"accuracy": 1e-6}), ("radau1", {"integrator": "radau1"}))


def candidates(settings=CANDIDATES):
    """Whole missions with cheaper integrator settings against today's options, same run.

    Prints, per setting, the processor time and its speed-up over today's options (the baseline,
    measured first in the same process), the integrator's work, the APE of the nominal mission
    and the largest attitude difference from today's run (1 Hz log) relative to the APE
    requirement. The error against a converged reference is the accuracy study's
    (``--accuracy-study``): a setting is a candidate default only if both stay small.
    """
    requirement = load_scenario("paper").control.pointing_requirement
    columns = [f"phi_{a} [rad]" for a in "xyz"]
    rows, baseline = [], None
    for label, options in (("today's options", {}), *settings):
        simulation = _simulation(MissionOptions(**options))
        result = simulation.run({}, seed=1)
        phi = result.timeseries[columns].to_numpy()
        baseline = (result, phi) if baseline is None else baseline
        s = result.statistics
        difference = np.abs(phi - baseline[1]).max()
        rows.append(
            {
                "setting": label,
                "cpu [s]": result.cpu_time,
                "x RT (cpu)": simulation.duration / result.cpu_time,
                "speed vs today": baseline[0].cpu_time / result.cpu_time,
                "f evals/step": s["integrator_num_derivative_evaluations"] / result.steps,
                "NR iters/step": s["integrator_num_newton_raphson_iterations"] / result.steps,
                "APE [rad]": result.metrics["ape"],
                "max |phi - phi_today| [rad]": difference,
                "/ requirement": difference / requirement,
            }
        )
    print(
        "\nwhole nominal mission, candidate settings against today's "
        f"(APE requirement {requirement} rad)"
    )
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))


def window_start_study(events=(("capture", 255.0), ("pull-in", 600.0)), leads=(20.0, 60.0)):
    """Windows starting at rest against the whole mission from t = 0 (nominal, no noise).

    Prints, per event and lead time, the APE over ``[t, t + 60]`` s from both runs, the largest
    attitude difference and the hub rate the whole-mission run has at the window start.
    """
    simulation = _simulation(MissionOptions())
    axes = "xyz"

    def run(start: float, end: float) -> pd.DataFrame:
        n = int((end - start) * simulation.options.control_rate) + 2
        result = simulation.run({}, seed=1, start=start, end=end, noise_table=np.zeros((n, 9)))
        return result.timeseries.set_index("time [s]")

    rows = []
    for event, t0 in events:
        full = run(0.0, t0 + 60.0)
        for lead in leads:
            window = run(t0 - lead, t0 + 60.0)
            common = window.index[(window.index >= t0) & (window.index <= t0 + 60.0)]
            phi = [f"phi_{a} [rad]" for a in axes]
            a, b = full.loc[common, phi].to_numpy(), window.loc[common, phi].to_numpy()
            rate = full.loc[t0 - lead, [f"w_{a} [rad/s]" for a in axes]].to_numpy()
            rows.append(
                {
                    "event": event,
                    "window start [s]": t0 - lead,
                    "APE from t=0 [rad]": np.abs(a).max(),
                    "APE from window [rad]": np.abs(b).max(),
                    "max |dphi| [rad]": np.abs(a - b).max(),
                    "|w_hub| at start, run from 0 [rad/s]": np.linalg.norm(rate),
                }
            )
    print("windows starting at rest vs the mission from t = 0 (APE over [t, t + 60] s)")
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.3g}".format))


def pointing_by_phase(seed: int = 0) -> None:
    """The nominal mission from t = 0 against the APE requirement, phase by phase: the largest
    logged |phi| (1 Hz log, any axis) of each phase and the logged samples above the requirement
    (``--pointing-by-phase``; the phases are the mission cut at its events, as in the campaign
    specs)."""
    simulation = _simulation(MissionOptions(log_rate=1.0))
    requirement = load_scenario("paper").control.pointing_requirement
    result = simulation.run({}, seed=seed)
    series = result.timeseries
    t = series["time [s]"].to_numpy()
    phi = series[[f"phi_{a} [rad]" for a in "xyz"]].abs().max(axis=1).to_numpy()
    events = sorted(simulation.events.items(), key=lambda item: item[1])
    edges = [(0.0, "start"), *[(time, name) for name, time in events], (simulation.duration, "end")]
    rows = []
    for (a, first), (b, second) in zip(edges[:-1], edges[1:], strict=True):
        inside = (t >= a) & (t < b) if b < simulation.duration else (t >= a)
        above = inside & (phi > requirement)
        k = np.argmax(np.where(inside, phi, -1.0))
        rows.append(
            {
                "phase": f"{first}-{second}",
                "start [s]": a,
                "end [s]": b,
                "max |phi| [rad]": phi[k],
                "at [s]": t[k],
                "samples above": int(above.sum()),
                "first above [s]": t[above][0] if above.any() else np.nan,
                "last above [s]": t[above][-1] if above.any() else np.nan,
            }
        )
    print(
        f"\nnominal mission from t = 0 (seed {seed}), APE requirement {requirement} rad; "
        f"metric ape (10 Hz) {result.metrics['ape']:.4g} rad"
    )
    print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-full", action="store_true", help="skip the whole-mission run")
    parser.add_argument("--profile", action="store_true", help="part 2: where the time goes")
    parser.add_argument("--runs", type=int, default=6, help="cases of the parallel benchmark")
    parser.add_argument("--window", type=float, default=40.0, help="window of each case [s]")
    parser.add_argument("--repeats", type=int, default=2, help="interleaved repeats")
    parser.add_argument("--accuracy-study", action="store_true", help="also the accuracy table")
    parser.add_argument(
        "--same-session",
        action="store_true",
        help="keep the pool workers in the driver's session (see bench_campaign)",
    )
    parser.add_argument(
        "--window-start-study",
        action="store_true",
        help="also compare windows starting at rest with the mission from t = 0",
    )
    parser.add_argument(
        "--pointing-by-phase",
        action="store_true",
        help="also the nominal mission from t = 0 against the APE requirement, per phase",
    )
    parser.add_argument(
        "--candidates",
        action="store_true",
        help="also whole missions with cheaper integrator settings against today's options",
    )
    parser.add_argument("--only-parallel", action="store_true", help="only part 4")
    parser.add_argument("--skip-parallel", action="store_true", help="skip part 4")
    args = parser.parse_args()
    limit_blas_threads(1)  # as in a campaign worker: one process per core
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if not args.only_parallel:
        rows = []
        if not args.skip_full or args.profile:
            simulation = _simulation(MissionOptions())
            row, result = full_mission(simulation)
            rows.append(row)
        rows += integrators()
        print(pd.DataFrame(rows).to_string(index=False, float_format="{:.4g}".format))
        if args.profile:
            profile(simulation, result)
        if args.accuracy_study:
            accuracy_study()
        if args.window_start_study:
            window_start_study()
        if args.pointing_by_phase:
            pointing_by_phase()
        if args.candidates:
            candidates()
    if not args.skip_parallel:
        from bench_campaign import parallel_efficiency

        print("\nparallel efficiency of the campaign's process pool (Drake mission simulator)")
        parallel_efficiency(
            args.runs, args.window, args.repeats, "drake-mission", isolate=not args.same_session
        )


if __name__ == "__main__":
    main()
