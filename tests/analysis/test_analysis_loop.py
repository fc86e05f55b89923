"""The uncertain closed loop against the control package's (independently assembled) loop."""

import numpy as np
import pytest

from oos_drake.control.analysis_model import MULTIPLICATIVE_BLOCKS, close_loop
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import plant_statespace, weighted_interconnection
from oos_drake.control.plants import flexible_rotational_plant
from oos_drake.lfr import LFR, ureal, usubs


def _plant():
    """Rigid hub + two flexible modes, T -> wdot (3x3), as a certain LFR and raw matrices."""
    J0 = np.diag([300.0, 250.0, 200.0])
    L = np.array([[4.0, 1.0], [0.5, 3.0], [1.0, -2.0]])
    A, B, C, D = flexible_rotational_plant(J0, L, 2 * np.pi * np.array([0.6, 1.3]), 0.01)
    return A, B, C, D


K = np.hstack([np.diag([1.2, 1.0, 0.9]), np.diag([30.0, 25.0, 20.0])])


def test_nominal_loop_equals_control_interconnection():
    A, B, C, D = _plant()
    spec = DesignSpecification()
    closed = close_loop(LFR.from_ss(A, B, C, D), K, spec)
    ref = weighted_interconnection(plant_statespace(A, B, C, D), spec).close(K)
    w = np.logspace(-3, 1.5, 60)
    np.testing.assert_allclose(closed.nominal.freqresp(w), ref.freqresp(w), rtol=1e-7, atol=1e-8)


def test_additive_and_multiplicative_blocks_act_as_documented():
    """Delta_add = X, Delta_mul_xy = m: the control loop around (P + W X)(I + W_R m E_xy)."""
    A, B, C, D = _plant()
    spec = DesignSpecification()
    closed = close_loop(LFR.from_ss(A, B, C, D), K, spec)
    X = np.array([[0.3, -0.2, 0.1], [0.5, 0.0, -0.7], [0.2, 0.4, 0.6]])
    m = 0.8
    sub = usubs(closed, {"Delta_add": X * 1.0, "Delta_mul_xy": np.array([[m]])})
    # the hand-made perturbed plant
    W = 10 ** (spec.additive_weight_db / 20)
    F = np.eye(3)
    F[0, 1] += spec.multiplicative_off_diagonal * m
    Dp = (D + W * X) @ F
    ref = weighted_interconnection(plant_statespace(A, B @ F, C, Dp), spec).close(K)
    w = np.logspace(-3, 1.5, 40)
    np.testing.assert_allclose(sub.nominal.freqresp(w), ref.freqresp(w), rtol=1e-7, atol=1e-8)
    assert set(MULTIPLICATIVE_BLOCKS) <= set(closed.uncertainty)


def test_bad_gain_is_refused():
    A, B, C, D = _plant()
    with pytest.raises(ValueError, match="3x6"):
        close_loop(LFR.from_ss(A, B, C, D), np.ones((3, 3)))


def test_real_blocks_of_the_plant_are_kept():
    A, B, C, D = _plant()
    k = ureal("k_gain", 1.0, percent=10)
    closed = close_loop(k * LFR.from_ss(A, B, C, D), K)
    assert "k_gain" in closed.uncertainty


def test_subsets_follow_the_blocks_quantities_not_their_names():
    """A renamed block keeps its subset; a name that looks modal does not make a block modal."""
    import control

    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.lfr import ultidyn, ureal

    s = control.tf("s")
    sys = (
        ureal("flex_mode_a", 8.0, percent=20, unit="rad/s", quantity="modal frequency")
        * (1 / (s + 1))
        + ureal("w1_not_modal", 25.0, percent=10, unit="kg", quantity="mass") * (1 / (s + 2))
        + ultidyn("u_add", (1, 1), unit="-", quantity="additive dynamics")
        + ultidyn("Delta_add", (1, 1), unit="-", quantity="multiplicative dynamics")
    )
    subsets = uncertainty_subsets(sys.uncertainty)
    assert subsets["modal"] == ["flex_mode_a"]
    assert subsets["mechanical"] == ["w1_not_modal"]
    assert subsets["real"] == ["flex_mode_a", "w1_not_modal"]
    assert subsets["additive"] == ["u_add"]
    assert subsets["multiplicative"] == ["Delta_add"]
    # the mission blocks keep their subsets when renamed
    from dataclasses import replace

    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.model import physical_blocks

    blocks = physical_blocks(load_scenario("paper"))
    renamed = {f"p{i}": replace(b, name=f"p{i}") for i, b in enumerate(blocks.values())}
    original = uncertainty_subsets(blocks)
    again = uncertainty_subsets(renamed)
    lookup = {f"p{i}": name for i, name in enumerate(blocks)}
    for subset, members in original.items():
        assert sorted(lookup[m] for m in again[subset]) == members
    assert set(original) == {"total", "real", "modal", "mechanical"}
