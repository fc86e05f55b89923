"""ureal / ucomplex / ultidyn semantics (MATLAB Robust Control Toolbox) and their errors."""

import numpy as np
import pytest

from oos_drake.lfr import ucomplex, ultidyn, ureal, usubs


def physical(block_lfr, delta):
    """Value of a 1x1 atom LFR at normalized ``delta`` by closing the LFT by hand."""
    M = block_lfr.M
    return M[1, 1] + M[1, 0] * delta * M[0, 1] / (1.0 - M[0, 0] * delta)


def test_percent_plusminus_range_match_matlab_definitions():
    spec = ureal("m", 2.0, percent=10).uncertainty["m"]
    assert spec.range == pytest.approx((1.8, 2.2), rel=1e-15)
    spec = ureal("m", -2.0, percent=10).uncertainty["m"]  # |nominal| is used
    assert spec.range == pytest.approx((-2.2, -1.8), rel=1e-15)
    spec = ureal("c", 3.0, plusminus=0.5).uncertainty["c"]
    assert spec.range == (2.5, 3.5)
    spec = ureal("c", 3.0, plusminus=[-0.5, 1.0]).uncertainty["c"]
    assert spec.range == (2.5, 4.0)
    spec = ureal("c", 10.0, percent=[-10, 30]).uncertainty["c"]
    assert spec.range == pytest.approx((9.0, 13.0), rel=1e-15)
    spec = ureal("k", 3.0).uncertainty["k"]  # MATLAB default PlusMinus 1
    assert spec.range == (2.0, 4.0)


def test_symmetric_range_is_affine_like_matlab_actual2normalized():
    # MATLAB doc: a = ureal('a',3,'range',[1 5]); actual2normalized(a,[1 3 5]) -> [-1 0 1],
    # [2 4] -> [-0.5 0.5], [0 6] -> [-1.5 1.5]; normalized2actual(a,[-1.5 1.5]) -> [0 6]
    a = ureal("a", 3.0, range=(1, 5))
    spec = a.uncertainty["a"]
    np.testing.assert_allclose(spec.to_normalized([1, 3, 5]), [-1, 0, 1], atol=1e-15)
    np.testing.assert_allclose(spec.to_normalized([2, 4]), [-0.5, 0.5], atol=1e-15)
    np.testing.assert_allclose(spec.to_normalized([0, 6], check=False), [-1.5, 1.5], atol=1e-15)
    np.testing.assert_allclose(spec.to_physical([-1.5, 1.5]), [0, 6], atol=1e-15)
    assert spec.is_affine
    assert a.M[0, 0] == 0.0
    for delta in (-1.0, -0.3, 0.0, 0.7, 1.0):
        assert physical(a, delta) == pytest.approx(3.0 + 2.0 * delta, rel=1e-14)


@pytest.mark.parametrize("nominal, lo, hi", [(2.0, 1.0, 5.0), (4.0, 1.0, 5.0), (-1.0, -10.0, 0.5)])
def test_asymmetric_range_bilinear_map(nominal, lo, hi):
    b = ureal("b", nominal, range=(lo, hi))
    spec = b.uncertainty["b"]
    assert not spec.is_affine
    # MATLAB's normalization: end points -> -1/+1, nominal -> 0, one occurrence
    assert b.occurrences == {"b": 1}
    for delta, expected in ((-1.0, lo), (0.0, nominal), (1.0, hi)):
        assert physical(b, delta) == pytest.approx(expected, rel=1e-13, abs=1e-13)
        assert spec.to_physical(delta) == pytest.approx(expected, rel=1e-13, abs=1e-13)
    # the map is a Moebius transform: cross-ratio of 4 points is preserved
    d = np.array([-1.0, -0.2, 0.0, 0.6])
    p = spec.to_physical(d)

    def cross(x):
        return (x[0] - x[2]) * (x[1] - x[3]) / ((x[0] - x[3]) * (x[1] - x[2]))

    assert cross(p) == pytest.approx(cross(d), rel=1e-12)
    # monotone on [-1, 1] and inverse of to_normalized
    grid = np.linspace(-1, 1, 41)
    values = spec.to_physical(grid)
    assert np.all(np.diff(values) > 0)
    np.testing.assert_allclose(spec.to_normalized(values), grid, atol=1e-12)
    # substitution of physical values reproduces them exactly
    np.testing.assert_allclose(usubs(b, {"b": values}).M[:, 0, 0], values, rtol=1e-13, atol=1e-13)


def test_ucomplex_and_ultidyn_atoms():
    c = ucomplex("c", 1.0 + 2.0j, 0.5)
    assert physical(c, 1j) == pytest.approx(1.0 + 2.5j, rel=1e-14)
    assert c.blk.tolist() == [[1, 0]]
    d = ultidyn("D", (2, 3), bound=4.0)
    assert d.shape == (2, 3) and d.nz == 3 and d.nw == 2
    assert d.blk.tolist() == [[2, 3]]
    value = np.array([[1.0, 0, 0], [0, -2.0, 0]])
    np.testing.assert_allclose(usubs(d, {"D": value}).M, value, atol=1e-14)


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        (dict(name="m", nominal=2.0, range=(2.5, 3.0)), "m"),
        (dict(name="m", nominal=2.0, range=(1.0, 2.0)), "2"),
        (dict(name="m", nominal=2.0, percent=-5), "-5"),
        (dict(name="m", nominal=2.0, plusminus=-1), "-1"),
        (dict(name="m", nominal=0.0, percent=10), "m"),
        (dict(name="m", nominal=2.0, percent=10, plusminus=1), "m"),
        (dict(name="", nominal=2.0), "name"),
    ],
)
def test_ureal_errors_name_block_and_value(kwargs, fragment):
    with pytest.raises(ValueError) as info:
        ureal(kwargs.pop("name"), kwargs.pop("nominal"), **kwargs)
    assert fragment in str(info.value)


def test_nominal_outside_range_message():
    with pytest.raises(ValueError, match=r"ureal 'stiff'.*nominal 7 outside its range \[1, 5\]"):
        ureal("stiff", 7.0, range=(1, 5))
    with pytest.raises(ValueError, match=r"percent must be >= 0, got -3"):
        ureal("stiff", 7.0, percent=-3)


def test_other_block_errors():
    with pytest.raises(ValueError, match="radius"):
        ucomplex("c", 1.0, -1.0)
    with pytest.raises(ValueError, match="bound"):
        ultidyn("D", (1, 1), bound=0.0)
    with pytest.raises(ValueError, match="shape"):
        ultidyn("D", (0, 2))


def test_unit_and_quantity_travel_through_the_algebra():
    """Unit and quantity set at creation survive products, merges, usubs, lftdata and reduce."""
    import control

    from oos_drake.lfr import feedback, inv, lftdata

    m = ureal("m", 2.0, percent=10, unit="kg", quantity="mass")
    k = ureal("k", 100.0, plusminus=20.0, unit="N/m", quantity="stiffness")
    dyn = ultidyn("D", (1, 1), unit="-", quantity="additive dynamics")
    s = control.tf("s")
    plant = feedback(inv(m) * (1 / s) * (1 / s), k)  # 1 / (m s^2 + k)
    sys = plant * (1 + 0.1 * dyn) + 0.01 * m  # m occurs twice: merged by name
    assert sys.occurrences["m"] == 2
    expected = {
        "D": ("-", "additive dynamics"),
        "k": ("N/m", "stiffness"),
        "m": ("kg", "mass"),
    }
    facts = {n: (b.unit, b.quantity) for n, b in sys.uncertainty.items()}
    assert facts == expected
    table = sys.blocks.set_index("name")
    assert table.loc["m", "unit"] == "kg" and table.loc["k", "quantity"] == "stiffness"
    left = usubs(sys, {"k": 110.0})
    assert {n: (b.unit, b.quantity) for n, b in left.uncertainty.items()} == {
        n: expected[n] for n in ("D", "m")
    }
    _, Delta = lftdata(sys)
    assert {n: (b.unit, b.quantity) for n, b in Delta.uncertainty.items()} == expected
    assert {n: (b.unit, b.quantity) for n, b in sys.reduce().uncertainty.items()} == expected


def test_block_without_facts_merges_with_one_that_has_them_and_conflicts_are_errors():
    plain = ureal("m", 2.0, percent=10)
    described = ureal("m", 2.0, percent=10, unit="kg", quantity="mass")
    merged = plain + described
    assert merged.occurrences["m"] == 2
    assert (merged.uncertainty["m"].unit, merged.uncertainty["m"].quantity) == ("kg", "mass")
    with pytest.raises(ValueError, match="'m' is defined twice differently"):
        described + ureal("m", 2.0, percent=10, unit="g", quantity="mass")
    with pytest.raises(ValueError, match="unknown quantity 'weight'"):
        ureal("m", 2.0, quantity="weight")
