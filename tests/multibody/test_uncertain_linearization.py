"""ulinearize on the shipped servicer SDF vs an LFR derived by hand; robstab vs a pole sweep."""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.lfr import LFR, feedback, hstack, inv, lft, ureal, usubs, vstack  # noqa: E402
from oos_drake.multibody.uncertain_linearization import (  # noqa: E402
    ExtractionOptions,
    PhysicalParameter,
    _extract,
    load_parameters,
    sdf_plant,
    ulinearize,
)

ROOT = Path(__file__).resolve().parents[2]
SDF = ROOT / "examples" / "servicer" / "servicer.sdf"
PARAMETERS = ROOT / "examples" / "servicer" / "servicer_parameters.toml"
INPUTS = "servicer_actuation"  # Fx, Fy (hub_x, hub_y) [N], Tz (hub_yaw) [N m]
OUTPUTS = "servicer_state[0,1,2,7,8,9]"  # x, y [m], yaw [rad], their rates
OMEGA = np.logspace(-2, 3, 300)  # rad/s


@pytest.fixture(scope="module")
def extracted():
    plant, context = sdf_plant(SDF)
    return ulinearize(plant, context, load_parameters(PARAMETERS), INPUTS, OUTPUTS)


def hand_lfr(declared):
    """The servicer's linear model written by hand from the SDF's numbers (closed form).

    Generalized coordinates ``q = [x, y, yaw, phi, x_r, y_r, yaw_r]`` (hub translation and yaw,
    panel hinge, client planar joint in the dock frame). At ``q = 0`` the velocity Jacobians
    (rows ``v_x, v_y, omega_z``) of the centres of mass are: hub ``[e_x; e_y; e_yaw]``; panel
    (CoM 2.5 m along x from the hub CoM, 1.5 m from the hinge) ``[e_x; e_y + 2.5 e_yaw + 1.5
    e_phi; e_yaw + e_phi]``; client (CoM 1.5 m along -x, 0.5 m from the dock)
    ``[e_x + e_xr; e_y - 1.5 e_yaw + e_yr - 0.5 e_yawr; e_yaw + e_yawr]``.
    ``M = sum J^T diag(m, m, I_zz) J``; the hinge spring ``400 (w / 6)^2`` and damper
    ``2 (w / 6)`` act on ``phi``; the bushing's force stiffness/damping (20 N s/m) on ``x_r,
    y_r`` and its torsion about z (damping 5 N m s/rad) on ``yaw_r``. Each parameter enters
    through an explicit low-rank factor, which gives its repetitions by hand.
    """
    p = {d.name: ureal(d.name, d.nominal, range=(d.lower, d.upper)) for d in declared}
    e = np.eye(7)
    J_hub_t = e[[0, 1]]  # translation rows of the hub's Jacobian
    J_panel = np.array([e[0], e[1] + 2.5 * e[2] + 1.5 * e[3], e[2] + e[3]])
    J_client = np.array([e[0] + e[4], e[1] - 1.5 * e[2] + e[5] - 0.5 * e[6], e[2] + e[6]])
    M_fixed = J_panel.T @ np.diag([10.0, 10.0, 8.0]) @ J_panel + 6.0 * np.outer(
        J_client[2], J_client[2]
    )
    M = (
        M_fixed
        + J_hub_t.T @ (p["m_hub"] * np.eye(2)) @ J_hub_t
        + e[[2]].T @ p["Izz_hub"] @ e[[2]]
        + J_client[:2].T @ (p["m_client"] * np.eye(2)) @ J_client[:2]
    )
    # forces on [q; v]: -K q - D v, the hinge row by Horner: w (w a + b)
    Z = np.zeros((7, 7))
    KD_fixed = np.hstack([Z, -np.diag([0, 0, 0, 0, 20.0, 20.0, 5.0])])
    a = -400.0 / 36.0 * np.concatenate([e[3], np.zeros(7)])[None, :]
    b = -2.0 / 6.0 * np.concatenate([np.zeros(7), e[3]])[None, :]
    hinge = e[[3]].T @ p["w_panel"] @ (p["w_panel"] * a + b)
    S_xy = np.hstack([e[[4, 5]], np.zeros((2, 7))])
    S_r = np.concatenate([e[6], np.zeros(7)])[None, :]
    KD = (
        KD_fixed
        + hinge
        - S_xy.T[:7] @ (p["k_dock"] * np.eye(2)) @ S_xy
        - e[[6]].T @ p["kt_dock"] @ S_r
    )
    B = e[:, :3]
    vdot = inv(M) * hstack([KD, B])  # [q; v; u] -> v'
    qdot = np.hstack([Z, np.eye(7), np.zeros((7, 3))])
    xdot = vstack([qdot, vdot])  # [x; u] -> x'
    perm = np.zeros((17, 17))
    perm[:14, 3:] = np.eye(14)
    perm[14:, :3] = np.eye(3)
    C = np.eye(14)[[0, 1, 2, 7, 8, 9]]
    S = vstack([np.hstack([np.zeros((6, 3)), C]), xdot * perm])  # [u; x] -> [y; x']
    integrator = LFR.from_ss(np.zeros((14, 14)), np.eye(14), np.eye(14), np.zeros((14, 14)))
    return lft(S, integrator, 14, 14)


def relative_error(G, H, values, normalized=False):
    a = usubs(G, values, normalized=normalized).nominal.freqresp(OMEGA)
    b = usubs(H, values, normalized=normalized).nominal.freqresp(OMEGA)
    worst = np.linalg.norm(a - b, ord=2, axis=(-2, -1)).max(axis=-1)
    return worst / np.linalg.norm(b, ord=2, axis=(-2, -1)).max(axis=-1)


def test_extracted_lfr_equals_the_hand_lfr(extracted):
    declared = load_parameters(PARAMETERS)
    hand = hand_lfr(declared)
    # repetitions: the ranks of the hand factors (planar masses 2, yaw inertia 1, hinge mode
    # w I2, bushing force stiffness on x and y 2, torsion 1)
    assert extracted.occurrences == hand.occurrences == {
        "Izz_hub": 1, "k_dock": 2, "kt_dock": 1, "m_client": 2, "m_hub": 2, "w_panel": 2,
    }  # fmt: skip
    rng = np.random.default_rng(18)
    names = [d.name for d in declared]
    inside = {
        d.name: rng.uniform(d.lower, d.upper, 40) for d in declared
    }  # physical values in the ranges
    assert relative_error(extracted, hand, inside).max() < 1e-9
    # normalized values up to 1.8 outside the ranges (same ureal normalization on both sides,
    # including the off-centre range of w_panel, bilinear)
    outside = {name: rng.uniform(-1.8, 1.8, 40) for name in names}
    assert relative_error(extracted, hand, outside, normalized=True).max() < 1e-9
    assert relative_error(extracted, hand, {}).max() < 1e-12 + 1e-9


@pytest.mark.parametrize("scaled", [False, True])
def test_extracted_lfr_matches_drake_at_the_context_values(scaled):
    """Setting the parameters in the Context and linearizing plainly gives the same model: in
    Drake's states, or with the hinge angle scaled by ``w / w0`` (``x = S x~``: ``S^-1 A S``)."""
    from pydrake.systems.primitives import FirstOrderTaylorApproximation

    plant, context = sdf_plant(SDF)
    declared = load_parameters(PARAMETERS)
    G = ulinearize(plant, context, declared, INPUTS, OUTPUTS, prune=False,
                   scale_modal_states=scaled)  # fmt: skip
    values = {"m_hub": 95.0, "Izz_hub": 32.0, "w_panel": 5.2, "k_dock": 2300.0,
              "kt_dock": 400.0, "m_client": 58.0}  # fmt: skip
    plant_context = plant.GetMyMutableContextFromRoot(context)
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia

    hub, client = plant.GetBodyByName("hub"), plant.GetBodyByName("client")
    hub.SetSpatialInertiaInBodyFrame(
        plant_context,
        SpatialInertia.MakeFromCentralInertia(95.0, np.zeros(3), RotationalInertia(20, 20, 32)),
    )
    client.SetSpatialInertiaInBodyFrame(
        plant_context,
        SpatialInertia.MakeFromCentralInertia(58.0, np.zeros(3), RotationalInertia(5, 5, 6)),
    )
    from pydrake.multibody.tree import ForceElementIndex, LinearBushingRollPitchYaw, RevoluteSpring

    for i in range(plant.num_force_elements()):
        element = plant.get_force_element(ForceElementIndex(i))
        if isinstance(element, RevoluteSpring):
            element.SetStiffness(plant_context, 400.0 * (5.2 / 6.0) ** 2)
        if isinstance(element, LinearBushingRollPitchYaw):
            element.SetForceStiffnessConstants(plant_context, [2300.0] * 3)
            element.SetTorqueStiffnessConstants(plant_context, [100.0, 100.0, 400.0])
    plant.GetJointByName("panel_hinge").SetDampingVector(plant_context, [2.0 * 5.2 / 6.0])
    port = plant.GetInputPort(INPUTS)
    port.FixValue(plant_context, np.zeros(3))
    taylor = FirstOrderTaylorApproximation(
        plant, context, input_port_index=port.get_index(),
        output_port_index=plant.GetOutputPort("servicer_state").get_index(),
    )  # fmt: skip
    rows = [0, 1, 2, 7, 8, 9]
    A, B, C = taylor.A(), taylor.B(), taylor.C()[rows]
    if scaled:
        hinge = plant.GetJointByName("panel_hinge").position_start()  # the plant's state = [q; v]
        S = np.eye(A.shape[0])
        S[hinge, hinge] = 6.0 / 5.2  # q = (w0 / w) q~
        A, B, C = np.linalg.solve(S, A @ S), np.linalg.solve(S, B), C @ S
    reference = np.block([[A, B], [C, taylor.D()[rows]]])
    model = usubs(G, values).nominal
    np.testing.assert_allclose(model.M, reference, rtol=0, atol=1e-9 * np.abs(reference).max())


def test_robstab_agrees_with_a_dense_pole_sweep(extracted):
    """Closed loop with a lagged PD controller: every perturbation that the dense sweep finds
    destabilizing is larger than the certified margin, and the returned destabilizing
    perturbation puts a pole on the imaginary axis."""
    from oos_drake.robust import robstab

    tau, kp, kd = 0.3, np.diag([200.0, 200.0, 600.0]), np.diag([400.0, 400.0, 300.0])
    K = LFR.from_ss(-np.eye(3) / tau, np.hstack([kp, kd]) / tau, -np.eye(3), np.zeros((3, 6)))
    loop = feedback(extracted, K, sign=1)
    result = robstab(loop)
    assert result.nominal_stable and 1.0 < result.lower <= result.upper < 10.0
    names = sorted(extracted.uncertainty)
    rng = np.random.default_rng(7)
    # directions: the box's corners and random points, at radii up to 1.2 x the upper bound
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * len(names))).reshape(len(names), -1).T
    directions = np.vstack([corners, rng.uniform(-1, 1, (4000, len(names)))])
    directions /= np.abs(directions).max(axis=1, keepdims=True)
    radii = rng.uniform(0.0, 1.2 * result.upper, directions.shape[0])
    radii[: corners.shape[0]] = 0.999 * result.lower  # corners just inside the certificate
    deltas = directions * radii[:, None]
    models = usubs(loop, {n: deltas[:, k] for k, n in enumerate(names)}, normalized=True)
    unstable = np.linalg.eigvals(np.asarray(models.nominal.A)).real.max(axis=-1) >= 0
    assert not np.any(unstable & (radii < result.lower)), "certified margin violated"
    worst = usubs(loop, result.worst_case_normalized, normalized=True).nominal
    closest = np.abs(np.linalg.eigvals(np.asarray(worst.A)) - 1j * result.critical_frequency).min()
    assert closest < 1e-6 * max(1.0, result.critical_frequency)


def test_modal_frequency_is_affine_in_the_scaled_states():
    """``w_panel`` (spring ``400 (w/6)^2``, damper ``2 w/6``) enters Drake's coordinates as
    ``w^2``: two cascaded channels, the second reading only the first (a nilpotent self-loop
    in ``M11``). With the hinge angle scaled by ``w / w0`` it is affine: the LFR is a polynomial
    of degree 1 in ``delta`` (the model at ``delta = 1/2`` is the mean of those at 0 and 1)."""
    plant, context = sdf_plant(SDF)
    declared = [p for p in load_parameters(PARAMETERS) if p.name == "w_panel"]
    # a centred range (affine normalization), so that affine in w is affine in delta
    centred = [PhysicalParameter("w_panel", declared[0].element, "frequency", 6.0, 5.0, 7.0)]

    def matrices(scaled):
        G = ulinearize(plant, context, centred, INPUTS, OUTPUTS, scale_modal_states=scaled)
        return [np.asarray(usubs(G, {"w_panel": d}, normalized=True).nominal.M)
                for d in (0.0, 0.5, 1.0)]  # fmt: skip

    for scaled, affine in ((True, True), (False, False)):
        m0, m_half, m1 = matrices(scaled)
        curvature = np.abs(m_half - 0.5 * (m0 + m1)).max() / np.abs(m1 - m0).max()
        assert (curvature < 1e-10) == affine, (scaled, curvature)


def test_channel_basis_is_canonical():
    """The channels are balanced on input-output Gram matrices only: the extracted LFR with
    its states and each block's channels transformed at random (an exact equivalent, as the
    TITOP LFR is for the twin's) is balanced to the same channels."""
    from oos_drake.multibody.uncertain_linearization import _balance_channels

    plant, context = sdf_plant(SDF)
    G = ulinearize(plant, context, load_parameters(PARAMETERS), INPUTS, OUTPUTS)
    rng = np.random.default_rng(5)
    n, nz, M = G.nstates, G.nz, np.array(G.M)
    L = np.eye(M.shape[0])  # rows [x'; z; y]
    L[:n, :n] = rng.standard_normal((n, n)) + 3 * np.eye(n)  # state coordinates
    start = n
    for entry in G.block_entries:  # each block's channels: z -> T z, w -> T w
        k = slice(start, start + entry.reps)
        start += entry.reps
        L[k, k] = rng.standard_normal((entry.reps, entry.reps)) + 2 * np.eye(entry.reps)
    R = np.eye(M.shape[1])  # columns [x; w; u]
    R[: n + nz, : n + nz] = np.linalg.inv(L[: n + nz, : n + nz])
    other = LFR(L @ M @ R, n, G.block_entries,
                input_names=G.input_names, output_names=G.output_names)  # fmt: skip
    assert np.abs(np.asarray(other.M) - M).max() > 1e-2 * np.abs(M).max()  # really different

    def response(sys, omega):  # [z; y] <- [w; u]
        Ms = np.asarray(sys.M)
        A, B, C, D = Ms[:n, :n], Ms[:n, n:], Ms[n:, :n], Ms[n:, n:]
        return np.array([D + C @ np.linalg.solve(1j * w * np.eye(n) - A, B) for w in omega])

    omega = np.array([0.3, 2.0, 9.0])  # rad/s
    a = response(_balance_channels(G), omega)
    b = response(_balance_channels(other), omega)
    # the same channels, signs included (fixed by each channel's driven response): a model
    # array's neighbouring configurations get neighbouring channels
    assert np.abs(b - a).max() < 1e-8 * np.abs(a).max()
    assert np.abs(response(other, omega) - a).max() > 1e-2 * np.abs(a).max()  # it mattered


# ----------------------------------------------------------------------------- bad input
def test_unknown_names_and_bad_ranges_are_refused():
    plant, context = sdf_plant(SDF)
    good = load_parameters(PARAMETERS)
    with pytest.raises(ValueError, match="no body named 'hubb'"):
        ulinearize(plant, context, [PhysicalParameter("m", "hubb", "mass", 1, 0.5, 2)],
                   INPUTS, OUTPUTS)  # fmt: skip
    with pytest.raises(ValueError, match="no joint named 'hinge2'"):
        ulinearize(plant, context, [PhysicalParameter("w", "hinge2", "frequency", 6, 5, 7)],
                   INPUTS, OUTPUTS)  # fmt: skip
    with pytest.raises(ValueError, match="no bushing between frames 'dock' and 'x'"):
        ulinearize(plant, context, [PhysicalParameter("k", "dock/x", "force_stiffness", 1, 0.5, 2)],
                   INPUTS, OUTPUTS)  # fmt: skip
    with pytest.raises(ValueError, match="makes the mass of 'hub' non-positive"):
        PhysicalParameter("m", "hub", "mass", 1.0, -0.5, 2.0)
    with pytest.raises(ValueError, match="makes the torque_stiffness_z of 'dock/client_dock'"):
        PhysicalParameter("k", "dock/client_dock", "torque_stiffness_z", 10.0, 0.0, 20.0)
    with pytest.raises(ValueError, match="no input port 'thrust'"):
        ulinearize(plant, context, good, "thrust", OUTPUTS)
    with pytest.raises(ValueError, match="no output port 'hub_state'"):
        ulinearize(plant, context, good, INPUTS, "hub_state")
    with pytest.raises(
        ValueError, match="'Ixx_hub' does not change the linearization"
    ):  # planar: Ixx does not enter
        ulinearize(plant, context, [PhysicalParameter("Ixx_hub", "hub", "Ixx", 20, 18, 22)],
                   INPUTS, OUTPUTS)  # fmt: skip


def test_non_equilibrium_context_is_refused():
    plant, context = sdf_plant(SDF)
    plant.GetJointByName("panel_hinge").set_angle(plant.GetMyMutableContextFromRoot(context), 0.1)
    with pytest.raises(ValueError, match="not an equilibrium"):
        ulinearize(plant, context, load_parameters(PARAMETERS), INPUTS, OUTPUTS)


@dataclass
class _Binding:
    parameter: PhysicalParameter


@dataclass
class _RationalProblem:
    """A 1-DOF model whose output reads ``1 / (1 + k)``: not polynomial in ``k``."""

    bindings: tuple = (_Binding(PhysicalParameter("k", "spring", "stiffness", 2.0, 1.0, 3.0)),)
    inputs: tuple = ((None, np.arange(1), "u"),)
    outputs: tuple = ((None, np.arange(1), "y"),)
    velocity_rows: np.ndarray = field(default_factory=lambda: np.array([1]))

    @property
    def nominal(self):
        return np.array([2.0])

    def acceleration_map(self):
        return None

    def linearize(self, values):
        k = float(values[0])
        return {
            "A": np.array([[0.0, 1.0], [-k, -0.1]]), "B": np.array([[0.0], [1.0]]),
            "C": np.array([[1.0 / (1.0 + k), 0.0]]), "D": np.zeros((1, 1)),
            "M": np.eye(1), "xdot": np.zeros(2),
        }  # fmt: skip


def test_non_polynomial_dependence_is_refused_naming_the_parameter():
    with pytest.raises(ValueError, match=r"parameter 'k': .* not polynomial of degree <= 2 in it"):
        _extract(
            _RationalProblem(), ExtractionOptions(rtol=1e-9, check_points=2, check_tolerance=1e-7)
        )


# ----------------------------------------------------------------------------- command line
def _cli(args):
    from oos_drake.app.main import main

    return main(["ulinearize", str(SDF), *args])


def test_cli_writes_mat_and_npz_that_load_back(tmp_path, capsys):
    import scipy.io

    from oos_drake.lfr import load_lfr

    out = tmp_path / "servicer"
    status = _cli(["--parameters", str(PARAMETERS), "--input", INPUTS, "--output", OUTPUTS,
                   "--out", str(out)])  # fmt: skip
    assert status == 0, capsys.readouterr().err
    plant, context = sdf_plant(SDF)
    direct = ulinearize(plant, context, load_parameters(PARAMETERS), INPUTS, OUTPUTS)
    for suffix in ("mat", "npz"):
        loaded = load_lfr(out / f"lfr.{suffix}")
        assert loaded.occurrences == direct.occurrences
        np.testing.assert_array_equal(loaded.M, direct.M)
        assert loaded.input_names == direct.input_names
    data = scipy.io.loadmat(out / "lfr.mat")
    # MATLAB mussv BLK rows [-r 0], blocks sorted by name: Izz_hub, k_dock, kt_dock, m_client,
    # m_hub, w_panel
    np.testing.assert_array_equal(
        data["blk"], [[-1, 0], [-2, 0], [-1, 0], [-2, 0], [-2, 0], [-2, 0]]
    )


@pytest.mark.parametrize(
    ("edit", "port", "message"),
    [
        (('element = "hub"', 'element = "hubb"'), None, "no body named 'hubb'"),
        (('element = "panel_hinge"', 'element = "hinge"'), None, "no joint named 'hinge'"),
        (("nominal = 100.0\npercent = 10", "nominal = 100.0\npercent = 120"), None,
         "makes the mass of 'hub' non-positive"),
        (("nominal = 500.0\npercent = 30", "nominal = 500.0\nrange = [-10.0, 600.0]"), None,
         "makes the torque_stiffness_z of 'dock/client_dock' non-positive"),
        (("nominal = 2000.0\npercent = 20", "nominal = 2000.0\nrange = [0.0, 4000.0]"), None,
         "makes the force_stiffness of 'dock/client_dock' non-positive"),
        (('element = "dock/client_dock"', 'element = "dock/client"'), None,
         "no bushing between frames 'dock' and 'client'"),
        (None, ("--input", "thrusters"), "no input port 'thrusters'"),
        (None, ("--output", "hub_state"), "no output port 'hub_state' on 'MultibodyPlant'"),
        (None, ("--output", "servicer_state[40]"), "selection outside its 14 entries"),
    ],
)  # fmt: skip
def test_cli_bad_input_exit_2_and_nothing_written(tmp_path, capsys, edit, port, message):
    text = PARAMETERS.read_text()
    if edit is not None:
        assert edit[0] in text
        text = text.replace(edit[0], edit[1], 1)
    parameters = tmp_path / "parameters.toml"
    parameters.write_text(text)
    ports = {"--input": INPUTS, "--output": OUTPUTS}
    if port is not None:
        ports[port[0]] = port[1]
    out = tmp_path / "out"
    args = ["--parameters", str(parameters), "--out", str(out)]
    for flag, value in ports.items():
        args += [flag, value]
    assert _cli(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_oos_robust_robstab_reads_a_stored_closed_loop(extracted, tmp_path, capsys):
    from oos_drake.app.main import main
    from oos_drake.robust import robstab

    K = LFR.from_ss(-np.eye(3) / 0.3, np.hstack([np.eye(3) * 200, np.eye(3) * 300]) / 0.3,
                    -np.eye(3), np.zeros((3, 6)))  # fmt: skip
    loop = feedback(extracted, K, sign=1)
    loop.to_npz(tmp_path / "loop.npz")
    assert main(["robust", "robstab", str(tmp_path / "loop.npz")]) == 0
    text = capsys.readouterr().out
    result = robstab(loop)
    assert f"stability margin in [{result.lower:.6g}, {result.upper:.6g}]" in text


def test_readme_servicer_snippet_runs(monkeypatch, capsys):
    import re

    text = (ROOT / "README.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, re.DOTALL) if "ulinearize" in b]
    assert len(blocks) == 1
    monkeypatch.chdir(ROOT)
    namespace = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)
    result = namespace["result"]
    assert 1.0 < result.lower <= result.upper
    assert "stability margin in [" in capsys.readouterr().out
