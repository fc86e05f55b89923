"""robstab's destabilizing perturbation on a model extracted with ``oos ulinearize``.

``tests/robust/data/sprung_hub.sdf`` (a hub on a yaw joint, a panel on a sprung revolute
hinge, a boom on a prismatic slide held by a bushing; written for this test, not by the LFR
code) is extracted by the ``oos ulinearize`` command, closed with a PD behind a first-order lag,
and robstab's worst case is compared with the first instabilities of the box's vertices and
1000 random directions, then substituted in Drake's own linearization: a pole on the axis.
"""

from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.lfr import LFR, feedback, load_lfr, usubs  # noqa: E402
from oos_drake.robust import robstab  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "robust" / "data"
SDF = DATA / "sprung_hub.sdf"
KP, KD, TAU = 4000.0, 4000.0, 0.15  # PD [N m/rad, N m s/rad] behind a lag [s]


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    from oos_drake.app.main import main

    out = tmp_path_factory.mktemp("ulinearize")
    args = ["ulinearize", str(SDF), "--parameters", str(DATA / "sprung_hub_parameters.toml")]
    args += ["--input", "sprung_hub_actuation", "--output", "sprung_hub_state[0,3]"]
    assert main([*args, "--out", str(out), "--name", "hub"]) == 0
    plant = load_lfr(out / "hub.npz")
    controller = LFR.from_ss(
        np.array([[-1.0 / TAU]]), np.array([[KP, KD]]) / TAU, np.array([[-1.0]]), np.zeros((1, 2))
    )
    return feedback(plant, controller, sign=1)


def _abscissa(loop, names, X):
    """Spectral abscissa of ``A + Bw Delta (I - Dzw Delta)^{-1} Cz`` (the LFR's definition)
    at the normalized parameters of each row of ``X`` (no range check: sizes beyond 1)."""
    A, Bw, Cz, Dzw = (np.asarray(m) for m in (loop.A, loop.Bw, loop.Cz, loop.Dzw))
    slices = loop.channel_slices()
    out = []
    for x in X:
        delta = np.zeros((Dzw.shape[1], Dzw.shape[0]))
        for value, name in zip(x, names, strict=True):
            z, w = slices[name]
            delta[w, z] = value * np.eye(w.stop - w.start)
        Acl = A + Bw @ delta @ np.linalg.solve(np.eye(Dzw.shape[0]) - Dzw @ delta, Cz)
        out.append(np.linalg.eigvals(Acl).real.max())
    return np.array(out)


def test_robstab_worst_case_against_box_search_and_drake(loop):
    from pydrake.multibody.tree import (
        ForceElementIndex,
        LinearBushingRollPitchYaw,
        RevoluteSpring,
        RotationalInertia,
        SpatialInertia,
    )
    from pydrake.systems.primitives import FirstOrderTaylorApproximation

    from oos_drake.multibody.uncertain_linearization import sdf_plant

    res = robstab(loop, guaranteed=False)
    names = list(loop.uncertainty)
    k = len(names)
    rng = np.random.default_rng(4)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    R = rng.uniform(-1, 1, (1000, k))
    D = np.vstack([V, R / np.abs(R).max(axis=1, keepdims=True)])
    # no vertex or random direction is unstable at 0.995 times robstab's destabilizing size
    assert _abscissa(loop, names, 0.995 * res.upper * D).max() < 0
    # Drake's linearization at the worst case (physical values), closed by the same controller
    wc = res.worst_case
    plant, context = sdf_plant(SDF)
    pc = plant.GetMyMutableContextFromRoot(context)

    def inertia(body, mass, com, rotational):
        plant.GetBodyByName(body).SetSpatialInertiaInBodyFrame(
            pc, SpatialInertia.MakeFromCentralInertia(mass, np.array(com), rotational)
        )

    inertia("hub", 200.0, [0, 0, 0], RotationalInertia(40, 40, wc["Izz_hub"]))
    inertia("panel_a", wc["m_panel"], [1.5, 0, 0], RotationalInertia(1, 12, 12))
    inertia("boom_b", wc["m_boom"], [-1.0, 0, 0], RotationalInertia(1, 8, 8))
    w = wc["w_hinge"]  # hinge spring 300 (w / 4)^2, damping 3 w / 4
    for i in range(plant.num_force_elements()):
        element = plant.get_force_element(ForceElementIndex(i))
        if isinstance(element, RevoluteSpring):
            element.SetStiffness(pc, 300.0 * (w / 4.0) ** 2)
        if isinstance(element, LinearBushingRollPitchYaw):
            element.SetForceStiffnessConstants(pc, [1500.0, wc["k_boom"], 1500.0])
            element.SetForceDampingConstants(pc, [12.0, wc["c_boom"], 12.0])
    plant.GetJointByName("panel_a_hinge").SetDampingVector(pc, [3.0 * w / 4.0])
    port = plant.GetInputPort("sprung_hub_actuation")
    port.FixValue(pc, np.zeros(1))
    taylor = FirstOrderTaylorApproximation(
        plant, context, input_port_index=port.get_index(),
        output_port_index=plant.GetOutputPort("sprung_hub_state").get_index(),
    )  # fmt: skip
    yaw = plant.GetJointByName("hub_yaw")
    rows = [yaw.position_start(), plant.num_positions() + yaw.velocity_start()]
    A, B, C = taylor.A(), taylor.B(), taylor.C()[rows]
    Acl = np.block([[A, B], [-(np.array([[KP, KD]]) @ C) / TAU, -np.eye(1) / TAU]])
    poles = np.linalg.eigvals(Acl)
    scale = np.abs(poles).max()
    assert np.min(np.abs(poles - 1j * res.critical_frequency)) < 1e-7 * scale
    assert poles.real.max() < 1e-9 * scale


def test_servicer_worst_case_not_beyond_the_vertices():
    """The shipped servicer example with a PD behind a lag on three axes: the power iteration
    alone stopped 3 % beyond the first unstable vertex; the worst case is no longer there."""
    from oos_drake.multibody.uncertain_linearization import load_parameters, sdf_plant, ulinearize

    root = Path(__file__).resolve().parents[2] / "examples" / "servicer"
    plant, context = sdf_plant(root / "servicer.sdf")
    G = ulinearize(
        plant, context, load_parameters(root / "servicer_parameters.toml"),
        "servicer_actuation", "servicer_state[0,1,2,7,8,9]",
    )  # fmt: skip
    K = LFR.from_ss(-np.eye(3) / 0.3, np.hstack([np.eye(3) * 200, np.eye(3) * 300]) / 0.3,
                    -np.eye(3), np.zeros((3, 6)))  # fmt: skip
    closed = feedback(G, K, sign=1)
    res = robstab(closed, guaranteed=False)
    names = list(closed.uncertainty)
    k = len(names)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    R = np.random.default_rng(8).uniform(-1, 1, (1000, k))
    D = np.vstack([V, R / np.abs(R).max(axis=1, keepdims=True)])
    assert _abscissa(closed, names, 0.995 * res.upper * D).max() < 0
    one = usubs(closed, res.worst_case_normalized, normalized=True)  # beyond the ranges
    poles = np.linalg.eigvals(np.asarray(one.A))
    assert np.min(np.abs(poles - 1j * res.critical_frequency)) < 1e-7 * np.abs(poles).max()
