"""The on-orbit-servicing scenario as one LFR (paper section 2, Figs. complete_lft and compact_lft).

:func:`build_mission_model` assembles the TITOP blocks of the chaser hub RH1, its arrays SA1, SA2,
the UR5-like arm (links L0..L6, joints alpha_1..6), the target hub RH2 with its arrays SA3, SA4 and
the two connection switches into one LFR

.. math::

    \\ddot x_{G_1} = F_u(M(s), \\Delta_P)\\, W_{ext, G_1}, \\qquad
    \\Delta_P = \\mathrm{diag}(\\Delta_{w_1..4}, \\Delta_{\\theta_1..4}, \\Delta_{RA},
    \\Delta_{C_1}, \\Delta_{C_2}, \\Delta_{RH_2})

with input the external wrench at G1 ``[F; T]`` (6) [N; N m] and output the hub acceleration
twist at G1 ``[a; wdot]`` (6) [m/s^2; rad/s^2], both in R_RH1. Its blocks and occurrences are the
paper's (see :data:`PAPER_OCCURRENCES`): ``w1_SAk`` x2, ``tau_thetak`` x16, ``tau_alphai`` x16,
``delta_C1`` x(12 + 4), ``delta_C2`` x(12 + 4), ``m_RH2`` x3, ``Jxx_RH2``, ``Jyy_RH2``,
``Jzz_RH2`` x1.

:func:`build_docking_model` gives the docking-phase LFRs (paper Fig. compact_lft_springmass): the
switches are replaced by spring-dampers SM1 (arm tip J7 / D2, phase 7) and SM2 (D1 / D3, phase 8)
and RH2 becomes an inverse model with ports D2, D3, P3, P4.

:func:`mission_values` maps mission times (or configurations) to the physical values of the
scheduled blocks, so ``usubs(model, mission_values(times))`` is the model array along the mission
in one vectorized call.

Signal names used in the assembly (all 6-vectors): ``xdd_<point>_<frame>`` acceleration twists and
``W_<point>_<frame>`` wrenches (at a parent port: applied by the child to the parent).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np
from scipy.linalg import block_diag

from oos_drake.lfr import LFR
from oos_drake.titop import (
    Component,
    angle_parameter,
    assemble,
    connection_parameter,
    fixed_connection,
    flexible_appendage,
    repeat,
    revolute_connection,
    rigid_body_direct,
    rigid_body_inverse,
    rigid_link,
    spring_damper,
    spring_damper_parameters,
    uncertain_inertia,
    uncertain_mass,
)
from oos_drake.titop.parameters import mode_frequency_name, relative_parameter
from oos_drake.titop.rotation import rotation_frame_change
from oos_drake.titop.spatial import angle_to_tau, frame_change_matrix

__all__ = [
    "ARRAY_NAMES",
    "PAPER_OCCURRENCES",
    "DELTA_GROUPS",
    "build_mission_model",
    "build_docking_model",
    "physical_blocks",
    "hub_parameters",
    "spring_damper_between",
    "attitude_model",
    "configuration_values",
    "mission_values",
    "delta_block_table",
    "PAPER_DELTA_STRUCTURE",
    "paper_delta_table",
]

ARRAY_NAMES = ("SA1", "SA2", "SA3", "SA4")

#: Occurrences of every block of the mission model in the paper (section 2).
PAPER_OCCURRENCES: dict[str, int] = {
    **{f"w1_{a}": 2 for a in ARRAY_NAMES},
    **{f"tau_theta{k}": 16 for k in range(1, 5)},
    **{f"tau_alpha{k}": 16 for k in range(1, 7)},
    "delta_C1": 12 + 4,
    "delta_C2": 12 + 4,
    "m_RH2": 3,
    "Jxx_RH2": 1,
    "Jyy_RH2": 1,
    "Jzz_RH2": 1,
}

#: The paper's ``Delta_P`` in its order: (sub-block, [(block name, repetitions), ...]).
PAPER_DELTA_STRUCTURE: tuple[tuple[str, tuple[tuple[str, int], ...]], ...] = (
    *((f"Delta_w{k}", ((f"w1_SA{k}", 2),)) for k in range(1, 5)),
    *((f"Delta_theta{k}", ((f"tau_theta{k}", 16),)) for k in range(1, 5)),
    ("Delta_RA", tuple((f"tau_alpha{i}", 16) for i in range(1, 7))),
    ("Delta_C1", (("delta_C1", 12),)),
    ("Delta_C2", (("delta_C2", 12),)),
    (
        "Delta_RH2",
        (
            ("m_RH2", 3),
            ("Jxx_RH2", 1),
            ("Jyy_RH2", 1),
            ("Jzz_RH2", 1),
            ("delta_C1", 4),
            ("delta_C2", 4),
        ),
    ),
)

#: Paper name of the Delta_P sub-block each model block belongs to (for tables).
DELTA_GROUPS: dict[str, str] = {
    **{f"w1_SA{k}": f"Delta_w{k} (mod)" for k in range(1, 5)},
    **{f"tau_theta{k}": f"Delta_theta{k}" for k in range(1, 5)},
    **{f"tau_alpha{k}": "Delta_RA" for k in range(1, 7)},
    "delta_C1": "Delta_C1 (I12) + Delta_RH2 (I4)",
    "delta_C2": "Delta_C2 (I12) + Delta_RH2 (I4)",
    "m_RH2": "Delta_RH2: Delta_mec",
    "Jxx_RH2": "Delta_RH2: Delta_mec",
    "Jyy_RH2": "Delta_RH2: Delta_mec",
    "Jzz_RH2": "Delta_RH2: Delta_mec",
    **{
        f"{q}_SM{k}": f"Delta_SM{k}"
        for k in (1, 2)
        for q in ("k_shear", "k_tors", "d_shear", "d_tors")
    },
}


# ------------------------------------------------------------------------------------------ blocks
def hub_parameters(hub):
    """Mass [kg] and inertia at G [kg m^2] of a rigid body (``RigidHub`` or a tree's
    ``RigidBodyData``): ureal blocks ``m_<name>``, ``Jxx_<name>``, ... when its data declare
    uncertainty, plain numbers otherwise."""
    mass_percent = float(hub.mass_uncertainty_percent)
    inertia_percent = np.asarray(hub.inertia_uncertainty_percent, dtype=float)
    mass = uncertain_mass(hub.name, hub.mass, mass_percent if mass_percent > 0 else None)
    if np.any(inertia_percent > 0):
        inertia = uncertain_inertia(hub.name, hub.inertia, inertia_percent)
    else:
        inertia = np.asarray(hub.inertia, dtype=float)
    return mass, inertia


def _first_mode_parameter(mount):
    """First cantilever mode frequency ``w1_<array>`` [rad/s]: a ureal if the data say uncertain."""
    model = mount.model
    percent = float(model.first_mode_uncertainty_percent)
    return relative_parameter(
        mode_frequency_name(mount.name, 1),
        float(model.omega[0]),
        percent if percent > 0 else None,
        unit="rad/s",
        quantity="modal frequency",
    )


def _spring_damper_blocks(name: str, docking) -> dict:
    """Default blocks of spring-damper ``name`` (``SM1``, ``SM2``): ranges ``[0, 2 x nominal]``."""
    return spring_damper_parameters(
        name,
        stiffness=(docking.rigid_stiffness, docking.rigid_stiffness),
        damping=(docking.damping, docking.damping),
        stiffness_range=(0.0, 2.0 * docking.rigid_stiffness),
        damping_range=(0.0, 2.0 * docking.damping),
    )


def physical_blocks(scenario) -> dict:
    """The scenario's uncertain physical parameters as the models create them.

    Hub masses and inertias, first array mode frequencies and the docking spring-dampers' default
    blocks (those the scenario data declare uncertain), each with its unit, quantity, nominal and
    range; the scheduled blocks (angles, switches) are not included.

    Returns
    -------
    dict
        Block name -> block spec (:class:`~oos_drake.lfr.blocks.UReal`), sorted by name.
    """
    parts = [p for hub in scenario.hubs.values() for p in hub_parameters(hub)]
    parts += [_first_mode_parameter(mount) for mount in scenario.arrays.values()]
    for name in ("SM1", "SM2"):
        parts += list(_spring_damper_blocks(name, scenario.docking).values())
    blocks = {}
    for part in parts:
        if isinstance(part, LFR):
            blocks.update(part.uncertainty)
    return dict(sorted(blocks.items()))


def _array_component(mount, parent_frame: str) -> Component:
    """Array k on its hub: ``T0^T T_theta^T (-M_P(s)) T_theta T0`` (16 tau + 2 w occurrences)."""
    model = mount.model
    k = mount.name[-1]
    omega = np.asarray(model.omega, dtype=float)
    first = _first_mode_parameter(mount)
    uncertain = {} if isinstance(first, float) else {0: first}
    appendage = flexible_appendage(
        model.rigid_spatial_inertia,
        np.asarray(model.participation, dtype=float).T,  # data: one row per mode
        omega,
        model.damping_ratios,
        uncertain_frequencies=uncertain,
        name=mount.name,
    )
    tau = angle_parameter(f"tau_theta{k}")
    t0 = frame_change_matrix(np.asarray(mount.R_G_P0).T)  # DCM_{SA0/hub}
    forward = rotation_frame_change(tau, mount.axis) @ t0
    backward = t0.T @ rotation_frame_change(tau, mount.axis, transpose=True)
    system = backward @ appendage @ forward
    port = f"P{k}"
    return Component(
        mount.name,
        system,
        inputs=(f"xdd_{port}_{parent_frame}",),
        outputs=(f"W_{port}_{parent_frame}",),
    )


def _arm_components(arm) -> list[Component]:
    """Base connection, links L0..L6 and motion-driven joints alpha_1..6 (16 occurrences each)."""
    components = [
        Component(
            "J0",
            fixed_connection(np.asarray(arm.R_G_L0).T),  # DCM_{L0/RH1}
            inputs=("xdd_J0_RH1", "W_J0_L0"),
            outputs=("xdd_J0_L0", "W_J0_RH1"),
        )
    ]
    for i, link in enumerate(arm.links):
        p_GP = -np.asarray(link.p_J_G, dtype=float)
        p_GC = np.asarray(link.p_J_Jnext, dtype=float) - np.asarray(link.p_J_G, dtype=float)
        components.append(
            Component(
                link.name,
                rigid_link(link.mass, link.inertia, p_GP, p_GC, body=link.name),
                inputs=(f"W_J{i + 1}_L{i}", f"xdd_J{i}_L{i}"),
                outputs=(f"xdd_J{i + 1}_L{i}", f"W_J{i}_L{i}"),
            )
        )
        if i >= 1:
            components.append(
                Component(
                    f"joint{i}",
                    revolute_connection(angle_parameter(f"tau_alpha{i}"), link.joint_axis),
                    inputs=(f"xdd_J{i}_L{i - 1}", f"W_J{i}_L{i}"),
                    outputs=(f"xdd_J{i}_L{i}", f"W_J{i}_L{i - 1}"),
                )
            )
    return components


def _port_frames(scenario):
    """Constant frame changes across the mated ports: T_{RH2/L6} (grasp) and T_{RH2/RH1} (dock)."""
    ports = scenario.ports
    # J7 frame = L6 frame (moved to J7) coincides with the D2 frame: v_RH2 = R_G_D2 v_L6
    dcm_rh2_l6 = np.asarray(ports["D2"].R_G_D, dtype=float)
    # D3 frame coincides with D1 frame: v_RH2 = R_G_D3 R_G_D1^T v_RH1
    dcm_rh2_rh1 = np.asarray(ports["D3"].R_G_D, dtype=float) @ np.asarray(ports["D1"].R_G_D).T
    return dcm_rh2_l6, dcm_rh2_rh1


def _docking_switches(delta_c1: LFR, delta_c2: LFR, dcm_rh2_l6, dcm_rh2_rh1) -> LFR:
    """``xdd_D = dC1 T_a xdd_J7 + dC2 T_b xdd_D1``, ``W_J7 = dC1 T_a^T W``, ``W_D1 = dC2 T_b^T W``.

    Inputs ``[xdd_J7 (L6); xdd_D1 (RH1); W_D (RH2)]``, outputs ``[xdd_D (RH2); W_J7 (L6);
    W_D1 (RH1)]``; each switch occurs 12 times (``delta_C I12``).
    """
    t_a = frame_change_matrix(dcm_rh2_l6)
    t_b = frame_change_matrix(dcm_rh2_rh1)
    zero = np.zeros((6, 6))
    select_1 = np.block([[t_a, zero, zero], [zero, zero, t_a.T]])  # 12 x 18
    spread_1 = np.block([[np.eye(6), zero], [zero, np.eye(6)], [zero, zero]])  # 18 x 12
    select_2 = np.block([[zero, t_b, zero], [zero, zero, t_b.T]])
    spread_2 = np.block([[np.eye(6), zero], [zero, zero], [zero, np.eye(6)]])
    return spread_1 @ repeat(delta_c1, 12) @ select_1 + spread_2 @ repeat(delta_c2, 12) @ select_2


def _chaser_components(scenario, with_d1: bool) -> list[Component]:
    """RH1 (inverse model, external wrench at G1; ports at its arrays' mounts, J0 and, with
    ``with_d1``, D1), its arrays and the arm."""
    mounts = scenario.arrays
    on_rh1 = [m for m in ARRAY_NAMES if mounts[m].parent == "RH1"]
    rh1_ports = [mounts[m].p_G_P for m in on_rh1] + [scenario.arm.p_G_J0]
    rh1_in = ["W_ext_G1"] + [f"W_P{m[-1]}_RH1" for m in on_rh1] + ["W_J0_RH1"]
    rh1_out = ["xdd_G1_RH1"] + [f"xdd_P{m[-1]}_RH1" for m in on_rh1] + ["xdd_J0_RH1"]
    if with_d1:
        rh1_ports.append(scenario.ports["D1"].p_G_D)
        rh1_in.append("W_D1_RH1")
        rh1_out.append("xdd_D1_RH1")
    mass1, inertia1 = hub_parameters(scenario.hubs["RH1"])
    components = [
        Component(
            "RH1", rigid_body_inverse(mass1, inertia1, rh1_ports, body="RH1"), rh1_in, rh1_out
        )
    ]
    components += [_array_component(mounts[m], "RH1") for m in on_rh1]
    return components + _arm_components(scenario.arm)


def _assemble_at_G1(components: list[Component]) -> LFR:
    """The assembly from the external wrench at G1 to the acceleration twist of G1, named
    ``Fx_G1 .. Tz_G1`` -> ``ax_G1 .. wdot_z_G1``."""
    model = assemble(components, inputs=["W_ext_G1"], outputs=["xdd_G1_RH1"])
    names = ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]
    outs = ["ax", "ay", "az", "wdot_x", "wdot_y", "wdot_z"]
    return model.with_names(inputs=[f"{n}_G1" for n in names], outputs=[f"{n}_G1" for n in outs])


def build_mission_model(scenario) -> LFR:
    """Full mission LFR: external wrench at G1 (6) -> acceleration twist of RH1 at G1 (6).

    Cached per scenario object (LFRs are immutable).

    Parameters
    ----------
    scenario : oos_drake.scenario.data.Scenario or TreeScenario
        Validated scenario; a schema-2 tree gives its own plant
        (:meth:`~oos_drake.scenario.tree_scenario.TreeScenario.mission_model`).

    Returns
    -------
    LFR
        48 states (4 arrays x 6 modes x 2); blocks and occurrences as in :data:`PAPER_OCCURRENCES`.
        Substitute the scheduled blocks with :func:`mission_values`.

    Examples
    --------
    >>> import numpy as np
    >>> from oos_drake.lfr import usubs
    >>> from oos_drake.scenario.data import load_scenario
    >>> scenario = load_scenario("paper")
    >>> model = build_mission_model(scenario)
    >>> model.occurrences["tau_alpha1"], model.occurrences["delta_C1"]
    (16, 16)
    >>> models = usubs(model, mission_values(np.linspace(0.0, 1500.0, 330), scenario)).nominal
    >>> models.freqresp(2 * np.pi * np.logspace(-2, 2, 500)).shape
    (330, 500, 6, 6)
    """
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):
        return scenario.mission_model()
    return _mission_model(scenario)


@functools.lru_cache(maxsize=4)
def _mission_model(scenario) -> LFR:
    rh2 = scenario.hubs["RH2"]
    mounts = scenario.arrays
    ports = scenario.ports
    on_rh2 = [m for m in ARRAY_NAMES if mounts[m].parent == "RH2"]
    components = _chaser_components(scenario, with_d1=True)
    delta_c1 = connection_parameter("delta_C1")
    delta_c2 = connection_parameter("delta_C2")
    mass2, inertia2 = hub_parameters(rh2)
    components.append(
        Component(
            "RH2",
            rigid_body_direct(
                mass2,
                inertia2,
                [mounts[m].p_G_P for m in on_rh2],
                np.zeros(3),
                parent_terms=[(delta_c1, ports["D2"].p_G_D), (delta_c2, ports["D3"].p_G_D)],
                body="RH2",
            ),
            inputs=tuple(f"W_P{m[-1]}_RH2" for m in on_rh2) + ("xdd_D_RH2",),
            outputs=tuple(f"xdd_P{m[-1]}_RH2" for m in on_rh2) + ("W_D_RH2",),
        )
    )
    components += [_array_component(mounts[m], "RH2") for m in on_rh2]
    components.append(
        Component(
            "switches",
            _docking_switches(delta_c1, delta_c2, *_port_frames(scenario)),
            inputs=("xdd_J7_L6", "xdd_D1_RH1", "W_D_RH2"),
            outputs=("xdd_D_RH2", "W_J7_L6", "W_D1_RH1"),
        )
    )
    return _assemble_at_G1(components)


def build_docking_model(phase: str, scenario, *, spring_dampers=None) -> LFR:
    """Docking-phase LFR with spring-dampers (paper Fig. compact_lft_springmass).

    Parameters
    ----------
    phase : {"7", "8"}
        ``"7"``: the arm tip J7 docks to D2 through SM1 (SM2 open, RH2 not at D1);
        ``"8"``: D3 docks to D1 through SM2 while the arm holds D2 through SM1 (closed loop).
    scenario : Scenario
    spring_dampers : dict, optional
        ``{"SM1": {"k_shear": LFR|float, ...}, ...}``; default: ureal blocks
        ``k_shear_SMk``, ``k_tors_SMk``, ``d_shear_SMk``, ``d_tors_SMk`` (see
        :func:`oos_drake.titop.spring_damper_parameters`) with nominal values from the scenario.

    Returns
    -------
    LFR
        W_ext,G1 (6) -> xdd_G1 (6); blocks ``w1_SAk``, ``tau_thetak``, ``tau_alphai``, ``m_RH2``,
        ``J.._RH2`` and the spring-damper blocks (3 occurrences each).
    """
    phase = str(phase)
    if phase not in ("7", "8"):
        raise ValueError(f"build_docking_model: phase must be '7' or '8', got {phase!r}")
    if spring_dampers is None:
        return _default_docking_model(phase, scenario)
    return _docking_model(phase, scenario, spring_dampers)


@functools.lru_cache(maxsize=8)
def _default_docking_model(phase: str, scenario) -> LFR:
    return _docking_model(phase, scenario, None)


def _docking_model(phase: str, scenario, spring_dampers) -> LFR:
    active = ("SM1",) if phase == "7" else ("SM1", "SM2")
    given = spring_dampers or {}
    params = {
        sm: _spring_damper_blocks(sm, scenario.docking)
        if given.get(sm) is None
        else dict(given[sm])
        for sm in active
    }
    rh2 = scenario.hubs["RH2"]
    mounts = scenario.arrays
    ports = scenario.ports
    on_rh2 = [m for m in ARRAY_NAMES if mounts[m].parent == "RH2"]
    with_d1 = "SM2" in active
    components = _chaser_components(scenario, with_d1)
    rh2_ports = [ports["D2"].p_G_D] + [mounts[m].p_G_P for m in on_rh2]
    rh2_in = ["W_D2_RH2"] + [f"W_P{m[-1]}_RH2" for m in on_rh2]
    rh2_out = ["xdd_D2_RH2"] + [f"xdd_P{m[-1]}_RH2" for m in on_rh2]
    if with_d1:
        rh2_ports.append(ports["D3"].p_G_D)
        rh2_in.append("W_D3_RH2")
        rh2_out.append("xdd_D3_RH2")
    mass2, inertia2 = hub_parameters(rh2)
    rh2_model = rigid_body_inverse(mass2, inertia2, rh2_ports, body="RH2")[6:, 6:]  # no W_ext
    components.append(Component("RH2", rh2_model, rh2_in, rh2_out))
    components += [_array_component(mounts[m], "RH2") for m in on_rh2]
    dcm_rh2_l6, dcm_rh2_rh1 = _port_frames(scenario)
    # SM1 in the frame of J7 (= D2): C = RH2 at D2, P = arm tip J7;
    # SM2 in the frame of D1 (= D3): C = RH2 at D3, P = RH1 at D1
    springs = [("SM1", "D2_RH2", "J7_L6", dcm_rh2_l6)]
    if with_d1:
        springs.append(("SM2", "D3_RH2", "D1_RH1", dcm_rh2_rh1))
    for name, c, p, dcm in springs:
        blocks = spring_damper_between(params[name], dcm)
        components.append(
            Component(name, blocks, inputs=(f"xdd_{c}", f"xdd_{p}"), outputs=(f"W_{c}", f"W_{p}"))
        )
    return _assemble_at_G1(components)


def spring_damper_between(blocks: Mapping, dcm_c_sm) -> LFR:
    """Spring-damper whose C side is expressed in another frame: ``v_C = dcm_c_sm v_SM``.

    Inputs ``[xdd_C (C frame); xdd_P (SM frame)]``, outputs ``[W_C (C frame); W_P (SM frame)]``.
    """
    t = frame_change_matrix(dcm_c_sm)  # SM frame -> C frame
    inner = spring_damper(blocks["k_shear"], blocks["k_tors"], blocks["d_shear"], blocks["d_tors"])
    return block_diag(t, np.eye(6)) @ inner @ block_diag(t.T, np.eye(6))


def attitude_model(model: LFR) -> LFR:
    """``W_ext,G1 (6) -> phi (3)``: the linearized Euler angles, double integral of ``wdot``.

    Parameters
    ----------
    model : LFR
        Mission or docking model (6 outputs ``[a; wdot]``).

    Returns
    -------
    LFR
        6 inputs, 3 outputs ``phi`` [rad], 6 more states (``1/s^2 I3``).
    """
    # x = [phi; omega]: A = [[0, I3], [0, 0]], B = [0; I3], C = [I3, 0]
    integrator = LFR.from_ss(np.eye(6, k=3), np.eye(6, 3, k=-3), np.eye(3, 6), np.zeros((3, 3)))
    result = integrator @ model[3:6, :]
    return result.with_names(inputs=model.input_names, outputs=["phi_x", "phi_y", "phi_z"])


# ---------------------------------------------------------------------------------- substitution
def configuration_values(alpha, theta, delta_C1, delta_C2) -> dict[str, np.ndarray]:
    """Block values ``tau_alpha<i> = tan(alpha_i/4)``, ``tau_theta<k>``, ``delta_C1``, ``delta_C2``.

    Parameters
    ----------
    alpha : array_like (..., 6)
        Arm joint angles [rad] (wrapped to [-pi, pi]).
    theta : array_like (..., 4)
        Array tilt angles theta_1..4 [rad].
    delta_C1, delta_C2 : array_like (...)
        Connection switches in [0, 1].

    Returns
    -------
    dict
        Block name -> array of physical values (shape ``(...)``).
    """
    alpha = np.asarray(alpha, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if alpha.shape[-1:] != (6,):
        raise ValueError(
            f"configuration_values: alpha must have 6 columns, got shape {alpha.shape}"
        )
    if theta.shape[-1:] != (4,):
        raise ValueError(
            f"configuration_values: theta must have 4 columns, got shape {theta.shape}"
        )
    values = {f"tau_alpha{i + 1}": angle_to_tau(alpha[..., i]) for i in range(6)}
    values.update({f"tau_theta{k + 1}": angle_to_tau(theta[..., k]) for k in range(4)})
    for name, value in (("delta_C1", delta_C1), ("delta_C2", delta_C2)):
        value = np.asarray(value, dtype=float)
        if np.any((value < 0) | (value > 1)):
            raise ValueError(f"configuration_values: {name} must be in [0, 1], got {value}")
        values[name] = value
    return values


def mission_values(times, scenario) -> dict[str, np.ndarray]:
    """Scheduled block values at mission times (arm, arrays and switches from the timeline).

    Parameters
    ----------
    times : float or array_like (N,)
        Mission times [s].
    scenario : Scenario or TreeScenario
        (a tree: the ``tau_<body>`` of its timeline's joint angles,
        :meth:`~oos_drake.scenario.tree_scenario.TreeScenario.mission_values`)

    Returns
    -------
    dict
        Block name -> (N,) physical values, for ``usubs(model, mission_values(times))``.
    """
    from oos_drake.scenario.timeline import mission_timeline
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):
        return scenario.mission_values(times)

    timeline = mission_timeline(scenario)
    config = timeline.configuration(np.atleast_1d(np.asarray(times, dtype=float)))
    return configuration_values(config.alpha, config.theta, config.delta_C1, config.delta_C2)


# -------------------------------------------------------------------------------------- tables
def delta_block_table(model: LFR):
    """Table of the model's blocks: name, paper group, kind, occurrences, nominal and range.

    Returns
    -------
    pandas.DataFrame
        One row per block (sorted by name) plus the column ``paper_occurrences`` when the block
        is one of :data:`PAPER_OCCURRENCES`.
    """
    import pandas as pd

    table = model.blocks.copy()
    occurrences = model.occurrences
    table["occurrences"] = [occurrences[name] for name in table["name"]]
    table["group"] = [DELTA_GROUPS.get(name, "") for name in table["name"]]
    table["paper_occurrences"] = [PAPER_OCCURRENCES.get(name, pd.NA) for name in table["name"]]
    return table


def paper_delta_table(model: LFR):
    """The paper's ``Delta_P`` sub-blocks with their sizes, checked against ``model``.

    Returns
    -------
    pandas.DataFrame
        Columns ``sub_block, content, size``; the last row is the total. Raises ``ValueError``
        if the model's occurrences cannot be split into the paper's sub-blocks.
    """
    import pandas as pd

    needed: dict[str, int] = {}
    rows = []
    for sub_block, entries in PAPER_DELTA_STRUCTURE:
        content = ", ".join(f"{name} I{reps}" if reps > 1 else name for name, reps in entries)
        rows.append(
            {"sub_block": sub_block, "content": content, "size": sum(reps for _, reps in entries)}
        )
        for name, reps in entries:
            needed[name] = needed.get(name, 0) + reps
    occurrences = model.occurrences
    wrong = {n: (occurrences.get(n, 0), r) for n, r in needed.items() if occurrences.get(n) != r}
    if wrong:
        raise ValueError(f"paper_delta_table: occurrences (model, paper) differ: {wrong}")
    rows.append({"sub_block": "Delta_P", "content": "total", "size": sum(r["size"] for r in rows)})
    return pd.DataFrame(rows)
