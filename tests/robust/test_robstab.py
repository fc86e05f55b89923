"""robstab, wcgain, robust_sweep against margins from parameter sweeps tracking the poles."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from oos_drake.lfr import feedback, ultidyn, ureal, usubs
from oos_drake.robust import hinfnorm, robstab, robust_sweep, wcgain
from oos_drake.robust.mu_intervals import SLACK


def _max_real_pole(sys, values):
    """Largest real part of the closed-loop poles for NORMALIZED block values (arrays allowed)."""
    closed = usubs(sys, values, normalized=True)
    A = np.asarray(closed.A)
    return np.max(np.linalg.eigvals(A).real, axis=-1)


def _margin_by_pole_sweep(sys, names, n_boundary=400, hi=10.0):
    """Smallest box size alpha (normalized, inf-norm) with an unstable point on its boundary.

    Independent of mu: bisection on alpha, each step evaluates closed-loop poles on a dense grid
    of the boundary of the box [-alpha, alpha]^k (one or two parameters).
    """
    t = np.linspace(-1.0, 1.0, n_boundary)
    if len(names) == 1:
        pts = [np.array([-1.0, 1.0])]
    else:
        one = np.ones_like(t)
        pts = [np.concatenate([t, t, one, -one]), np.concatenate([one, -one, t, t])]

    def unstable(alpha):
        values = {n: alpha * p for n, p in zip(names, pts, strict=True)}
        return np.any(_max_real_pole(sys, values) >= 0)

    lo, hi_ = 0.0, hi
    assert unstable(hi_)
    for _ in range(50):
        mid = 0.5 * (lo + hi_)
        lo, hi_ = (lo, mid) if unstable(mid) else (mid, hi_)
    return hi_


def test_single_gain_margin_matches_pole_sweep():
    k = ureal("k", 40.0, plusminus=10.0)
    loop = feedback(k * control.tf(1, [1, 6, 11, 6]), 1)
    exact = _margin_by_pole_sweep(loop, ["k"])
    res = robstab(loop)
    assert_allclose(res.upper, exact, rtol=1e-6)
    assert res.lower <= exact * (1 + 1e-9)
    assert res.lower >= 0.97 * exact
    assert_allclose(res.critical_frequency, np.sqrt(11.0), rtol=1e-6)
    assert_allclose(res.worst_case["k"], 60.0, rtol=1e-6)  # physical value
    # the worst case puts a pole on the imaginary axis
    assert abs(_max_real_pole(loop, res.worst_case_normalized)) < 1e-6


def test_lightly_damped_mode_not_missed():
    # flexible mode zeta = 0.01 with uncertain frequency (w appears 5 times) and loop gain:
    # char. poly (s + 1)(s^2 + 2 zeta w s + w^2) + kk w^2, destabilized at the resonance
    zeta = 0.01
    w = ureal("w", 1.0, percent=20)
    kk = ureal("kk", 0.02, plusminus=0.01)
    integ = control.tf(1, [1, 0])
    plant = feedback(integ * feedback(integ, 2 * zeta * w), w**2)
    loop = feedback(kk * control.tf(1, [1, 1]) * (w**2) * plant, 1)
    exact = _margin_by_pole_sweep(loop, ["kk", "w"], n_boundary=2001)
    res = robstab(loop)
    assert res.nominal_stable
    assert_allclose(res.upper, exact, rtol=2e-3)
    assert res.lower <= exact * (1 + 1e-6)
    assert abs(res.critical_frequency - 1.0) < 0.05  # at the lightly damped resonance
    assert abs(_max_real_pole(loop, res.worst_case_normalized)) < 1e-6
    # the gain alone (w nominal): the same margin here, since k_crit(w) is smallest at w = 1
    only_k = robstab(loop, blocks=["kk"])
    assert_allclose(only_k.upper, _margin_by_pole_sweep(loop, ["kk"]), rtol=1e-4)
    assert set(only_k.worst_case) == {"kk"}


def test_unstructured_margin_is_inverse_hinf_norm_and_worst_case_realization():
    # multiplicative input uncertainty P (1 + 0.5 d): margin = 1 / ||0.5 T||_inf
    P = control.tf([4.0], [1.0, 2.0, 1.0])
    K = control.tf([1.0, 0.5], [1.0, 5.0])
    d = ultidyn("d", (1, 1))
    loop = feedback(P * (1 + 0.5 * d) * K, 1)
    T = control.feedback(P * K, 1)
    ref = 1.0 / hinfnorm(control.ss(0.5 * T)).norm
    res = robstab(loop)
    assert_allclose(res.upper, ref, rtol=2e-3)
    assert res.lower <= res.upper
    # guaranteed on the whole axis, below the exact margin by at most the slack of the cover
    assert ref / (1 + SLACK) / (1 + 2e-3) <= res.lower <= ref * (1 + 1e-9)
    assert_allclose(robstab(loop, guaranteed=False).lower, ref, rtol=2e-3)
    wc = res.worst_case["d"]  # stable LTI system with ||wc||_inf = upper
    assert_allclose(hinfnorm(wc).norm, res.upper, rtol=1e-6)
    closed = control.feedback(P * (1 + 0.5 * wc) * K, 1)
    assert abs(np.max(np.linalg.eigvals(control.ss(closed).A).real)) < 1e-6


def test_nominally_unstable_is_reported():
    k = ureal("k", 1.0, plusminus=0.1)
    loop = feedback(k * control.tf(1, [1, -1]), -1, sign=1)  # positive feedback, unstable
    res = robstab(loop)
    assert not res.nominal_stable and res.upper == 0.0 and res.lower == 0.0


def test_wcgain_matches_parameter_sweep():
    zeta_c = 0.1
    z = ureal("z", zeta_c, plusminus=0.05)
    integ = control.tf(1, [1, 0])
    sys = feedback(integ * feedback(integ, 2 * z), 1.0)  # 1/(s^2 + 2 z s + 1)
    res = wcgain(sys)
    exact = 1 / (2 * 0.05 * np.sqrt(1 - 0.05**2))  # z = 0.05 worst
    assert res.lower <= exact * (1 + 1e-9)
    assert res.lower >= exact * 0.995
    assert res.upper >= res.lower
    assert_allclose(res.worst_case["z"], 0.05, rtol=1e-3)


def test_robust_sweep_table_and_consistency_with_robstab():
    k = ureal("k", 40.0, plusminus=10.0)
    g = ureal("g", 1.0, plusminus=0.2)
    loop = feedback(k * g * control.tf(1, [1, 6, 11, 6]), 1)
    arr = usubs(loop, {"g": np.array([0.9, 1.0, 1.1])})
    omega = np.linspace(0.5, 6.0, 40)
    df = robust_sweep(arr, omega, subsets={"k": ["k"]}, times=np.array([0.0, 10.0, 20.0]))
    assert list(df.columns) == [
        "subset",
        "model",
        "time [s]",
        "frequency [Hz]",
        "mu lower [-]",
        "mu upper [-]",
        "refined",
        "tightened",
        "mu upper guaranteed [-]",
        "guarantee points",
        "covered",
        "reason",
    ]
    assert df["covered"].all() and (df["reason"] == "").all()
    assert set(df.model) == {0, 1, 2}
    # the guaranteed peak over the whole axis: stable for k g < 60, so mu = 10 / (60 / g - 40)
    exact = 10.0 / (60.0 / np.array([0.9, 1.0, 1.1]) - 40.0)
    axis = df.groupby("model")["mu upper guaranteed [-]"].first().values
    assert np.all(axis >= exact) and np.all(axis <= 1.02 * exact)
    assert np.all(df["mu lower [-]"] <= df["mu upper [-]"] * (1 + 1e-9))
    grid = df[~df.refined]["frequency [Hz]"].unique() * 2 * np.pi
    assert_allclose(np.sort(grid), omega)
    assert df[df.model == 1]["time [s]"].iloc[0] == 10.0
    with pytest.raises(ValueError, match="unknown"):
        robust_sweep(arr, omega, subsets={"bad": ["nope"]})
    # peak mode (default): untightened frequencies cannot hold a model's peak
    best = df.groupby("model")["mu lower [-]"].transform("max")
    assert np.all(df["mu upper [-]"][~df.tightened] <= best[~df.tightened] * (1 + 1e-12))
    # independent mussv calls per frequency (full mode, no warm start) agree on the peaks
    cold = robust_sweep(
        arr, omega, subsets={"k": ["k"]}, mode="full", warm_start=False, n_jobs=2, guaranteed=False
    )
    assert "mu upper guaranteed [-]" not in cold.columns
    assert cold.tightened.all()
    assert_allclose(
        cold.groupby("model")["mu upper [-]"].max().values,
        df.groupby("model")["mu upper [-]"].max().values,
        rtol=1e-2,
    )


def test_complex_scalar_margin_matches_dense_frequency_sweep():
    # loop 1 + c P(s) = 0 with c = 1 + 0.5 delta (ucomplex): the smallest destabilizing |delta|
    # at frequency w solves 1 + (1 + 0.5 delta) P(jw) = 0, i.e. delta = -2 (1 + 1/P(jw))
    from oos_drake.lfr import ucomplex

    P = control.tf([4.0], [1.0, 2.0, 1.0])
    c = ucomplex("c", 1.0, 0.5)
    loop = feedback(c * P, 1)
    w = np.linspace(0.0, 20.0, 400001)
    Pjw = 4.0 / (1j * w + 1.0) ** 2
    exact = np.min(np.abs(2.0 * (1.0 + 1.0 / Pjw)))
    res = robstab(loop)
    assert_allclose(res.upper, exact, rtol=1e-4)
    assert exact / (1 + SLACK) / (1 + 1e-3) <= res.lower <= exact * (1 + 1e-9)
    c_wc = res.worst_case["c"]  # physical complex value
    P_crit = 4.0 / (1j * res.critical_frequency + 1.0) ** 2
    assert abs(1.0 + c_wc * P_crit) < 1e-8
