"""LFR algebra against python-control built directly for the same parameter values."""

import control
import numpy as np
import pytest
from lfr_helpers import assert_response_close, control_response, random_ss

from oos_drake.lfr import (
    LFR,
    append,
    as_lfr,
    feedback,
    hstack,
    inv,
    lft,
    ultidyn,
    ureal,
    usubs,
    vstack,
)

OMEGA = np.array([0.03, 0.4, 1.7, 9.0, 55.0])


def test_one_over_m_s2_closed_form():
    m = ureal("m", 2.0, percent=20)
    s = control.tf("s")
    plant = (1 / m) * (1 / s**2)
    assert plant.occurrences == {"m": 1}
    assert plant.nstates == 2
    masses = np.array([1.6, 1.9, 2.0, 2.4])
    resp = usubs(plant, {"m": masses}).freqresp(OMEGA)
    expected = -1.0 / (masses[:, None] * OMEGA[None, :] ** 2)
    np.testing.assert_allclose(resp[..., 0, 0], expected, rtol=1e-12)
    # nominal is 1/(2 s^2); the other ways to write it agree
    np.testing.assert_allclose(plant.nominal.freqresp(OMEGA)[:, 0, 0], -0.5 / OMEGA**2, rtol=1e-12)
    other = inv(m * control.tf([1, 0, 0], [1]) ** 0) * control.tf(1, [1, 0, 0])
    np.testing.assert_allclose(
        usubs(other, {"m": 1.7}).freqresp(OMEGA)[:, 0, 0], -1 / (1.7 * OMEGA**2), rtol=1e-12
    )


def test_blocks_merge_by_name_and_sort():
    k = ureal("k", 10.0, percent=10)
    a = ureal("alpha", 1.0, range=(0.5, 2.0))
    sys = (k * a + k) * k - a
    assert list(sys.occurrences) == ["alpha", "k"]
    assert sys.occurrences == {"alpha": 2, "k": 3}
    table = sys.blocks
    assert list(table["name"]) == ["alpha", "k"]
    assert list(table["repetitions"]) == [2, 3]
    assert table.loc[1, "range"] == pytest.approx((9.0, 11.0))
    value = usubs(sys, {"k": 10.5, "alpha": 1.7}).M[0, 0]
    assert value == pytest.approx((10.5 * 1.7 + 10.5) * 10.5 - 1.7, rel=1e-13)


def test_same_name_different_range_is_an_error():
    with pytest.raises(ValueError, match="'k' is defined twice"):
        ureal("k", 1.0, percent=10) + ureal("k", 1.0, percent=20)


def test_series_parallel_feedback_match_control():
    rng = np.random.default_rng(1)
    P = random_ss(rng, 3, 2, 2)
    K = random_ss(rng, 2, 2, 2)
    H = random_ss(rng, 1, 2, 2)
    g = ureal("g", 1.5, range=(1.0, 3.0))
    sys = feedback(P * (g * K) + H, H, sign=-1) - 0.5 * P
    for value in (1.0, 1.2, 2.9):
        direct = control.feedback(P * (value * K) + H, H, sign=-1) - 0.5 * P
        assert_response_close(
            usubs(sys, {"g": value}).freqresp(OMEGA), control_response(direct, OMEGA)
        )


def test_numpy_array_on_the_left_and_gains():
    k = ureal("k", 2.0, plusminus=0.5)
    gain = np.array([[1.0], [3.0]])
    left = gain * k  # numpy defers to LFR.__rmul__ (__array_ufunc__ = None)
    assert isinstance(left, LFR) and left.shape == (2, 1)
    np.testing.assert_allclose(usubs(left, {"k": 2.4}).M, gain * 2.4, rtol=1e-14)
    right = k * np.array([[1.0, -1.0]])
    np.testing.assert_allclose(usubs(right, {"k": 1.6}).M, [[1.6, -1.6]], rtol=1e-14)
    diag = k * np.eye(3)
    assert diag.occurrences == {"k": 3}
    expanded = np.eye(2) + k  # 1x1 operand expands MATLAB-style (one occurrence)
    assert expanded.shape == (2, 2) and expanded.occurrences == {"k": 1}
    np.testing.assert_allclose(usubs(expanded, {"k": 1.5}).M, np.eye(2) + 1.5, rtol=1e-14)


def test_statespace_and_tf_interop_on_both_sides():
    rng = np.random.default_rng(2)
    P = random_ss(rng, 2, 1, 1)
    T = control.tf([1, 2], [1, 3, 5])
    k = ureal("k", 1.0, percent=50)
    cases = [
        (P * k, lambda v: P * v),
        (k * P, lambda v: v * P),
        (T * k, lambda v: T * v),
        (k * T + P, lambda v: v * T + P),
        (P - k, lambda v: P - v),
        (as_lfr(T) / (1 + k), lambda v: T * (1 / (1 + v))),  # T / lfr: control raises TypeError
        (T * inv(1 + k), lambda v: T * (1 / (1 + v))),
    ]
    for sys, direct in cases:
        assert isinstance(sys, LFR)
        assert_response_close(
            usubs(sys, {"k": 1.3}).freqresp(OMEGA), control_response(direct(1.3), OMEGA)
        )


def test_hstack_vstack_append_indexing():
    rng = np.random.default_rng(3)
    P1, P2 = random_ss(rng, 2, 2, 1), random_ss(rng, 3, 2, 2)
    k = ureal("k", 1.0, percent=50)
    h = hstack([P1 * k, P2])
    v = vstack([(P1 * k)[0:1, :], P1])
    a = append(P1, k * P2)
    assert h.shape == (2, 3) and v.shape == (3, 1) and a.shape == (4, 3)
    kv = 0.7
    hv = usubs(h, {"k": kv}).freqresp(OMEGA)
    np.testing.assert_allclose(hv[..., :, :1], control_response(P1 * kv, OMEGA), rtol=1e-10)
    np.testing.assert_allclose(hv[..., :, 1:], control_response(P2, OMEGA), rtol=1e-10)
    vv = usubs(v, {"k": kv}).freqresp(OMEGA)
    np.testing.assert_allclose(
        vv[..., :1, :], control_response(P1 * kv, OMEGA)[..., :1, :], rtol=1e-10
    )
    av = usubs(a, {"k": kv}).freqresp(OMEGA)
    np.testing.assert_allclose(av[..., :2, :1], control_response(P1, OMEGA), rtol=1e-10)
    np.testing.assert_allclose(av[..., 2:, 1:], control_response(kv * P2, OMEGA), rtol=1e-10)
    np.testing.assert_allclose(av[..., :2, 1:], 0, atol=1e-14)
    sub = a[[3, 0], 1:]
    np.testing.assert_allclose(
        usubs(sub, {"k": kv}).freqresp(OMEGA), av[..., [3, 0], 1:], rtol=1e-12
    )
    with pytest.raises(ValueError, match="output index"):
        a[4, 0]


def test_inverse_and_power():
    rng = np.random.default_rng(4)
    P = random_ss(rng, 3, 2, 2, d_scale=1.0)
    P = control.ss(P.A, P.B, P.C, P.D + 2 * np.eye(2))
    k = ureal("k", 1.0, range=(0.5, 4.0))
    sys = inv(P * k)
    direct = control.ss(P * 2.5) ** -1
    assert_response_close(usubs(sys, {"k": 2.5}).freqresp(OMEGA), control_response(direct, OMEGA))
    sq = (P * k) ** 2
    assert_response_close(
        usubs(sq, {"k": 0.6}).freqresp(OMEGA), control_response((P * 0.6) * (P * 0.6), OMEGA)
    )
    with pytest.raises(ValueError, match="singular"):
        inv(as_lfr(control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]])))
    with pytest.raises(ValueError, match="square"):
        inv(as_lfr(np.ones((2, 1))))


def test_lower_lft_closes_a_controller():
    rng = np.random.default_rng(5)
    # generalized plant with 2 exogenous in/out, 1 control in/out
    P = random_ss(rng, 4, 3, 3)
    K = random_ss(rng, 2, 1, 1, d_scale=0.1)
    k = ureal("k", 1.0, percent=30)
    closed = lft(P * k, K)  # lower LFT: K closes the last output -> last input
    assert closed.shape == (2, 2)
    Pv = control.ss(P * 1.2)
    # independent: python-control interconnect of the loop u = K y
    P11, P12, P21, P22 = Pv[:2, :2], Pv[:2, 2:], Pv[2:, :2], Pv[2:, 2:]
    direct = P11 + P12 * control.feedback(K, P22, sign=1) * P21  # P12 K (I - P22 K)^-1 P21
    assert_response_close(
        usubs(closed, {"k": 1.2}).freqresp(OMEGA), control_response(direct, OMEGA), rtol=1e-8
    )


def test_upper_lft_with_delta_block():
    M = np.array([[0.3, 1.0], [2.0, 0.5]])
    D = ultidyn("D", (1, 1), bound=0.5)
    sys = lft(D, M)  # upper LFT: D closes the first channel of M
    assert sys.shape == (1, 1) and sys.occurrences == {"D": 1}
    value = 0.4  # |value| <= bound
    expected = M[1, 1] + M[1, 0] * value * M[0, 1] / (1 - M[0, 0] * value)
    assert usubs(sys, {"D": [[value]]}).M[0, 0] == pytest.approx(expected, rel=1e-13)


def test_dimension_mismatch_errors():
    k = ureal("k", 1.0)
    A = as_lfr(np.ones((2, 3)))
    with pytest.raises(ValueError, match="2 outputs cannot drive 3 inputs"):
        A * as_lfr(np.ones((2, 2)))
    with pytest.raises(ValueError, match="shapes"):
        A + as_lfr(np.ones((3, 2)))
    with pytest.raises(ValueError, match="feedback"):
        feedback(A, np.ones((2, 2)))
    with pytest.raises(ValueError, match="hstack"):
        hstack([A, np.ones((3, 1))])
    with pytest.raises(ValueError, match="vstack"):
        vstack([A, np.ones((1, 2))])
    with pytest.raises(ValueError, match="not well-posed"):
        feedback(as_lfr(1.0), as_lfr(1.0), sign=1)
    with pytest.raises(ValueError, match="improper"):
        k * control.tf([1, 0], [1])
    assert (k * 2).shape == (1, 1)


def test_immutability():
    k = ureal("k", 1.0)
    with pytest.raises(AttributeError):
        k.M = np.zeros((2, 2))
    with pytest.raises(ValueError):
        k.M[0, 0] = 1.0
