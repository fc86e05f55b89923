"""A linear twin with a sinusoidal input, of known worst case (falsification from the worst input).

The plant ``y = G_p(s) d`` (two outputs, three inputs, two lightly damped modes; the first
mode's frequency scales with the uncertain parameter ``p`` in [0.8, 1.2]) is driven by the
sinusoid ``d(t) = a Re(c / ||c|| e^{j 2 pi f t})`` whose amplitude ``a`` (``sine_amplitude``),
frequency ``f`` (``sine_frequency`` [Hz]) and complex direction ``c`` (``sine_re_<ch>``,
``sine_im_<ch>``) are parameters of kind ``disturbance``, as in the Drake mission. The metric
``ape`` [rad] is the steady-state peak of the larger output, ``a max_i |G_{p,i}(j w) c| / ||c||``,
plus ``noise_scale`` times :data:`NOISE` (a stand-in for the random inputs). Its maximum over
``p``, ``f`` and ``c`` (at ``a = 1``, no noise) is ``max_{p, w} max_i ||G_{p,i}(j w)||_2``.
"""

from __future__ import annotations

import numpy as np

from oos_drake.campaign.simulator import Parameter, ParameterKind, RunOutput

CHANNELS = ("d_x", "d_y", "d_z")
NOISE = 1.0e-3  # [rad]
_RNG = np.random.default_rng(7)
B = _RNG.standard_normal((4, 3))
C = _RNG.standard_normal((2, 4))
ZETA = 0.05
F1, F2 = 0.1, 0.3  # [Hz] the two modes at p = 1


def response(p: float, f: float) -> np.ndarray:
    """``G_p(j 2 pi f)`` (2x3)."""
    A = np.zeros((4, 4))
    for k, fn in enumerate((F1 * p, F2)):
        w = 2 * np.pi * fn
        A[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = [[0.0, 1.0], [-(w**2), -2 * ZETA * w]]
    s = 2j * np.pi * f
    return 0.01 * C @ np.linalg.solve(s * np.eye(4) - A, B)


def peak(values) -> float:
    """The metric [rad] (module docstring)."""
    c = np.array([values[f"sine_re_{ch}"] + 1j * values[f"sine_im_{ch}"] for ch in CHANNELS])
    norm = np.linalg.norm(c)
    forced = 0.0
    if norm > 0:
        y = response(values["p"], values["sine_frequency"]) @ (c / norm)
        forced = values["sine_amplitude"] * np.abs(y).max()
    return float(forced + values["noise_scale"] * NOISE)


class SineSimulator:
    """The linear twin as a campaign simulator (module docstring)."""

    def parameters(self):
        disturbance = ParameterKind.DISTURBANCE
        out = [
            Parameter("p", "-", 1.0, 0.5, 1.5, uncertainty=(0.8, 1.2)),
            Parameter("noise_scale", "-", 1.0, 0.0, 10.0, disturbance),
            Parameter("sine_amplitude", "-", 0.0, 0.0, 10.0, disturbance),
            Parameter("sine_frequency", "Hz", 0.1, 1e-3, 5.0, disturbance),
        ]
        for part in ("re", "im"):
            out += [
                Parameter(f"sine_{part}_{ch}", "-", 0.0, -1.0, 1.0, disturbance) for ch in CHANNELS
            ]
        return tuple(out)

    def metric_units(self):
        return {"ape": "rad"}

    def signal_units(self):
        return {}

    def events(self):
        return {"capture": 10.0}

    def duration(self):
        return 100.0

    def run(self, case):
        return RunOutput(metrics={"ape": peak(case.values)})


def make_simulator(**options) -> SineSimulator:
    return SineSimulator(**options)
