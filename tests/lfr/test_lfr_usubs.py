"""usubs (vectorized, partial, errors), nominal, usample."""

import control
import numpy as np
import pytest
from lfr_helpers import assert_response_close, control_response, random_ss

from oos_drake.lfr import LFR, feedback, inv, ucomplex, ultidyn, ureal, usample, usubs

OMEGA = np.array([0.05, 0.5, 2.0, 11.0])


def spring_mass():
    """x'' = (u - c x' - k x) / m built from the algebra; states (v, x)."""
    m = ureal("m", 2.0, percent=20)
    c = ureal("c", 0.3, range=(0.1, 0.4))  # asymmetric -> bilinear
    k = ureal("k", 5.0, plusminus=1.0)
    integ = control.tf(1, [1, 0])
    velocity = feedback(inv(m) * integ, c + k * integ)
    return velocity * integ, (m, c, k)


def direct_spring_mass(mv, cv, kv):
    return control.tf(1, [mv, cv, kv])


def test_vectorized_equals_per_sample_loop():
    sys, _ = spring_mass()
    rng = np.random.default_rng(0)
    N = 7
    values = {
        "m": rng.uniform(1.6, 2.4, N),
        "c": rng.uniform(0.1, 0.4, N),
        "k": rng.uniform(4.0, 6.0, N),
    }
    batch = usubs(sys, values)
    assert batch.batch_shape == (N,) and batch.is_certain
    resp = batch.freqresp(OMEGA)
    assert resp.shape == (N, OMEGA.size, 1, 1)
    for i in range(N):
        one = usubs(sys, {name: v[i] for name, v in values.items()})
        np.testing.assert_allclose(batch.model(i).M, one.M, rtol=1e-13, atol=1e-13)
        expected = control_response(direct_spring_mass(*(values[n][i] for n in "mck")), OMEGA)
        assert_response_close(resp[i], expected, rtol=1e-10)


def test_partial_substitution_keeps_other_blocks():
    sys, _ = spring_mass()
    part = usubs(sys, {"k": np.array([4.5, 5.5])})
    assert part.batch_shape == (2,)
    assert part.occurrences == {"c": sys.occurrences["c"], "m": sys.occurrences["m"]}
    rest = usubs(part, {"m": 2.2, "c": 0.15})
    full = usubs(sys, {"k": np.array([4.5, 5.5]), "m": 2.2, "c": 0.15})
    np.testing.assert_allclose(rest.M, full.M, rtol=1e-12, atol=1e-13)
    for i, kv in enumerate((4.5, 5.5)):
        assert_response_close(
            rest.model(i).freqresp(OMEGA),
            control_response(direct_spring_mass(2.2, 0.15, kv), OMEGA),
        )


def test_nominal_is_delta_zero():
    sys, _ = spring_mass()
    assert_response_close(
        sys.nominal.freqresp(OMEGA), control_response(direct_spring_mass(2.0, 0.3, 5.0), OMEGA)
    )
    # freqresp of an uncertain model is its nominal response (MATLAB behaviour)
    np.testing.assert_allclose(sys.freqresp(OMEGA), sys.nominal.freqresp(OMEGA), rtol=1e-14)


def test_normalized_substitution():
    sys, _ = spring_mass()
    phys = usubs(sys, {"c": 0.4, "m": 1.6})
    norm = usubs(sys, {"c": 1.0, "m": -1.0}, normalized=True)
    np.testing.assert_allclose(norm.M, phys.M, rtol=1e-13, atol=1e-13)


def test_broadcasting_grid_of_values():
    k = ureal("k", 1.0, percent=50)
    g = ureal("g", 3.0, percent=10)
    sys = k * g + k
    kv = np.linspace(0.5, 1.5, 3)[:, None]
    gv = np.array([2.7, 3.3])[None, :]
    out = usubs(sys, {"k": kv, "g": gv})
    assert out.batch_shape == (3, 2)
    np.testing.assert_allclose(out.M[..., 0, 0], kv * gv + kv, rtol=1e-14)


def test_complex_and_ultidyn_substitution():
    rng = np.random.default_rng(1)
    P = random_ss(rng, 3, 2, 2)
    c = ucomplex("c", 1.0, 0.5)
    D = ultidyn("D", (2, 2), bound=0.2)
    sys = P * (c * np.eye(2) + D)
    value = np.array([[0.1, 0.05], [-0.02, 0.1]])
    out = usubs(sys, {"c": 1.2 + 0.3j, "D": value})
    expected = control_response(P, OMEGA) @ ((1.2 + 0.3j) * np.eye(2) + value)
    np.testing.assert_allclose(out.freqresp(OMEGA), expected, rtol=1e-10)


def test_usubs_errors_name_block_and_value():
    sys, _ = spring_mass()
    with pytest.raises(ValueError, match=r"unknown block name 'mass'"):
        usubs(sys, {"mass": 2.0})
    with pytest.raises(ValueError, match=r"ureal 'm': value 2\.5 outside its range \[1\.6, 2\.4\]"):
        usubs(sys, {"m": 2.5})
    with pytest.raises(ValueError, match=r"ureal 'c': value 0\.05 outside"):
        usubs(sys, {"c": np.array([0.2, 0.05, 0.3])})
    with pytest.raises(ValueError, match="ucomplex 'z'"):
        usubs(ucomplex("z", 0.0, 1.0), {"z": 2.0})
    with pytest.raises(ValueError, match="ultidyn 'D'.*exceeds bound"):
        usubs(ultidyn("D", (1, 1), 0.5), {"D": [[0.8]]})
    with pytest.raises(ValueError, match="ultidyn 'D'.*shape"):
        usubs(ultidyn("D", (1, 1), 0.5), {"D": [[0.1, 0.1]]})
    with pytest.raises(ValueError, match="mapping"):
        usubs(sys, [("m", 2.0)])


def test_usample_draws_in_range_and_matches_table():
    sys, _ = spring_mass()
    models, table = usample(sys, 50, np.random.default_rng(3))
    assert models.batch_shape == (50,) and models.is_certain
    assert list(table.columns) == ["c", "k", "m"]
    assert table["m"].between(1.6, 2.4).all() and table["c"].between(0.1, 0.4).all()
    again = usubs(sys, {name: table[name].to_numpy() for name in table.columns})
    np.testing.assert_allclose(again.M, models.M, rtol=1e-13, atol=1e-13)
    models2, table2 = usample(sys, 50, np.random.default_rng(3))
    np.testing.assert_array_equal(table2.to_numpy(), table.to_numpy())
    with pytest.raises(ValueError, match="Generator"):
        usample(sys, 3, None)


def test_model_array_algebra_broadcasts():
    k = ureal("k", 2.0, percent=10)
    arr = usubs(k, {"k": np.array([1.9, 2.1])})
    combo = arr * ureal("g", 1.0) + 1.0
    assert combo.batch_shape == (2,)
    np.testing.assert_allclose(usubs(combo, {"g": 1.5}).M[:, 0, 0], [1.9 * 1.5 + 1, 2.1 * 1.5 + 1])
    assert isinstance(arr.model(1), LFR)


def test_pickle_round_trip_and_numpy_scalar_operands():
    import pickle

    sys, _ = spring_mass()
    again = pickle.loads(pickle.dumps(sys))
    assert again.occurrences == sys.occurrences
    np.testing.assert_array_equal(again.M, sys.M)
    k = ureal("k", 2.0)
    scaled = np.float64(3.0) * k
    assert isinstance(scaled, LFR)
    assert usubs(scaled, {"k": 2.5}).M[0, 0] == pytest.approx(7.5)


def test_lftdata_round_trip_and_dynamic_ultidyn_substitution():
    from oos_drake.lfr import lft, lftdata

    rng = np.random.default_rng(4)
    P = random_ss(rng, 2, 1, 1)
    D = ultidyn("D", (2, 1), bound=0.5)
    k = ureal("k", 1.0, range=(0.5, 3.0))
    sys = P * k * (1 + np.ones((1, 2)) @ D)
    M, Delta = lftdata(sys)
    assert M.is_certain and M.shape == (1 + 1 + 1, 1 + 2 + 1)  # z: k, D(1);  w: k, D(2)
    assert Delta.occurrences == {"D": 1, "k": 1}
    vals = {"k": 0.4, "D": [[0.3], [-0.6]]}
    np.testing.assert_allclose(
        usubs(lft(Delta, M), vals, normalized=True).freqresp(OMEGA),
        usubs(sys, vals, normalized=True).freqresp(OMEGA),
        rtol=1e-12,
    )
    # a dynamic value for the ultidyn block (physical: includes the bound)
    dyn = control.ss([[-2.0]], [[1.0]], [[0.2], [0.1]], [[0.0], [0.05]])
    out = usubs(sys, {"D": dyn, "k": 2.0})
    direct = control.series(dyn, control.ss([], [], [], np.ones((1, 2))))  # [1 1] * dyn
    expected = control_response(P * 2.0 * (1 + direct), OMEGA)
    np.testing.assert_allclose(out.freqresp(OMEGA), expected, rtol=1e-10)
    with pytest.raises(ValueError, match="only ultidyn"):
        usubs(sys, {"k": dyn})


def test_mismatched_batch_shapes_name_the_block():
    k = ureal("k", 1.0, percent=50)
    g = ureal("g", 3.0, percent=10)
    with pytest.raises(ValueError, match="block 'k'"):
        usubs(k * g, {"g": np.array([2.8, 3.1]), "k": np.array([1.0, 1.1, 1.2])})
