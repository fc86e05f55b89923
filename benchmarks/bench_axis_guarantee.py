"""Cost of the whole-axis guarantee (robust.mu_intervals) against the grid-only bounds.

Run: ``.venv/bin/python benchmarks/bench_axis_guarantee.py``

For the examples of the tests (lightly damped oscillators with real parameters, two modes, a
third-order loop whose crossing frequency moves), ``robstab`` and ``wcgain`` with
``guaranteed=False`` (grid only) and ``guaranteed=True`` in the same run: wall time, the ratio,
the bounds and the number of frequencies the cover solved. Timings on a shared machine are
noisy: read the ratios of the same run. The analysis' own ratio is in the ``guarantee`` entry of
each study's timing detail of ``summary.json`` (``oos analyze``), beside ``grid`` and
``tighten+certify``.
"""

from __future__ import annotations

import time

import control

from oos_drake.lfr import as_lfr, feedback, ureal
from oos_drake.robust import robstab, wcgain


def second_order(k, c):
    integ = as_lfr(control.tf(1, [1, 0]))
    return feedback(integ * feedback(integ, c), k)


def cases():
    yield (
        "oscillator 10 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.2, plusminus=0.1)),
    )
    yield (
        "oscillator 1 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.02, plusminus=0.01)),
    )
    yield (
        "oscillator 0.3 %",
        second_order(ureal("k", 1, plusminus=0.5), ureal("c", 0.006, plusminus=0.003)),
    )
    yield (
        "two modes",
        second_order(ureal("k1", 1, plusminus=0.3), ureal("c1", 0.01, plusminus=0.005))
        + second_order(ureal("k2", 9, plusminus=3), ureal("c2", 0.03, plusminus=0.01)),
    )


def timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def main():
    print(
        f"{'case':18s} {'fn':8s} {'grid [s]':>9s} {'guar [s]':>9s} {'ratio':>6s} "
        f"{'grid upper':>11s} {'guar upper':>11s} {'lower':>10s} {'points':>6s}"
    )
    for name, sys in cases():
        for fn in (wcgain, robstab):
            grid, t0 = timed(fn, sys, guaranteed=False)
            guar, t1 = timed(fn, sys)
            if fn is robstab:  # report mu (1 / margin)
                gu, uu, lo = 1 / grid.lower, 1 / guar.lower, 1 / guar.upper
            else:
                gu, uu, lo = grid.upper, guar.upper, guar.lower
            print(
                f"{name:18s} {fn.__name__:8s} {t0:9.2f} {t1:9.2f} {t1 / t0:6.2f} "
                f"{gu:11.5g} {uu:11.5g} {lo:10.5g} {guar.guarantee.omega.size:6d}"
            )


if __name__ == "__main__":
    main()
