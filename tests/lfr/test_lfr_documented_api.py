"""Documented LFR API (docs/DESIGN.md "The LFR object", README "Python"), checked against
hand-built expectations: BLK rows and the size of M11 (D10), block scalings (D11), ``@`` between
LFRs (D18), refusals of ``to_ss`` (D29), ``from_parts`` / ``channel_slices`` (D33) and the
``blocks`` table (R31)."""

import control
import numpy as np
import pytest
from scipy.linalg import block_diag

from oos_drake.lfr import LFR, append, close_blocks, feedback, ucomplex, ultidyn, ureal, usubs
from oos_drake.lfr.blocks import UComplex, ULTIDyn, make_ureal_spec

TOL = 1e-12


# ---------------------------------------------------------------- D10: BLK rows and M11
def test_repeated_ureal_is_one_blk_row_minus_r():
    k = ureal("k", 2.0, percent=10)
    rep = k * np.eye(3)
    assert rep.occurrences == {"k": 3}
    np.testing.assert_array_equal(rep.blk, [[-3, 0]])


def test_mixed_structure_blk_rows_and_m11_size():
    k3 = ureal("k", 2.0, percent=10) * np.eye(3)  # real scalar repeated 3 times
    dyn = ultidyn("D", (2, 3))  # full 2x3 block: w has p = 2 rows, z has q = 3 rows
    c = ucomplex("c", 1.0 + 2.0j, 0.5)  # complex scalar, once
    sys = append(k3, dyn, c)
    # blocks sorted by name: D, c, k (uppercase first); MATLAB rows ultidyn [p, q],
    # ucomplex [r, 0], ureal [-r, 0]
    np.testing.assert_array_equal(sys.blk, [[2, 3], [1, 0], [-3, 0]])
    # M11 is sum(q) x sum(p): q = 3 + 1 + 3 = 7 rows, p = 2 + 1 + 3 = 6 columns
    assert (sys.nz, sys.nw) == (7, 6)
    assert sys.Dzw.shape == (7, 6)
    # the brief's two-block case
    two = append(k3, dyn)
    np.testing.assert_array_equal(two.blk, [[2, 3], [-3, 0]])
    assert (two.nz, two.nw) == (6, 5)


def test_repeated_ultidyn_gives_one_blk_row_per_repetition():
    dyn = ultidyn("D", (2, 1))
    twice = append(dyn, dyn)  # same name: two occurrences of the same full block
    assert twice.occurrences == {"D": 2}
    np.testing.assert_array_equal(twice.blk, [[2, 1], [2, 1]])
    assert twice.Dzw.shape == (2, 4)


# ---------------------------------------------------------------- D11: block scalings
def test_ultidyn_is_bound_times_delta():
    v = np.array([[0.3, -0.5]])  # normalized, gain < 1
    D = ultidyn("D", (1, 2), bound=4.0)
    np.testing.assert_allclose(usubs(D, {"D": v}, normalized=True).M, 4.0 * v, atol=TOL)
    # physical value = the block itself
    np.testing.assert_allclose(usubs(D, {"D": 4.0 * v}).M, 4.0 * v, atol=TOL)
    # used twice in series (2x1 gain after the 1x2 block): v' v scaled by bound^2
    G = ultidyn("G", (2, 1), bound=3.0)
    w = np.array([[0.6], [0.2]])
    product = usubs(G * D, {"G": w, "D": v}, normalized=True)
    np.testing.assert_allclose(product.M, 12.0 * (w @ v), atol=TOL)


def test_ucomplex_is_nominal_plus_radius_times_delta():
    nominal, radius = 1.0 + 2.0j, 0.5
    c = ucomplex("c", nominal, radius)
    for delta in (0.3 - 0.4j, 1.0, -1.0j, 0.0):
        value = nominal + radius * delta
        np.testing.assert_allclose(usubs(c, {"c": delta}, normalized=True).M, [[value]], atol=TOL)
        np.testing.assert_allclose(usubs(c, {"c": value}).M, [[value]], atol=TOL)
        # two occurrences in a product: closed form value^2 + 3 value
        expr = c * c + 3 * c
        np.testing.assert_allclose(
            usubs(expr, {"c": delta}, normalized=True).M, [[value**2 + 3 * value]], atol=1e-12
        )


# ---------------------------------------------------------------- D18: sys @ other
def _plant_and_controller():
    s = control.tf("s")
    m = ureal("m", 2.0, percent=10)
    k = ureal("k", 5.0, range=(4.0, 7.0))  # asymmetric: bilinear normalization
    g = ultidyn("g", (1, 1), bound=0.2)
    # P: 2 outputs, 3 inputs; K: 3 outputs, 2 inputs; both uncertain and dynamic
    mass_spring = feedback((1 / m) * control.tf(1, [1, 0.4, 0]), k)  # 1 / (m s^2 + 0.4 s + k)
    P = np.array([[1.0, 0.0, 0.5], [0.0, 2.0, -1.0]]) * mass_spring
    P = P + np.array([[0.0, 0.1, 0.0], [0.2, 0.0, 0.0]]) * (1 + g)
    K = np.array([[1.0, 0.0], [0.5, 1.0], [0.0, -2.0]]) * (k * ((s + 1) / (s + 10)))
    return P, K


def test_matmul_between_lfrs_is_the_series_connection():
    P, K = _plant_and_controller()
    assert P.shape == (2, 3) and K.shape == (3, 2)
    loop_at, loop_mul = P @ K, P * K
    assert loop_at.shape == (2, 2)
    assert set(P.uncertainty) == {"g", "k", "m"} and set(K.uncertainty) == {"k"}
    omega = np.logspace(-1, 2, 17)
    rng = np.random.default_rng(18)
    for _ in range(3):
        values = {
            "m": rng.uniform(1.8, 2.2),
            "k": rng.uniform(4.0, 7.0),
            "g": rng.uniform(-0.2, 0.2, (1, 1)),
        }
        Ps = usubs(P, values).to_ss()
        Ks = usubs(K, {name: values[name] for name in K.uncertainty}).to_ss()
        reference = control.series(Ks, Ps)  # python-control: Ps after Ks
        expected = np.moveaxis(reference.frequency_response(omega).frdata, -1, 0)
        np.testing.assert_allclose(
            usubs(loop_at, values).freqresp(omega), expected, rtol=1e-9, atol=1e-12
        )
        np.testing.assert_allclose(
            usubs(loop_mul, values).freqresp(omega), expected, rtol=1e-9, atol=1e-12
        )


# ---------------------------------------------------------------- D29: to_ss refusals
def test_to_ss_refuses_an_uncertain_lfr_naming_the_blocks():
    m = ureal("m", 2.0, percent=10)
    sys = (1 / m) * control.tf(1, [1, 0, 0])
    with pytest.raises(ValueError, match="m") as info:
        sys.to_ss()
    assert "\n" not in str(info.value)
    assert "uncertain" in str(info.value)


def test_to_ss_refuses_a_model_array_naming_its_shape():
    m = ureal("m", 2.0, percent=10)
    array = usubs((1 / m) * control.tf(1, [1, 0, 0]), {"m": np.array([1.9, 2.0, 2.1])})
    assert array.batch_shape == (3,) and not array.uncertainty
    with pytest.raises(ValueError, match=r"\(3,\)") as info:
        array.to_ss()
    assert "\n" not in str(info.value)
    # one model of it converts, and is the closed form 1 / (m s^2)
    one = array.model(2).to_ss()
    np.testing.assert_allclose(control.evalfr(one, 2.0j), 1 / (2.1 * (2.0j) ** 2), rtol=1e-12)


# ---------------------------------------------------------------- D33: from_parts, channel_slices
def test_from_parts_round_trips_the_partition_and_channel_slices_give_the_layout():
    rng = np.random.default_rng(33)
    n, ny, nu = 2, 2, 3
    a = make_ureal_spec("a", 1.0, plusminus=0.5)  # 1x1, repeated 2 times: z 2 rows, w 2 cols
    b = ULTIDyn("b", (3, 2), 1.0)  # 3x2 full block, once: w 3 rows (cols of M), z 2 rows
    blocks = [(b, 1), (a, 2)]  # given out of name order on purpose
    nz, nw = 2 + 2, 2 + 3
    parts = {
        "A": rng.standard_normal((n, n)),
        "Bw": rng.standard_normal((n, nw)),
        "Bu": rng.standard_normal((n, nu)),
        "Cz": rng.standard_normal((nz, n)),
        "Cy": rng.standard_normal((ny, n)),
        "Dzw": 0.1 * rng.standard_normal((nz, nw)),
        "Dzu": rng.standard_normal((nz, nu)),
        "Dyw": rng.standard_normal((ny, nw)),
        "Dyu": rng.standard_normal((ny, nu)),
    }
    sys = LFR.from_parts(**parts, blocks=blocks)
    for name, value in parts.items():
        np.testing.assert_array_equal(getattr(sys, name), value, err_msg=name)
    assert (sys.nstates, sys.nz, sys.nw, sys.shape) == (n, nz, nw, (ny, nu))
    assert sys.occurrences == {"a": 2, "b": 1}
    # name order: a first (z rows 0..1, w cols 0..1), then b (z rows 2..3, w cols 2..4)
    slices = sys.channel_slices()
    assert list(slices) == ["a", "b"]
    assert slices["a"] == (slice(0, 2), slice(0, 2))
    assert slices["b"] == (slice(2, 4), slice(2, 5))
    # the slices are the channels each block closes: Fu(M, blkdiag(I/s, Delta)) by hand,
    # Delta = blkdiag(delta_a I_2, delta_b) in the order of channel_slices
    delta_a, delta_b = 0.7, rng.standard_normal((3, 2)) * 0.3
    Delta = np.zeros((nw, nz))
    Delta[slices["a"][1], slices["a"][0]] = delta_a * np.eye(2)
    Delta[slices["b"][1], slices["b"][0]] = delta_b
    closed = usubs(sys, {"a": delta_a, "b": delta_b}, normalized=True)
    loop = np.linalg.solve(np.eye(nw) - Delta @ parts["Dzw"], Delta)  # (I - Delta Dzw)^-1 Delta
    A = parts["A"] + parts["Bw"] @ loop @ parts["Cz"]
    B = parts["Bu"] + parts["Bw"] @ loop @ parts["Dzu"]
    C = parts["Cy"] + parts["Dyw"] @ loop @ parts["Cz"]
    D = parts["Dyu"] + parts["Dyw"] @ loop @ parts["Dzu"]
    s = 0.5j
    expected = C @ np.linalg.solve(s * np.eye(n) - A, B) + D
    np.testing.assert_allclose(closed.freqresp([0.5])[0], expected, rtol=1e-10, atol=1e-12)
    # close_blocks takes the same normalized values and is the same loop
    direct = close_blocks(sys, {"a": delta_a, "b": delta_b})
    np.testing.assert_allclose(direct.freqresp([0.5])[0], expected, rtol=1e-10, atol=1e-12)
    # closing one block keeps the other with its channels
    only_a = close_blocks(sys, {"a": delta_a})
    assert only_a.occurrences == {"b": 1} and only_a.channel_slices() == {
        "b": (slice(0, 2), slice(0, 3))
    }
    # the same with a block-diagonal Delta assembled in BLK order (BLK rows: [-2, 0], [3, 2])
    np.testing.assert_array_equal(sys.blk, [[-2, 0], [3, 2]])
    np.testing.assert_array_equal(block_diag(delta_a * np.eye(2), delta_b), Delta)


# ---------------------------------------------------------------- R31: blocks table
def test_blocks_table_documented_columns_kind_and_nominal():
    sys = append(
        ureal("m", 2.0, percent=10) * np.eye(2),
        ucomplex("c", 1.0 + 2.0j, 0.5),
        ultidyn("D", (2, 3), bound=4.0),
    )
    table = sys.blocks
    assert list(table.columns[:5]) == ["name", "kind", "repetitions", "nominal", "range"]
    rows = table.set_index("name")
    assert list(rows.index) == ["D", "c", "m"]
    assert rows.loc["m", "kind"] == "ureal" and rows.loc["m", "nominal"] == 2.0
    assert rows.loc["c", "kind"] == "ucomplex" and rows.loc["c", "nominal"] == 1.0 + 2.0j
    assert rows.loc["D", "kind"] == "ultidyn" and rows.loc["D", "nominal"] == 0.0
    assert rows.loc["m", "repetitions"] == 2 and rows.loc["c", "repetitions"] == 1
    lo, hi = rows.loc["m", "range"]
    assert (lo, hi) == pytest.approx((1.8, 2.2), abs=1e-15)
    assert isinstance(sys.uncertainty["c"], UComplex)


def test_blocks_table_has_exactly_the_documented_columns():
    sys = ureal("m", 2.0, percent=10) + ucomplex("c", 1.0, 0.5)
    documented = ["name", "kind", "repetitions", "nominal", "range", "radius", "shape"]
    assert list(sys.blocks.columns) == [*documented, "quantity", "unit"]  # README, DESIGN.md
