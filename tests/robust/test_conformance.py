"""Conformance: published examples, their published numbers, our bounds.

Sources (models and numbers in :mod:`published`, each with its page or file):

* MathWorks Robust Control Toolbox documentation: the two-mass ``robstab`` example ("Robust
  Stability and Worst-Case Gain of Uncertain System"), the ``robstab`` and ``wcgain`` reference
  pages' first examples;
* RobustAndOptimalControl.jl ``test/test_uncertainty.jl`` (``robstab`` of a SISO loop with an
  ``ultidyn`` or ``ucomplex`` block, of a MIMO loop with two complex scalars);
* SLICOT-Reference ``examples/AB13MD.dat`` / ``AB13MD.res`` (mu upper bound of a mixed 6 x 6
  structure), and slycot's ``ab13md`` as a second method on the same data.

Tolerances follow from what each source reports: a published interval ``[lo, up]`` contains the
exact value, so our certified bounds must not contradict it (our guaranteed margin <= their
destabilizing one, our destabilizing margin >= their guaranteed one, up to their printed
rounding) and must be close to it (within our slack, 0.5 %, plus the rounding).
"""

import numpy as np
import pytest
from published import (
    AB13MD_BLK,
    AB13MD_BOUND,
    RCT_ROBSTAB,
    RCT_TWO_MASS,
    RCT_WCGAIN,
    ROC_MIMO,
    ROC_SISO,
    ab13md_matrix,
    rct_robstab_loop,
    rct_wcgain_loop,
    roc_mimo_loop,
    roc_siso_loop,
)

from oos_drake.lfr import usubs
from oos_drake.robust import mussv, robstab, wcgain
from oos_drake.robust.hinf import hinfnorm
from oos_drake.robust.mu_intervals import SLACK

ROUND = 1e-4  # the pages print 5 significant digits


def assert_consistent_margin(res, published, *, close=2 * SLACK):
    """Our bounds against a published margin interval ``[lower, upper]``."""
    assert res.covered and res.reason == ""
    # the exact margin lies in both intervals: they must intersect
    assert res.lower <= published["upper"] * (1 + ROUND)
    assert res.upper >= published["lower"] * (1 - ROUND)
    # and ours is about as tight (the guaranteed bound carries the slack of the cover)
    assert res.lower >= published["lower"] * (1 - close)


def test_rct_two_mass_robstab(two_mass):
    T, _, _, res = two_mass
    assert_consistent_margin(res, RCT_TWO_MASS)
    assert res.guarantee.check()["covered"]
    # the published destabilizing values put a closed-loop pole on the imaginary axis at the
    # published critical frequency in OUR model (checks the model, independently of mu)
    # (1 +- 20 %: normalized value = (physical - 1) / 0.2, outside the unit box)
    worst = {name: (RCT_TWO_MASS[name] - 1.0) / 0.2 for name in ("k", "m1", "m2")}
    poles = np.linalg.eigvals(np.asarray(usubs(T, worst, normalized=True).A))
    crossing = poles[np.argmin(np.abs(poles.real))]
    assert abs(crossing.real) < 1e-3 * abs(crossing)
    assert abs(crossing.imag) == pytest.approx(RCT_TWO_MASS["critical"], rel=1e-3)


def test_rct_two_mass_critical_frequency(two_mass):
    # the guaranteed level is reached near the published critical frequency: the cover's
    # highest solved mu upper bound sits within 1 % of 575.0339 rad/s
    *_, res = two_mass
    g = res.guarantee
    peak = g.omega[np.nanargmax(np.where(np.isfinite(g.optimal), g.optimal, -np.inf))]
    assert peak == pytest.approx(RCT_TWO_MASS["critical"], rel=1e-2)


def test_rct_robstab_page_example():
    res = robstab(rct_robstab_loop())
    assert_consistent_margin(res, RCT_ROBSTAB)
    assert res.upper <= RCT_ROBSTAB["upper"] * (1 + 1e-3)
    assert res.critical_frequency == pytest.approx(RCT_ROBSTAB["critical"], rel=1e-2)


def test_rct_wcgain_page_example():
    res = wcgain(rct_wcgain_loop())
    assert res.covered and res.reason == ""
    # achieved gains never exceed a valid upper bound, and the reverse
    assert res.lower <= RCT_WCGAIN["upper"] * (1 + ROUND)
    assert res.upper >= RCT_WCGAIN["lower"] * (1 - ROUND)
    assert res.lower >= RCT_WCGAIN["lower"] * (1 - 1e-3)
    assert res.upper <= RCT_WCGAIN["upper"] * (1 + 2 * SLACK)
    # the peak is flat in frequency: the published critical frequency within 3 %
    assert res.critical_frequency == pytest.approx(RCT_WCGAIN["critical"], rel=3e-2)


@pytest.mark.parametrize("kind", ["ultidyn", "ucomplex"])
def test_roc_siso_robstab(kind):
    loop = roc_siso_loop(kind)
    # one full (or complex scalar) block: mu is the H-infinity norm of M
    M = (np.asarray(loop.A), np.asarray(loop.Bw), np.asarray(loop.Cz), np.asarray(loop.Dzw))
    assert float(hinfnorm(M).norm) == pytest.approx(ROC_SISO["hinf"], rel=1e-3)
    res = robstab(loop)
    assert res.covered
    for bound in (res.lower, res.upper):
        assert bound == pytest.approx(ROC_SISO["margin"], abs=ROC_SISO["atol"])
    assert res.lower <= 1 / ROC_SISO["hinf"] <= res.upper * (1 + 1e-6)


def test_roc_mimo_robstab():
    res = robstab(roc_mimo_loop())
    assert res.covered
    margin, atol = ROC_MIMO["margin"], ROC_MIMO["atol"]
    assert res.upper == pytest.approx(margin, abs=atol)
    # the guaranteed margin carries the cover's slack (0.5 %) on top of their tolerance
    assert (margin - atol) / (1 + 2 * SLACK) <= res.lower <= margin + atol


def test_slicot_ab13md_example():
    Z = ab13md_matrix()
    res = mussv(Z, AB13MD_BLK)
    # AB13MD's value is an upper bound: our certified lower bound cannot exceed it, and both
    # our bounds lie within 1e-5 of it (the printed 10 digits)
    assert res.lower <= AB13MD_BOUND * (1 + 1e-9)
    assert res.lower == pytest.approx(AB13MD_BOUND, rel=1e-5)
    assert res.upper == pytest.approx(AB13MD_BOUND, rel=1e-5)


def test_slicot_ab13md_second_method():
    slycot = pytest.importorskip("slycot")
    Z = ab13md_matrix()
    bound = slycot.ab13md(Z, np.array([1, 1, 2, 1, 1]), np.array([1, 1, 2, 2, 2]))[0]
    assert bound == pytest.approx(AB13MD_BOUND, rel=1e-9)  # the library reproduces its .res
    res = mussv(Z, AB13MD_BLK)
    assert res.lower <= bound * (1 + 1e-9) and res.upper >= res.lower
