"""Drake-extracted mission LFRs (ulinearize on the twin) vs the TITOP LFR (an independent model).

At the six moments and docking phases 7 and 8, both LFRs are substituted at the same physical
parameter values, inside the ranges and up to 1.8 half-ranges outside, and their 6x6 frequency
responses ``[F; T] at G1 -> [a; wdot] at G1`` compared; repetition counts must equal TITOP's.
"""

import numpy as np
import pytest

pytestmark = [pytest.mark.drake, pytest.mark.slow]
pytest.importorskip("pydrake")

from oos_drake.lfr import usubs  # noqa: E402
from oos_drake.multibody.cross_check import (  # noqa: E402
    _titop_builders,
    frequency_grid,
    validation_cases,
)
from oos_drake.multibody.mission_lfr import (  # noqa: E402
    SPRING_QUANTITIES,
    mission_parameters,
    spring_damper_parameters,
    twin_lfr,
)
from oos_drake.scenario.data import load_scenario  # noqa: E402

SAMPLES = 6  # per case: half inside the ranges, half outside
OMEGA = frequency_grid(omega_range=(2 * np.pi * 0.01, 2 * np.pi * 100.0), points=200)


@pytest.fixture(scope="module")
def titop():
    scenario = load_scenario()
    return scenario, {name: build() for name, build in _titop_builders(scenario).items()}


def cases(scenario):
    # phase 7 and 8 at a soft and a stiff docking spring (the sweep's 1e2 and 1e4 N/m)
    return validation_cases(scenario, stiffness=[1e2, 1e4])


def _relative_errors(G, H):
    a, b = G.freqresp(OMEGA), H.freqresp(OMEGA)
    worst = np.linalg.norm(a - b, ord=2, axis=(-2, -1)).max(axis=-1)
    return worst / np.linalg.norm(b, ord=2, axis=(-2, -1)).max(axis=-1)


@pytest.mark.parametrize("index", range(12))
def test_drake_lfr_equals_titop_lfr(titop, index):
    scenario, models = titop
    case = cases(scenario)[index]
    springs = {k: v for k, v in case.values.items() if k.split("_")[0] in ("k", "d")}
    declared = mission_parameters(scenario) + spring_damper_parameters(springs)
    drake = twin_lfr(scenario, case.point, declared)
    configuration = {k: v for k, v in case.values.items() if k not in springs}
    reference = usubs(models[case.model], configuration)
    # repetitions: the TITOP counts (delta_m I3, one per inertia moment, w I2 per array,
    # k/d I3 per spring-damper); blocks that do not act here (free target) are absent in Drake
    for name, reps in drake.occurrences.items():
        assert reps == reference.occurrences[name], (case.label, name)
    # a free target (hub RH2 with arrays SA3, SA4) does not act on the chaser's hub
    target = ("RH2", "SA3", "SA4") if case.point.connection == "free" else ()
    expected = {p.name for p in declared if not p.name.endswith(target or ("-",))}
    assert set(drake.uncertainty) == expected, case.label
    rng = np.random.default_rng(index)
    values = {}
    for p in declared:
        spec = p.spec
        inside = rng.uniform(p.lower, p.upper, SAMPLES // 2)
        outside = spec.to_physical(rng.uniform(-1.8, 1.8, SAMPLES - SAMPLES // 2))
        values[p.name] = np.concatenate([inside, outside])
    ours = {n: spec.to_normalized(values[n], check=False) for n, spec in drake.uncertainty.items()}
    theirs = {
        n: spec.to_normalized(values[n], check=False) for n, spec in reference.uncertainty.items()
    }
    G = usubs(drake, ours, normalized=True).nominal
    H = usubs(reference, theirs, normalized=True).nominal
    error = _relative_errors(G, H)
    assert error.max() < 1e-8, (case.label, error)


def test_spring_parameter_names_are_the_titop_blocks(titop):
    scenario, models = titop
    for prefix in SPRING_QUANTITIES:
        for spring in ("SM1", "SM2"):
            assert f"{prefix}_{spring}" in models["8"].uncertainty


@pytest.mark.parametrize("name", ["paper", "user_chaser"])
def test_extractions_on_spawned_workers_equal_the_serial_ones(name):
    """``twin_mission_plants`` on an executor (2 spawned workers, one task per time) gives the
    serial model array entry for entry: the LFRs do not depend on where they were extracted.
    The workers receive the scenario itself (pickled), also one that is not a shipped file."""
    from pathlib import Path

    from oos_drake.control.plants import mission_times
    from oos_drake.multibody.mission_lfr import twin_mission_plants
    from oos_drake.processes import make_executor

    data = Path(__file__).parents[1] / "data"
    scenario = load_scenario(name if name == "paper" else data / f"{name}.toml")
    times = mission_times(3, scenario)
    done = []
    with make_executor(2, method="spawn") as executor:
        pooled = twin_mission_plants(
            times, scenario, executor=executor, progress=lambda k, n: done.append((k, n))
        )
    serial = twin_mission_plants(times, scenario)
    assert done == [(1, 3), (2, 3), (3, 3)]
    assert pooled.batch_shape == (3,)
    assert np.array_equal(np.asarray(pooled.M), np.asarray(serial.M))
    assert pooled.block_entries == serial.block_entries
    assert (pooled.input_names, pooled.output_names) == (serial.input_names, serial.output_names)
