"""Structured reduction, .mat export."""

import control
import numpy as np
import pytest
import scipy.io
from lfr_helpers import assert_response_close, control_response, random_ss

from oos_drake.lfr import (
    LFR,
    append,
    feedback,
    inv,
    lft,
    ultidyn,
    ureal,
    usubs,
)

OMEGA = np.array([0.1, 0.8, 3.0, 20.0])


def test_reduce_removes_redundant_occurrences_and_states():
    m = ureal("m", 2.0, percent=10)
    assert (m + m).reduce().occurrences == {"m": 1}
    K = np.outer([1.0, 2.0, 3.0], [1.0, -1.0, 0.5])
    rank_one = m * K
    assert rank_one.occurrences == {"m": 3}
    reduced = rank_one.reduce()
    assert reduced.occurrences == {"m": 1}
    np.testing.assert_allclose(usubs(reduced, {"m": 2.15}).M, 2.15 * K, rtol=1e-12, atol=1e-12)
    # m*I3 in series twice: m^2 I3 needs 2 occurrences per channel, nothing to remove
    squared = (m * np.eye(3)) * (m * np.eye(3))
    assert squared.reduce().occurrences == {"m": 6}
    # duplicated dynamics: two copies of the same uncertain plant in parallel
    s = control.tf("s")
    plant = inv(m) * (1 / (s + 1)) * (1 / s)
    twice = plant + plant
    r = twice.reduce()
    assert twice.nstates == 4 and r.nstates == 2
    assert r.occurrences == {"m": 1}
    for mv in (1.8, 2.2):
        np.testing.assert_allclose(
            usubs(r, {"m": mv}).freqresp(OMEGA), usubs(twice, {"m": mv}).freqresp(OMEGA), rtol=1e-10
        )


def test_reduce_model_array_common_basis():
    m = ureal("m", 2.0, percent=10)
    k = ureal("k", 1.0, percent=10)
    s = control.tf("s")
    P = inv(m) * (1 / s**2)
    arr = usubs(P + P * k + P * k, {"k": np.array([0.9, 1.0, 1.1])})
    red = arr.reduce()
    assert arr.nstates == 6 and red.nstates == 2 and red.occurrences == {"m": 1}
    np.testing.assert_allclose(
        usubs(red, {"m": 2.1}).freqresp(OMEGA), usubs(arr, {"m": 2.1}).freqresp(OMEGA), rtol=1e-10
    )


def test_reduce_random_algebra_keeps_response():
    rng = np.random.default_rng(7)
    a = ureal("a", 1.0, range=(0.5, 3.0))
    b = ureal("b", -1.0, percent=30)
    P1, P2 = random_ss(rng, 3, 2, 2), random_ss(rng, 2, 2, 2)
    sys = feedback(P1 * a + P2 * b, P2 * a) + P1 * a * b
    red = sys.reduce()
    assert red.nstates <= sys.nstates and sum(red.occurrences.values()) <= sum(
        sys.occurrences.values()
    )
    values = {"a": np.array([0.5, 1.3, 3.0]), "b": np.array([-1.3, -0.8, -0.7])}
    np.testing.assert_allclose(
        usubs(red, values).freqresp(OMEGA),
        usubs(sys, values).freqresp(OMEGA),
        rtol=1e-9,
        atol=1e-12,
    )


def test_reduce_keeps_ultidyn_blocks():
    D = ultidyn("D", (1, 2), bound=0.3)
    k = ureal("k", 1.0)
    sys = D * np.array([[1.0], [1.0]]) * (k + k)
    red = sys.reduce()
    assert red.occurrences["D"] == 1 and red.occurrences["k"] == 1
    value = np.array([[0.1, -0.2]])
    np.testing.assert_allclose(
        usubs(red, {"D": value, "k": 1.5}).M, usubs(sys, {"D": value, "k": 1.5}).M, atol=1e-12
    )


def test_to_mat_round_trip(tmp_path):
    m = ureal("m", 2.0, percent=10, unit="kg", quantity="mass")
    c = ureal("c", 0.3, range=(0.1, 0.4))
    D = ultidyn("Dyn", (1, 1), bound=0.1)
    s = control.tf("s")
    sys = feedback(inv(m) * (1 / s) * (1 + D), c) * (1 / s)
    path = tmp_path / "model.mat"
    sys.to_mat(path)
    data = scipy.io.loadmat(path)
    n = int(data["nstates"].squeeze())
    assert n == sys.nstates
    np.testing.assert_allclose(data["A"], sys.M[:n, :n])
    np.testing.assert_allclose(data["D"], sys.M[n:, n:])
    # blocks sorted by name (Python string order: "Dyn" < "c" < "m")
    np.testing.assert_array_equal(data["blk"], [[1, 1], [-1, 0], [-1, 0]])
    names = [str(np.ravel(x)[0]) for x in np.ravel(data["block_names"])]
    assert names == ["Dyn", "c", "m"]
    np.testing.assert_allclose(data["lower"].ravel()[[1, 2]], [0.1, 1.8])
    # rebuild the LFR by hand from the file: Fu(M, blkdiag(I/s, Delta)) at given deltas
    rebuilt = LFR(np.block([[data["A"], data["B"]], [data["C"], data["D"]]]), n, sys.block_entries)
    vals = {"m": 2.1, "c": 0.2, "Dyn": [[0.05]]}
    np.testing.assert_allclose(
        usubs(rebuilt, vals).freqresp(OMEGA), usubs(sys, vals).freqresp(OMEGA), rtol=1e-12
    )


def test_star_product_general_sizes():
    rng = np.random.default_rng(11)
    P = random_ss(rng, 2, 3, 3)
    Q = random_ss(rng, 2, 2, 2, d_scale=0.0)  # no algebraic loop for control.interconnect
    star = lft(P, Q, nu=1, ny=1)
    assert star.shape == (3, 3)
    # independent: close the loop with python-control's interconnect of named signals
    Pn = control.ss(P, inputs=["p0", "p1", "p2"], outputs=["q0", "q1", "q2"], name="P")
    Qn = control.ss(Q, inputs=["q2", "r1"], outputs=["p2", "s1"], name="Q")
    ic = control.interconnect([Pn, Qn], inplist=["p0", "p1", "r1"], outlist=["q0", "q1", "s1"])
    assert_response_close(star.freqresp(OMEGA), control_response(ic, OMEGA), rtol=1e-9)
    assert append(P, Q).shape == (5, 5)


def test_load_lfr_round_trips_mat_and_npz_model_arrays(tmp_path):
    from oos_drake.lfr import load_lfr

    m = ureal("m", 2.0, percent=10, unit="kg", quantity="mass")
    c = ureal("c", 0.3, range=(0.1, 0.4))
    D = ultidyn("Dyn", (1, 1), bound=0.1)
    s = control.tf("s")
    sys = (feedback(inv(m) * (1 / s) * (1 + D), c) * (1 / s)).with_names(
        inputs=["F"], outputs=["x"]
    )
    for model in (sys, usubs(sys, {"m": np.array([1.9, 2.0, 2.1])})):
        for writer, suffix in ((model.to_mat, "mat"), (model.to_npz, "npz")):
            path = tmp_path / f"model.{suffix}"
            writer(path)
            back = load_lfr(path)
            np.testing.assert_array_equal(back.M, model.M)
            assert back.block_entries == model.block_entries
            assert back.input_names == ("F",) and back.output_names == ("x",)
    with pytest.raises(ValueError, match="not an LFR file"):
        np.savez(tmp_path / "other.npz", A=np.eye(2))
        load_lfr(tmp_path / "other.npz")


def test_to_mat_model_array_is_matlab_shaped_and_reads_back(tmp_path):
    """A model array is written as MATLAB stores it (A(:, :, k) is model k) and read back."""
    from oos_drake.lfr.matfile import read_mat

    k = ureal("k", 2.0, percent=20, unit="N/m", quantity="stiffness")
    s = control.tf("s")
    sys = usubs(k * (1 / (s + 1)) + ureal("g", 1.0, percent=10), {"g": [0.95, 1.0, 1.05, 1.1]})
    assert sys.batch_shape == (4,)
    path = tmp_path / "array.mat"
    sys.to_mat(path)
    raw = scipy.io.loadmat(path)
    n = sys.nstates
    assert raw["D"].shape == sys.M[0, n:, n:].shape + (4,)
    for j in range(4):
        np.testing.assert_allclose(raw["D"][:, :, j], sys.M[j, n:, n:])
    back = read_mat(path, matrices="ABCD")
    np.testing.assert_allclose(back["D"], sys.M[..., n:, n:])
    units = [str(np.ravel(x)[0]) for x in np.ravel(raw["block_units"])]
    quantities = [str(np.ravel(x)[0]) for x in np.ravel(raw["block_quantities"])]
    assert units == ["N/m"] and quantities == ["stiffness"]
