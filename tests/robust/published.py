"""Published robustness examples, built with the package's LFR algebra, and their sources.

Each builder states the page (or file) the model and its numbers come from. The numbers are the
ones printed there; the tests compare with tolerances that follow from what the source reports
(bounds of an interval, a printed rounding, a test's own ``atol``).
"""

import re

import control
import numpy as np

from oos_drake.lfr import append, as_lfr, feedback, hstack, lft, ucomplex, ultidyn, ureal, vstack

S = control.tf("s")
INTEG = control.tf(1, [1, 0])


def pid(kp, ki, kd, tf):
    """MATLAB ``pid(Kp, Ki, Kd, Tf)``: ``Kp + Ki / s + Kd s / (Tf s + 1)``."""
    return control.ss(kp + ki / S + kd * S / (tf * S + 1))


def rct_two_mass_loop():
    """MathWorks Robust Control Toolbox documentation, "Robust Stability and Worst-Case Gain of
    Uncertain System" (robust/gs/worst-case-performance-of-uncertain-system.html): masses
    ``m1``, ``m2`` and spring ``k``, each ``ureal(.., 1, 'percent', 20)``;
    ``F = [0; G1] [1 -1] + [1; -1] [0, G2]``, ``P = lft(F, k)``,
    ``C = 100 ((s + 1) / (0.001 s + 1))^3``, ``T = feedback(P C, 1)``.

    Printed: ``stabmarg = LowerBound 2.8834, UpperBound 2.8864, CriticalFrequency 575.0339``;
    ``wcus = k 1.5773, m1 0.4227, m2 0.4227``.
    """
    m1 = ureal("m1", 1.0, percent=20)
    m2 = ureal("m2", 1.0, percent=20)
    k = ureal("k", 1.0, percent=20)
    G1 = control.ss(1 / S**2) * (1 / m1)
    G2 = control.ss(1 / S**2) * (1 / m2)
    F = vstack([0, G1]) * hstack([1, -1]) + vstack([1, -1]) * hstack([0, G2])
    C = 100 * control.ss((S + 1) / (0.001 * S + 1)) ** 3
    return feedback(lft(F, k) * C, 1)


RCT_TWO_MASS = dict(lower=2.8834, upper=2.8864, critical=575.0339, k=1.5773, m1=0.4227, m2=0.4227)


def rct_robstab_loop():
    """MathWorks RCT ``robstab`` reference page, example "Robust Stability Margin of
    Closed-Loop System": ``k = ureal('k', 10, 'Percent', 40)``, ``delta = ultidyn('delta',
    [1 1])``, ``G = tf(18, [1 1.8 k]) (1 + 0.5 delta)``, ``C = pid(2.3, 3, 0.38, 0.001)``,
    ``CL = feedback(G C, 1)``.

    Printed: ``LowerBound 1.5960, UpperBound 1.5993, CriticalFrequency 4.8627``.
    """
    k = ureal("k", 10.0, percent=40)
    delta = ultidyn("delta", (1, 1))
    integ = as_lfr(INTEG)
    plant = 18 * feedback(integ * feedback(integ, 1.8), k)  # 18 / (s^2 + 1.8 s + k)
    return feedback(plant * (1 + 0.5 * delta) * pid(2.3, 3, 0.38, 0.001), 1)


RCT_ROBSTAB = dict(lower=1.5960, upper=1.5993, critical=4.8627)


def rct_wcgain_loop():
    """MathWorks RCT ``wcgain`` reference page, example "Worst-Case Peak Gain of Closed-Loop
    System": ``delta = ultidyn('delta', [1 1], 'bound', 0.4)``, ``G = tf(1, [1 0]) + delta``,
    ``C = pid(2, 0, -0.04, 0.02)``, ``S = feedback(1, G C)``.

    Printed: ``wcg = LowerBound 5.1036, UpperBound 5.1140, CriticalFrequency 10.7241``.
    """
    delta = ultidyn("delta", (1, 1), bound=0.4)
    G = as_lfr(INTEG) + delta
    return feedback(1, G * pid(2, 0, -0.04, 0.02))


RCT_WCGAIN = dict(lower=5.1036, upper=5.1140, critical=10.7241)


def roc_siso_loop(kind: str):
    """RobustAndOptimalControl.jl ``test/test_uncertainty.jl``, "Test structured_singular_value
    with different kinds of blocks": ``P = tf(1, [1, .2, 1]) (1 + 0.2 delta)`` with ``delta =
    δss(1, 1)`` (``ultidyn``) or ``δc()`` (``ucomplex``), ``K = 1 + 2 / s + 0.9 s / (0.1 s + 1)``,
    ``Gcl = lft(P, -K)``.

    Tested there: ``norm(Gcl, Inf) ≈ 1.1861236982687908 rtol=1e-3`` (``M`` seen by delta: a
    single full block, mu is its H-infinity norm) and ``robstab(Gcl) ≈ 0.84 atol=0.005``.
    """
    delta = ultidyn("delta", (1, 1)) if kind == "ultidyn" else ucomplex("delta", 0.0, 1.0)
    P = control.tf(1, [1, 0.2, 1]) * (1 + 0.2 * delta)
    return feedback(P * control.ss(1 + 2 / S + 0.9 * S / (0.1 * S + 1)), 1)


ROC_SISO = dict(hinf=1.1861236982687908, margin=0.84, atol=0.005)


def roc_mimo_loop():
    """RobustAndOptimalControl.jl ``test/test_uncertainty.jl``, "this time mimo complex":
    ``P = ss([0 1; 0 0], I(2), [1 0], 0) (I(2) + diag(δc(), δc()))``, ``K = [1; 1]``,
    ``G = lft(P, -K)``. Tested there: ``robstab(G) ≈ 0.4824 atol=0.001``.
    """
    d1, d2 = ucomplex("d1", 0.0, 1.0), ucomplex("d2", 0.0, 1.0)
    P = as_lfr(control.ss([[0, 1], [0, 0]], np.eye(2), [[1, 0]], 0)) * (np.eye(2) + append(d1, d2))
    return feedback(P, np.array([[1.0], [1.0]]))


ROC_MIMO = dict(margin=0.4824, atol=0.001)

#: SLICOT-Reference ``examples/AB13MD.dat`` (N = 6, M = 5, NBLOCK = 1 1 2 1 1,
#: ITYPE = 1 1 2 2 2: two real scalars, a 2x2 complex full block, two complex scalars; Z read
#: row by row) and ``examples/AB13MD.res``: "The value of the structured singular value is
#: 0.4174753408D+02" (AB13MD's upper bound).
AB13MD_ROWS = """
(-1.0D0,6.0D0)  (2.0D0,-3.0D0)  (3.0D0,8.0D0)
(3.0D0,8.0D0)   (-5.0D0,-9.0D0) (-6.0D0,2.0D0)
(4.0D0,2.0D0)   (-2.0D0,5.0D0)  (-6.0D0,-7.0D0)
(-4.0D0,11.0D0) (8.0D0,-7.0D0)  (12.0D0,-1.0D0)
(5.0D0,-4.0D0)  (-4.0D0,-8.0D0) (1.0D0,-3.0D0)
(-6.0D0,14.0D0) (2.0D0,-5.0D0)  (4.0D0,16.0D0)
(-1.0D0,6.0D0)  (2.0D0,-3.0D0)  (3.0D0,8.0D0)
(3.0D0,8.0D0)   (-5.0D0,-9.0D0) (-6.0D0,2.0D0)
(4.0D0,2.0D0)   (-2.0D0,5.0D0)  (-6.0D0,-7.0D0)
(-4.0D0,11.0D0) (8.0D0,-7.0D0)  (12.0D0,-1.0D0)
(5.0D0,-4.0D0)  (-4.0D0,-8.0D0) (1.0D0,-3.0D0)
(-6.0D0,14.0D0) (2.0D0,-5.0D0)  (4.0D0,16.0D0)
"""
AB13MD_BLK = [[-1, 0], [-1, 0], [2, 2], [1, 1], [1, 1]]
AB13MD_BOUND = 41.74753408


def ab13md_matrix() -> np.ndarray:
    """``Z`` of ``AB13MD.dat`` (6 x 6 complex)."""
    pairs = re.findall(r"\(([^,]+),([^)]+)\)", AB13MD_ROWS)
    values = [complex(float(a.replace("D", "e")), float(b.replace("D", "e"))) for a, b in pairs]
    return np.array(values).reshape(6, 6)
