"""ulinearize on the Drake twin vs the TITOP LFR: extraction time, repetitions, accuracy.

For the six moments and docking phases 7 and 8 (two stiffnesses each) prints: minimal states
(Drake / TITOP), Delta occurrences, the time of one ``ulinearize`` of the twin against the time
of the TITOP route in the same run (``usubs`` of the configuration into the cached TITOP LFR),
and the largest relative 6x6 frequency-response error between the two LFRs at 20 random
parameter points inside the ranges and 20 up to 1.8 half-ranges outside.

Run: ``PYTHONPATH=. python benchmarks/bench_ulinearize.py``
"""

import time

import numpy as np

from oos_drake.lfr import usubs
from oos_drake.multibody.cross_check import _titop_builders, frequency_grid, validation_cases
from oos_drake.multibody.mission_lfr import mission_parameters, spring_damper_parameters, twin_lfr
from oos_drake.scenario.data import load_scenario


def relative_errors(G, H, omega):
    a, b = G.freqresp(omega), H.freqresp(omega)
    worst = np.linalg.norm(a - b, ord=2, axis=(-2, -1)).max(axis=-1)
    return worst / np.linalg.norm(b, ord=2, axis=(-2, -1)).max(axis=-1)


def normalized(lfr, values):
    """Physical ``values`` of the blocks of ``lfr`` as normalized deltas (no range check)."""
    return {n: s.to_normalized(values[n], check=False) for n, s in lfr.uncertainty.items()}


def main():
    scenario = load_scenario()
    models = {name: build() for name, build in _titop_builders(scenario).items()}
    omega = frequency_grid(200)
    print(
        f"{'case':<22} {'states D/T':>10} {'occ.':>5} {'ulinearize [s]':>14} {'usubs [s]':>10} "
        f"{'ratio':>6} {'err inside':>10} {'err outside':>11}"
    )
    for index, case in enumerate(validation_cases(scenario, stiffness=[1e2, 1e4])):
        springs = {k: v for k, v in case.values.items() if k.split("_")[0] in ("k", "d")}
        declared = mission_parameters(scenario) + spring_damper_parameters(springs)
        wall = time.perf_counter()
        drake = twin_lfr(scenario, case.point, declared)
        drake_s = time.perf_counter() - wall
        wall = time.perf_counter()
        configuration = {k: v for k, v in case.values.items() if k not in springs}
        titop = usubs(models[case.model], configuration)
        titop_s = time.perf_counter() - wall
        rng = np.random.default_rng(index)
        values = {
            p.name: np.concatenate(
                [rng.uniform(p.lower, p.upper, 20), p.spec.to_physical(rng.uniform(-1.8, 1.8, 20))]
            )
            for p in declared
        }

        G = usubs(drake, normalized(drake, values), normalized=True).nominal
        H = usubs(titop, normalized(titop, values), normalized=True).nominal
        error = relative_errors(G, H, omega)
        print(
            f"{case.label:<22} {drake.nstates:>4d}/{titop.nstates:<5d} "
            f"{sum(drake.occurrences.values()):>5d} {drake_s:>14.2f} {titop_s:>10.3f} "
            f"{drake_s / titop_s:>6.0f} {error[:20].max():>10.1e} {error[20:].max():>11.1e}"
        )


if __name__ == "__main__":
    main()
