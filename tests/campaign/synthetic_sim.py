"""A synthetic simulator of known worst case, for falsification tests (runs in microseconds).

Two parameters ``a``, ``b`` in [0, 1] and a disturbance amplitude ``d`` in [0, 1]; the metric
``ape`` [rad] is a global bump of height ``PEAK`` at ``WORST`` plus a lower decoy bump, scaled by
``(0.5 + 0.5 d)``: the worst case is ``(a, b, d) = (*WORST, 1)`` with ``ape = PEAK``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from oos_drake.campaign.simulator import Parameter, ParameterKind, RunOutput

WORST = (0.73, 0.21)
PEAK = 0.012  # [rad]
DECOY = ((0.2, 0.8), 0.008)


def bump(a: float, b: float, d: float) -> float:
    """The metric [rad]: the function the falsification maximizes."""
    main = PEAK * math.exp(-((a - WORST[0]) ** 2 + (b - WORST[1]) ** 2) / 0.03)
    (ca, cb), height = DECOY
    decoy = height * math.exp(-((a - ca) ** 2 + (b - cb) ** 2) / 0.01)
    return max(main, decoy) * (0.5 + 0.5 * d)


class SyntheticSimulator:
    """Known worst case; ``interrupt_at``: run id at which the first call raises
    KeyboardInterrupt (a crash of the driver), marked done in ``marker`` so a resume passes."""

    def __init__(self, interrupt_at: int = -1, marker: str = ""):
        self.interrupt_at, self.marker = interrupt_at, marker
        self.calls = 0

    def parameters(self):
        return (
            Parameter("a", "-", 0.5, 0.0, 1.0),
            Parameter("b", "-", 0.5, 0.0, 1.0),
            Parameter("d", "-", 0.0, 0.0, 1.0, ParameterKind.INITIAL_CONDITION),
        )

    def metric_units(self):
        return {"ape": "rad"}

    def signal_units(self):
        return {}

    def events(self):
        return {"capture": 10.0}

    def duration(self):
        return 100.0

    def run(self, case):
        if case.run_id == self.interrupt_at and self.marker and not Path(self.marker).exists():
            Path(self.marker).write_text("interrupted once")
            raise KeyboardInterrupt
        self.calls += 1
        v = case.values
        return RunOutput(metrics={"ape": bump(v["a"], v["b"], v["d"])})


def make_simulator(**options) -> SyntheticSimulator:
    return SyntheticSimulator(**options)


#: The "scenario" of :class:`DeclaredSimulator`: nominal first-mode frequency [rad/s] and its
#: declared uncertainty [%].
W1_NOMINAL, W1_PERCENT = 8.0, 20.0


class DeclaredSimulator(SyntheticSimulator):
    """The synthetic simulator with a parameter ``w1`` the scenario declares uncertain
    (``W1_NOMINAL +- W1_PERCENT``), inside a wider domain of validity."""

    def parameters(self):
        r = W1_PERCENT / 100
        w1 = Parameter(
            "w1",
            "rad/s",
            W1_NOMINAL,
            1.0,
            20.0,
            uncertainty=(W1_NOMINAL * (1 - r), W1_NOMINAL * (1 + r)),
        )
        return (*super().parameters(), w1)


def make_declared_simulator(**options) -> DeclaredSimulator:
    return DeclaredSimulator(**options)


#: :class:`BumpSimulator`: its parameters' number, the worst case (one value per parameter, all
#: inside the box, spread over it) and the curvatures of the bump (condition number 16).
BUMP_DIMENSION = 20
BUMP_WORST = tuple(
    0.15 + 0.7 * ((7 * i) % BUMP_DIMENSION) / (BUMP_DIMENSION - 1) for i in range(BUMP_DIMENSION)
)
BUMP_CURVATURE = tuple(np.geomspace(0.5, 8.0, BUMP_DIMENSION).tolist())


def many_bump(x) -> float:
    """The metric of :class:`BumpSimulator` [rad]: ``PEAK exp(-sum_j c_j (x_j - x*_j)^2)``,
    largest (``PEAK``) at ``BUMP_WORST``."""
    x, worst = np.asarray(x, float), np.asarray(BUMP_WORST)
    return PEAK * math.exp(-float(np.sum(np.asarray(BUMP_CURVATURE) * (x - worst) ** 2)))


class BumpSimulator(SyntheticSimulator):
    """``BUMP_DIMENSION`` parameters ``x00``, ``x01``, ... in [0, 1] (nominal 0.5), one smooth
    anisotropic bump of known maximum ``PEAK`` at ``BUMP_WORST``: a search in many dimensions
    from a start off the optimum (the nominal point: ``many_bump`` there is 0.096 PEAK)."""

    def parameters(self):
        return tuple(Parameter(f"x{i:02d}", "-", 0.5, 0.0, 1.0) for i in range(BUMP_DIMENSION))

    def run(self, case):
        self.calls += 1
        return RunOutput(
            metrics={"ape": many_bump([case.values[f"x{i:02d}"] for i in range(BUMP_DIMENSION)])}
        )


def make_bump_simulator(**options) -> BumpSimulator:
    return BumpSimulator(**options)
