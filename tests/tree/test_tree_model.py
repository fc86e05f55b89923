"""TITOP LFR of a tree against closed forms: one rigid body, the frozen tree's inertia, M_P(s)."""

from __future__ import annotations

import numpy as np
import pytest
from appendage_oracle import effective_mass_model  # tests/ is on sys.path
from tree_documents import boom_document, shipped_document

from oos_drake.lfr import usubs
from oos_drake.scenario.tree import load_tree, parse_tree
from oos_drake.scenario.tree_model import (
    build_tree_model,
    rigid_inertia_at_root,
    tree_blocks,
    tree_values,
)


def _dc_gain(system):
    return system.D - system.C @ np.linalg.solve(system.A, system.B)


def test_single_rigid_body_is_inverse_inertia():
    """A tree of one rigid body: xdd_G = diag(m I3, J_G)^-1 W_G, whatever p_B_G."""
    document = shipped_document("flexible_satellite")
    document["bodies"] = document["bodies"][:1]
    document["ports"] = {}
    document.pop("mission")  # it drives the arrays removed here
    model = build_tree_model(parse_tree(document))
    inertia = np.array([[180.0, 2.0, -1.0], [2.0, 150.0, 1.5], [-1.0, 1.5, 210.0]])
    expected = np.zeros((6, 6))
    expected[:3, :3] = np.eye(3) / 300.0
    expected[3:, 3:] = np.linalg.inv(inertia)
    assert model.nstates == 0 and not model.uncertainty
    np.testing.assert_allclose(model.nominal.to_ss().D, expected, rtol=1e-13, atol=1e-16)


def test_hub_with_one_fixed_appendage_is_closed_form():
    """Hub + one appendage fixed at P: xdd_G = (D_G + tau^T T^T M_P(s) T tau)^-1 W, by hand."""
    document = shipped_document("flexible_satellite")
    hub, array = document["bodies"][:2]
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # quarter turn about z
    array["joint"] = {
        "type": "fixed",
        "p_parent_joint": [0.3, 0.9, 0.8],
        "R_parent_joint": R.tolist(),
    }
    document["bodies"] = [hub, array]
    document.pop("mission")  # it drives SA2 (removed) and SA1 (now fixed)
    tree = parse_tree(document)
    body = tree.body("SA1")
    s = 1j * 2 * np.pi * np.array([0.05, 0.49, 1.0, 3.3, 12.0])
    M_P = effective_mass_model(
        s, body.rigid_spatial_inertia, body.participation.T, body.omega, body.damping_ratios
    )
    p_GP = np.array([0.3, 0.9, 0.8]) - np.array([0.0, 0.0, 0.8])
    tau = np.eye(6)
    tau[:3, 3:] = -np.array(
        [[0, -p_GP[2], p_GP[1]], [p_GP[2], 0, -p_GP[0]], [-p_GP[1], p_GP[0], 0]]
    )
    T = np.kron(np.eye(2), R.T)  # hub axes -> array axes
    D_G = np.diag([300.0] * 3 + [0.0] * 3)
    D_G[3:, 3:] = np.array([[180.0, 2.0, -1.0], [2.0, 150.0, 1.5], [-1.0, 1.5, 210.0]])
    expected = np.linalg.inv(D_G + tau.T @ T.T @ M_P @ T @ tau)
    response = build_tree_model(tree).nominal.freqresp(np.imag(s))
    np.testing.assert_allclose(response, expected, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("name", ["flexible_satellite", "geo_satellite", "boom"])
def test_static_gain_is_inverse_rigid_inertia(name):
    tree = parse_tree(boom_document()) if name == "boom" else load_tree(name)
    angles = {b: 0.4 + 0.3 * k for k, b in enumerate(tree.revolute_bodies)}
    model = usubs(build_tree_model(tree), tree_values(tree, angles)).nominal.to_ss()
    np.testing.assert_allclose(
        _dc_gain(model) @ rigid_inertia_at_root(tree, angles), np.eye(6), atol=1e-10
    )


def test_blocks_named_from_bodies():
    tree = load_tree("geo_satellite")
    model = build_tree_model(tree)
    occurrences = model.occurrences
    for name in ("w1_SA_N", "w1_SA_S", "w1_REFL_E", "w2_REFL_E", "w3_REFL_E", "w1_REFL_W"):
        assert occurrences[name] == 2
    assert occurrences["tau_SA_N"] == occurrences["tau_SA_S"] == 16
    assert occurrences["m_HUB"] == 3 and occurrences["Jzz_HUB"] == 1
    blocks = tree_blocks(tree)
    assert "tau_SA_N" not in blocks
    w2 = blocks["w2_REFL_E"]
    np.testing.assert_allclose(w2.range, (2 * np.pi * 1.3, 2 * np.pi * 1.8), rtol=1e-14)
    np.testing.assert_allclose(blocks["w1_SA_N"].range, 2 * np.pi * 0.12 * np.array([0.8, 1.2]))
    assert model.nstates == 2 * (3 + 3 + 3 + 2)
    assert build_tree_model(tree, rotational=True).shape == (3, 3)


def test_file_angles_are_the_default_values():
    tree = load_tree("flexible_satellite")
    np.testing.assert_allclose(tree_values(tree)["tau_SA1"], np.tan(0.3 / 4), rtol=1e-15)
    with pytest.raises(ValueError, match="HUB: not a body on a revolute joint"):
        tree_values(tree, {"HUB": 1.0})
