"""The TITOP LFR of any spacecraft tree (:mod:`oos_drake.scenario.tree`).

:func:`build_tree_model` assembles, with :func:`oos_drake.titop.assemble`,

- the controlled (root) body as a multi-port rigid body, inverse model, with the external wrench
  at its centre of mass ``G`` and one port per child joint;
- every other rigid body as a rigid body with its inverted port at its joint (direct model), one
  more port per child joint;
- every flexible appendage as the one-port ``-M_P(s)`` at its attachment point, seen from its
  parent through its joint, ``T^T (-M_P(s)) T`` (one component);
- every other joint as a connection at the joint point: ``fixed_connection(R_parent_child^T)``
  or the motion-driven ``revolute_connection(tau_<body>, axis, R_parent_joint^T)``,

into the direct-dynamics model of the controlled body

.. math::

    \\ddot x_G = F_u(M(s), \\Delta)\\, W_{ext, G}

from the wrench ``[F; T]`` at ``G`` [N, N m] to the acceleration twist ``[a; wdot]`` at ``G``
[m/s^2, rad/s^2], both in the controlled body's axes. Uncertain and scheduled blocks are named
from the bodies: ``w<i>_<appendage>`` (mode frequency [rad/s], 2 occurrences), ``m_<body>`` (3),
``Jxx_<body>``, ``Jyy_<body>``, ``Jzz_<body>`` (1 each), ``tau_<body>`` (``tan(angle/4)`` of a
revolute joint, 16 occurrences). Substitute the joints' angles with :func:`tree_values`.

A mission that captures or docks a target (``captured``, ``docked`` phases,
:mod:`oos_drake.scenario.tree_mission`) has ONE model over all its phases,
:func:`build_mission_tree_model`, as schema 1's mission LFR (``scenario.model``,
``delta_C1``/``delta_C2``): each target is in it as a rigid body (direct model) whose parent
acceleration is switched between the tree's ports it connects to,

.. math::

    \\ddot x_{D,T} = \\sum_k \\delta_k\\, T_k\\, \\ddot x_{D_k}, \\qquad
    W_{D_k} = \\delta_k\\, T_k^T W_{D,T}, \\qquad
    \\overrightarrow{G_T D} = \\sum_k \\delta_k\\, \\overrightarrow{G_T D'_k}

(``T_k`` the frame change from the tree body of port ``D_k`` to the target at the mated ports,
``D'_k`` the target's port), with one switch block ``delta_<PORT>`` in ``[0, 1]`` per port of
the tree (12 + 4 occurrences): ``1`` through the phases that capture or dock the target at that
port (a rigid weld), ``0`` otherwise (the target free: its wrench does not reach the tree).
A docked phase is welded rigid in this model, like schema 1's mission LFR after its second
docking; its spring-damper is the docking model of that phase
(:func:`oos_drake.scenario.tree.docked_tree`).
"""

from __future__ import annotations

import functools

import numpy as np

from oos_drake.lfr import LFR, ureal
from oos_drake.scenario.model import hub_parameters, spring_damper_between
from oos_drake.scenario.tree import SpacecraftTree, body_poses
from oos_drake.titop import (
    Component,
    angle_parameter,
    assemble,
    connection_parameter,
    fixed_connection,
    flexible_appendage,
    repeat,
    revolute_connection,
    revolute_frame_changes,
    rigid_body_direct,
    rigid_body_inverse,
)
from oos_drake.titop.parameters import mode_frequency_name, relative_parameter
from oos_drake.titop.spatial import angle_to_tau, frame_change_matrix

__all__ = [
    "angle_block_name",
    "build_tree_model",
    "build_mission_tree_model",
    "docking_block_names",
    "mission_connections",
    "switch_block_name",
    "tree_values",
    "tree_blocks",
    "mode_frequency_blocks",
    "rigid_inertia_at_root",
]

_INPUTS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
_OUTPUTS = ("ax", "ay", "az", "wdot_x", "wdot_y", "wdot_z")


def angle_block_name(body: str) -> str:
    """Default name of the scheduled block of the revolute joint of ``body``: ``tau_<body>``
    (a file may name it: ``joint.block``, :meth:`SpacecraftTree.angle_block`)."""
    return f"tau_{body}"


def mode_frequency_blocks(appendage) -> dict[int, LFR]:
    """Uncertain mode frequencies of a flexible body: ``{mode index (0-based): ureal [rad/s]}``."""
    blocks = {}
    for entry in appendage.uncertainty:
        nominal = float(appendage.omega[entry.mode - 1])
        name = mode_frequency_name(appendage.name, entry.mode)
        if entry.percent is not None:
            block = relative_parameter(
                name, nominal, entry.percent, unit="rad/s", quantity="modal frequency"
            )
        else:
            low, high = entry.range_hz
            block = ureal(
                name,
                nominal,
                range=(2.0 * np.pi * low, 2.0 * np.pi * high),
                unit="rad/s",
                quantity="modal frequency",
            )
        blocks[entry.mode - 1] = block
    return blocks


def _origin_offset(body) -> np.ndarray:
    """``G -> B``: from a rigid body's centre of mass to its body frame origin [m]."""
    return -np.asarray(body.p_B_G, dtype=float)


def _connection(child) -> LFR:
    joint = child.joint
    if joint.type == "fixed":
        return fixed_connection(np.asarray(joint.R_parent_joint).T)
    return revolute_connection(
        angle_parameter(child.joint.block or angle_block_name(child.name)),
        joint.axis,
        dcm_fixed=np.asarray(joint.R_parent_joint).T,
    )


def _joint_point(tree: SpacecraftTree, child) -> np.ndarray:
    """Parent body frame origin -> the point where ``child`` is connected, parent axes [m]:
    the joint origin, or for a spring-damper the parent's port where it acts."""
    joint = child.joint
    if joint.type == "bushing":
        return np.asarray(tree.ports[joint.docking.port].p_B_D, dtype=float)
    return np.asarray(joint.p_parent_joint, dtype=float)


def _docking_blocks(docking) -> dict:
    """Stiffness [N/m, N m/rad] and damping [N s/m, N m s/rad] of a docking spring-damper:
    ureal blocks ``k_shear_<name>``, ``k_tors_<name>``, ``d_shear_<name>``, ``d_tors_<name>``
    (``name``: :attr:`~oos_drake.scenario.tree_mission.Docking.label`), nominal the file's
    values, over the declared ranges (``stiffness_percent``, ``damping_percent``); a known one
    (no percent) spans ``[0, 2 x nominal]``, schema 1's default spring-damper blocks
    (:func:`oos_drake.titop.spring_damper_parameters`): the docking study sweeps the stiffness
    there, every other use substitutes the file's value
    (:meth:`oos_drake.scenario.tree_scenario.TreeScenario.docking_values`)."""
    blocks = {}
    units = {"k_shear": "N/m", "k_tors": "N m/rad", "d_shear": "N s/m", "d_tors": "N m s/rad"}
    for key, percent in (
        ("k_shear", docking.stiffness_percent),
        ("k_tors", docking.stiffness_percent),
        ("d_shear", docking.damping_percent),
        ("d_tors", docking.damping_percent),
    ):
        nominal = float(getattr(docking, key))
        name = f"{key}_{docking.label}"
        quantity = "stiffness" if key.startswith("k") else "damping"
        blocks[key] = (
            relative_parameter(name, nominal, percent, unit=units[key], quantity=quantity)
            if percent > 0
            else ureal(name, nominal, range=(0.0, 2.0 * nominal), unit=units[key],
                       quantity=quantity)
        )  # fmt: skip
    return blocks


def docking_block_names(docking) -> dict[str, str]:
    """``{"k_shear": "k_shear_<name>", ...}``: the block names of a docking spring-damper."""
    return {key: f"{key}_{docking.label}" for key in ("k_shear", "k_tors", "d_shear", "d_tors")}


def _closure_ports(tree: SpacecraftTree) -> dict[str, list]:
    """The ports of :attr:`SpacecraftTree.closures` as extra ports of their bodies:
    ``{body: [(signal suffix, p_B_D [m])]}``."""
    extra: dict[str, list] = {}
    for closure in tree.closures:
        for port in (closure.port, closure.target_port):
            spec = tree.ports[port]
            extra.setdefault(spec.body, []).append((f"C{port}_{spec.body}", spec.p_B_D))
    return extra


def _closure_components(tree: SpacecraftTree) -> list[Component]:
    """A spring-damper per closure, C = the target at its port (its axes), P = the tree's
    body at its port (its axes); at rest the ports coincide, axes aligned, so the frame change
    is ``R_TB = R_TD' R_BD^T`` whatever the joint angles."""
    components = []
    for closure in tree.closures:
        chaser, target = tree.ports[closure.port], tree.ports[closure.target_port]
        dcm = np.asarray(target.R_B_D) @ np.asarray(chaser.R_B_D).T  # v_T = dcm v_B
        c = f"C{closure.target_port}_{target.body}"
        p = f"C{closure.port}_{chaser.body}"
        components.append(
            Component(
                f"closure_{closure.label}",
                spring_damper_between(_docking_blocks(closure), dcm),
                inputs=(f"xdd_{c}", f"xdd_{p}"),
                outputs=(f"W_{c}", f"W_{p}"),
            )
        )
    return components


def _joint_component(body) -> Component:
    """The connection of ``body`` to its parent at the joint point (fixed or revolute)."""
    name, parent = body.name, body.parent
    return Component(
        f"joint_{name}",
        _connection(body),
        inputs=(f"xdd_J{name}_{parent}", f"W_J{name}_{name}"),
        outputs=(f"xdd_J{name}_{name}", f"W_J{name}_{parent}"),
    )


def _appendage_model(body) -> LFR:
    """The flexible appendage ``body`` at its port, in its own axes (TITOP ``M_P(s)``)."""
    return flexible_appendage(
        body.rigid_spatial_inertia,
        np.asarray(body.participation).T,  # data: one row per mode
        body.omega,
        body.damping_ratios,
        uncertain_frequencies=mode_frequency_blocks(body),
        name=body.name,
    )


def _appendage_component(body) -> Component:
    """A flexible appendage seen from its parent through its joint, one component:
    ``T^T (-M_P(s)) T`` from the parent's acceleration twist at the joint point to the wrench
    on the parent there, both in the parent's axes (``T`` the joint's frame change; schema 1's
    array block ``T0^T T_theta^T (-M_P(s)) T_theta T0``, 16 occurrences of ``tau``)."""
    name, joint = body.name, body.joint
    system = _appendage_model(body)
    dcm = np.asarray(joint.R_parent_joint).T
    if joint.type == "fixed":
        t = frame_change_matrix(dcm)
        system = t.T @ system @ t
    else:
        tau = angle_parameter(joint.block or angle_block_name(name))
        forward, backward = revolute_frame_changes(tau, joint.axis, dcm)
        system = backward @ system @ forward
    return Component(name, system, (f"xdd_J{name}_{body.parent}",), (f"W_J{name}_{body.parent}",))


def _components(
    tree: SpacecraftTree, extra_ports=None, *, skip_root: bool = False
) -> list[Component]:
    """Components of every body and joint of ``tree``.

    ``extra_ports``: ``{body: [(signal suffix, p_B_D [m]), ...]}``, more ports of rigid bodies
    (inputs ``W_<suffix>``, outputs ``xdd_<suffix>``); ``skip_root``: leave the root body out
    (a target, whose root :func:`_target_components` models).

    In the order of ``tree.bodies``: a flexible appendage is one component with its joint
    (:func:`_appendage_component`); a rigid body's fixed joint comes before the body, a revolute
    joint or a spring-damper after it. The order and the grouping are schema 1's
    (:func:`oos_drake.scenario.model.build_mission_model`: hub, arrays, ``J0``, ``L0``, then
    each link and its joint), so the converted paper's LFR is schema 1's to the last bit: the
    assembly's algebraic loop is solved by one LU factorization whose rounding depends on the
    order of the components' channels.
    """
    components, springs = [], []
    root = tree.root
    extra_ports = dict(extra_ports or {})
    for body, ports in _closure_ports(tree).items():
        extra_ports[body] = list(extra_ports.get(body, ())) + ports
    for body in tree.bodies:
        name = body.name
        children = [tree.body(c) for c in tree.children(name)]
        if name in extra_ports and body.kind != "rigid":
            raise ValueError(
                f"{name}: a target connects to a port of this flexible body: capture and "
                "docking ports must be on rigid bodies"
            )
        if skip_root and name == root:
            continue
        joint = body.joint
        if body.kind != "rigid":
            if joint is not None and joint.type in ("fixed", "revolute"):
                components.append(_appendage_component(body))
                continue
            components.append(
                Component(
                    name, _appendage_model(body), (f"xdd_J{name}_{name}",), (f"W_J{name}_{name}",)
                )
            )
        else:
            if joint is not None and joint.type == "fixed":
                components.append(_joint_component(body))
            offset = _origin_offset(body)
            ports_GP = [offset + _joint_point(tree, c) for c in children]
            child_in = [f"W_J{c.name}_{name}" for c in children]
            child_out = [f"xdd_J{c.name}_{name}" for c in children]
            for suffix, p_B_D in extra_ports.get(name, ()):
                ports_GP.append(offset + np.asarray(p_B_D, dtype=float))
                child_in.append(f"W_{suffix}")
                child_out.append(f"xdd_{suffix}")
            mass, inertia = hub_parameters(body)
            if name == root:
                system = rigid_body_inverse(mass, inertia, ports_GP, body=name)
                inputs = [f"W_ext_{name}"] + child_in
                outputs = [f"xdd_G_{name}"] + child_out
            elif joint.type == "bushing":
                # a free body held by a spring-damper: inverse model, no external wrench; its
                # spring-damper ports in the order of docking (those of the closures, docked
                # before, then its own): the first before the children's ports, the others
                # after (schema 1's RH2: D2, its arrays, D3)
                port = tree.ports[joint.docking.target_port]
                n_child = len(children)
                ports_GP.append(offset + np.asarray(port.p_B_D, dtype=float))
                child_in.append(f"W_J{name}_{name}")
                child_out.append(f"xdd_J{name}_{name}")
                spring = range(n_child, len(ports_GP))  # the closures', then its own
                order = [spring[0], *range(n_child), *spring[1:]]
                ports_GP = [ports_GP[k] for k in order]
                child_in = [child_in[k] for k in order]
                child_out = [child_out[k] for k in order]
                system = rigid_body_inverse(mass, inertia, ports_GP, body=name)[6:, 6:]
                inputs, outputs = child_in, child_out
            else:
                system = rigid_body_direct(mass, inertia, ports_GP, offset, body=name)
                inputs = child_in + [f"xdd_J{name}_{name}"]
                outputs = child_out + [f"W_J{name}_{name}"]
            components.append(Component(name, system, inputs, outputs))
            if joint is not None and joint.type == "fixed":
                continue
        if joint is not None and joint.type == "bushing":
            # C = the target at its port (its axes), P = the parent at its port (parent axes);
            # after the closures' spring-dampers (docked before it: schema 1's SM1, SM2)
            blocks = _docking_blocks(joint.docking)
            springs.append(
                Component(
                    f"joint_{name}",
                    spring_damper_between(blocks, np.asarray(joint.R_parent_joint).T),
                    inputs=(f"xdd_J{name}_{name}", f"xdd_J{name}_{body.parent}"),
                    outputs=(f"W_J{name}_{name}", f"W_J{name}_{body.parent}"),
                )
            )
        elif joint is not None:
            components.append(_joint_component(body))
    return components + _closure_components(tree) + springs


def build_tree_model(tree: SpacecraftTree, *, rotational: bool = False) -> LFR:
    """Direct-dynamics LFR of the controlled body of ``tree`` with its appendages' modes.

    Parameters
    ----------
    tree : SpacecraftTree
        Validated tree (:func:`oos_drake.scenario.tree.load_tree`).
    rotational : bool
        Return only the 3x3 rotational part ``T -> wdot`` [N m -> rad/s^2].

    Returns
    -------
    LFR
        6x6 (or 3x3) with inputs ``Fx_<root> .. Tz_<root>`` and outputs
        ``ax_<root> .. wdot_z_<root>``; ``2 sum(n_modes)`` states; blocks named from the bodies
        (module docstring). Revolute joints are scheduled blocks ``tau_<body>`` (nominal: angle 0);
        substitute :func:`tree_values` for the file's angles. Cached per tree object.

    Examples
    --------
    >>> from oos_drake.lfr import usubs
    >>> from oos_drake.scenario.tree import load_tree
    >>> tree = load_tree("geo_satellite")
    >>> model = build_tree_model(tree)
    >>> sorted(n for n in model.uncertainty if n.startswith("w"))[:3]
    ['w1_REFL_E', 'w1_REFL_W', 'w1_SA_N']
    >>> usubs(model, tree_values(tree)).nominal.shape
    (6, 6)
    """
    model = _tree_model(tree)
    return model[3:6, 3:6] if rotational else model


@functools.lru_cache(maxsize=8)
def _tree_model(tree: SpacecraftTree) -> LFR:
    """One assembly per tree object (trees and LFRs are immutable)."""
    root = tree.root
    model = assemble(_components(tree), inputs=[f"W_ext_{root}"], outputs=[f"xdd_G_{root}"])
    return model.with_names(
        inputs=[f"{n}_{root}" for n in _INPUTS], outputs=[f"{n}_{root}" for n in _OUTPUTS]
    )


def switch_block_name(tree: SpacecraftTree, port: str) -> str:
    """Name of the switch block of the connections at port ``port`` of the tree: the port's
    ``block``, else ``delta_<port>``."""
    return tree.ports[port].block or f"delta_{port}"


def mission_connections(tree: SpacecraftTree) -> tuple[tuple[str, str], ...]:
    """The ``(port, target port)`` pairs the mission's phases capture or dock, in mission order
    (each once).

    Raises
    ------
    ValueError
        A port of the tree mated with two different target ports (its switch block would mean
        two things).
    """
    phases = () if tree.mission is None else tree.mission.phases
    pairs: list[tuple[str, str]] = []
    for phase in phases:
        pair = phase.captured if phase.docked is None else phase.docked.connection
        if pair is None or tuple(pair) in pairs:
            continue
        other = [p for p in pairs if p[0] == pair[0]]
        if other:
            raise ValueError(
                f"mission.{phase.name}: port {pair[0]} is mated with {pair[1]} here and with "
                f"{other[0][1]} in another phase: one target port per port of the tree"
            )
        pairs.append(tuple(pair))
    return tuple(pairs)


def _target_components(tree: SpacecraftTree, target: SpacecraftTree, pairs) -> list[Component]:
    """A target, switched between the tree's ports it mates with (module docstring)."""
    body = target.bodies[0]
    name = body.name
    offset = _origin_offset(body)
    children = [target.body(c) for c in target.children(name)]
    terms, links = [], []
    for port, target_port in pairs:
        spec, mate = tree.ports[port], target.ports[target_port]
        if mate.body != name:
            raise ValueError(
                f"ports.{target_port}: a captured or docked port must be on the target's root "
                f"body '{name}', not on '{mate.body}'"
            )
        delta = connection_parameter(switch_block_name(tree, port))
        terms.append((delta, offset + np.asarray(mate.p_B_D, dtype=float)))
        dcm_T_B = np.asarray(mate.R_B_D) @ np.asarray(spec.R_B_D).T  # v_T = dcm v_B
        links.append((delta, dcm_T_B, f"S{port}_{spec.body}"))
    mass, inertia = hub_parameters(body)
    root = Component(
        name,
        rigid_body_direct(
            mass,
            inertia,
            [offset + _joint_point(target, c) for c in children],
            np.zeros(3),
            parent_terms=terms,
            body=name,
        ),
        inputs=[f"W_J{c.name}_{name}" for c in children] + [f"xdd_S_{name}"],
        outputs=[f"xdd_J{c.name}_{name}" for c in children] + [f"W_S_{name}"],
    )
    n = len(links)
    size = 6 * n + 6
    switches = None
    for k, (delta, dcm, _) in enumerate(links):
        t = frame_change_matrix(dcm)
        select = np.zeros((12, size))  # [T xdd_k; T^T W_T]
        select[:6, 6 * k : 6 * k + 6] = t
        select[6:, 6 * n :] = t.T
        spread = np.zeros((size, 12))  # -> [xdd_T; W_1 .. W_n]
        spread[:6, :6] = np.eye(6)
        spread[6 + 6 * k : 12 + 6 * k, 6:] = np.eye(6)
        term = spread @ repeat(delta, 12) @ select
        switches = term if switches is None else switches + term
    switch = Component(
        f"switches_{name}",
        switches,
        inputs=[f"xdd_{suffix}" for *_, suffix in links] + [f"W_S_{name}"],
        outputs=[f"xdd_S_{name}"] + [f"W_{suffix}" for *_, suffix in links],
    )
    # schema 1's order: the target's root, its bodies, then the switches
    return [root, *_components(target, skip_root=True), switch]


def build_mission_tree_model(tree: SpacecraftTree) -> LFR:
    """One LFR of ``tree`` over all its mission's phases, targets included by switch blocks.

    Without captured or docked phases: :func:`build_tree_model`. Otherwise every target the
    mission mates is in the model, switched between the tree's ports it mates with (module
    docstring): blocks ``delta_<PORT>`` (range ``[0, 1]``, 12 + 4 occurrences), substituted
    by :meth:`oos_drake.scenario.tree_scenario.TreeScenario.mission_values` (``1`` through the
    phases that capture or dock at ``PORT``). With one ``delta_<PORT> = 1`` its nominal model
    is :func:`build_tree_model` of :func:`~oos_drake.scenario.tree.captured_tree` (the target
    welded at that port); with all ``0`` that of ``tree`` (plus the free target's uncoupled
    modes, if it has flexible bodies). Cached per tree object.

    Raises
    ------
    ValueError
        A mated port on a flexible body, a target port off its target's root body, or one port
        mated with two target ports.
    """
    if not mission_connections(tree):
        return build_tree_model(tree)
    return _mission_tree_model(tree)


@functools.lru_cache(maxsize=8)
def _mission_tree_model(tree: SpacecraftTree) -> LFR:
    pairs = mission_connections(tree)
    by_target: dict[str, list] = {}
    for port, target_port in pairs:
        owner = next(t for t, sub in tree.targets.items() if target_port in sub.ports)
        by_target.setdefault(owner, []).append((port, target_port))
    extra: dict[str, list] = {}
    for port, _ in pairs:
        spec = tree.ports[port]
        extra.setdefault(spec.body, []).append((f"S{port}_{spec.body}", spec.p_B_D))
    components = _components(tree, extra)
    for owner, owned in by_target.items():
        components += _target_components(tree, tree.targets[owner], owned)
    root = tree.root
    model = assemble(components, inputs=[f"W_ext_{root}"], outputs=[f"xdd_G_{root}"])
    return model.with_names(
        inputs=[f"{n}_{root}" for n in _INPUTS], outputs=[f"{n}_{root}" for n in _OUTPUTS]
    )


def tree_values(tree: SpacecraftTree, angles: dict[str, float] | None = None) -> dict:
    """Values of the scheduled blocks ``tau_<body> = tan(angle/4)``.

    Parameters
    ----------
    tree : SpacecraftTree
        The tree.
    angles : dict {body: angle [rad]}, optional
        Joint angles overriding the file's operating angles.

    Returns
    -------
    dict
        Block name -> value, for :func:`oos_drake.lfr.usubs`.
    """
    chosen = tree.joint_angles(angles)
    return {tree.angle_block(name): float(angle_to_tau(a)) for name, a in chosen.items()}


def tree_blocks(tree: SpacecraftTree) -> dict:
    """The tree's uncertain physical blocks (masses, inertias, mode frequencies) by name."""
    model = build_tree_model(tree)
    scheduled = {tree.angle_block(n) for n in tree.revolute_bodies}
    return {n: b for n, b in sorted(model.uncertainty.items()) if n not in scheduled}


def rigid_inertia_at_root(tree: SpacecraftTree, angles: dict[str, float] | None = None):
    """Rigid spatial inertia (6x6) of the whole tree at the root's centre of mass, root axes.

    A closed form independent of the LFR algebra (every body frozen, flexible ones at their rigid
    ``D_P``): the LFR's static gain is its inverse.
    """
    from oos_drake.titop.spatial import kinematic_matrix, rigid_spatial_inertia

    poses = body_poses(tree, angles)
    total = np.zeros((6, 6))
    for body in tree.bodies:
        R, p = poses[body.name]
        if body.kind == "rigid":
            d_local = rigid_spatial_inertia(body.mass, body.inertia, body.p_B_G)
        else:
            d_local = body.rigid_spatial_inertia
        T = np.kron(np.eye(2), R)
        d_rootaxes = T @ d_local @ T.T  # at the body origin, root axes
        tau = kinematic_matrix(-p)  # tau_{Bo G}: xdd_Bo = tau xdd_G for a rigid motion
        total += tau.T @ d_rootaxes @ tau
    return total
