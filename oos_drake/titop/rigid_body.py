"""Multi-port rigid body (inverse dynamic model), its inverted-port (direct) form and rigid links.

Inverse model at ``n`` ports ``P_i`` plus the external wrench at the center of mass ``G``
(SDT's *Multi-port rigid body*):

.. math::

    \\ddot x_G = D_G^{-1} \\left(W_{ext} + \\sum_i \\tau_{P_i G}^T W_i\\right), \\qquad
    \\ddot x_{P_i} = \\tau_{P_i G} \\ddot x_G, \\qquad D_G = \\mathrm{diag}(m I_3, J_G)

``W_i`` is the wrench applied *to* the body at ``P_i``. Inverting one port ``D`` (partial
inversion of its 6 channels, MATLAB ``invio``) gives the direct model at ``D``: the port's input
becomes the acceleration twist ``xdd_D`` and its output the wrench the body applies *to its parent*
at ``D`` (the TITOP child convention, i.e. minus the inverse model's input):

.. math::

    \\ddot x_G = \\tau_{GD} \\ddot x_D, \\qquad
    W_{body/parent, D} = \\tau_{GD}^T \\left(W_{ext} + \\sum_{i} \\tau_{P_i G}^T W_i
    - D_G \\ddot x_G\\right)

In this form ``m`` occurs 3 times and each uncertain diagonal inertia once; a parameter-dependent
port position ``GD = sum_k delta_k v_k`` gives 2 occurrences of ``delta_k`` in ``tau_GD`` and 2 in
``tau_GD^T`` (the paper's ``delta_C1 I4``, ``delta_C2 I4`` for RH2's shared port D2/D3).
A rigid link is the two-port direct model (parent port inverted):
``[xdd_C; W_P] = [[0, tau_CP], [tau_CP^T, -D_P]] [W_C; xdd_P]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, hstack, inv, vstack
from oos_drake.titop.kinematics import kinematic_model, kinematic_model_transposed, repeat
from oos_drake.titop.parameters import inertia_names, mass_name, relative_parameter
from oos_drake.titop.spatial import kinematic_matrix

__all__ = [
    "uncertain_mass",
    "uncertain_inertia",
    "spatial_inertia_lfr",
    "rigid_body_inverse",
    "rigid_body_direct",
    "rigid_link",
]


def _check_mass(mass, body: str):
    if isinstance(mass, LFR):
        if mass.shape != (1, 1):
            raise ValueError(f"{body}: mass must be a float or a 1x1 LFR, got shape {mass.shape}")
        return mass
    mass = float(mass)
    if not mass > 0:
        raise ValueError(f"{body}: mass must be > 0 kg, got {mass}")
    return mass


def _check_inertia(inertia, body: str):
    if isinstance(inertia, LFR):
        if inertia.shape != (3, 3):
            raise ValueError(f"{body}: inertia LFR must be 3x3, got shape {inertia.shape}")
        return inertia
    inertia = np.asarray(inertia, dtype=float)
    if inertia.shape != (3, 3) or not np.allclose(inertia, inertia.T, atol=1e-12):
        raise ValueError(f"{body}: inertia must be a symmetric 3x3 matrix [kg m^2]")
    if np.min(np.linalg.eigvalsh(inertia)) <= 0:
        raise ValueError(f"{body}: inertia must be positive definite, got {inertia.tolist()}")
    return inertia


def uncertain_mass(body: str, nominal: float, percent: float | None):
    """Mass parameter ``m_<body>`` [kg] (ureal with relative ``percent``, or a float if None)."""
    if not nominal > 0:
        raise ValueError(f"{body}: mass must be > 0 kg, got {nominal}")
    return relative_parameter(mass_name(body), nominal, percent, unit="kg", quantity="mass")


def uncertain_inertia(body: str, inertia_G, percent: float | Sequence[float] | None) -> LFR:
    """Inertia tensor with uncertain diagonals ``Jxx_<body>``, ``Jyy_<body>``, ``Jzz_<body>``.

    Parameters
    ----------
    body : str
        Body name used in the block names.
    inertia_G : array_like, shape (3, 3)
        Nominal inertia at the center of mass [kg m^2]; off-diagonal terms stay nominal.
    percent : float, sequence of 3 floats or None
        Relative uncertainty of each diagonal entry [%]; None gives a constant LFR.

    Returns
    -------
    LFR (3x3)
        Each diagonal block occurs once.
    """
    inertia_G = _check_inertia(inertia_G, body)
    if percent is None:
        return as_lfr(inertia_G)
    percents = np.broadcast_to(np.asarray(percent, dtype=float), (3,))
    off_diagonal = inertia_G - np.diag(np.diag(inertia_G))
    diagonal = [
        relative_parameter(name, inertia_G[k, k], percents[k], unit="kg m^2", quantity="inertia")
        for k, name in enumerate(inertia_names(body))
    ]
    return as_lfr(off_diagonal) + append(*[as_lfr(d) for d in diagonal])


def spatial_inertia_lfr(mass, inertia_G, body: str = "body") -> LFR:
    """``D_G = diag(m I3, J_G)`` as a 6x6 LFR (``m`` 3 occurrences if uncertain).

    Parameters
    ----------
    mass : float or LFR (1x1)
        Mass [kg].
    inertia_G : array_like (3, 3) or LFR (3x3)
        Inertia at the center of mass [kg m^2].
    body : str
        Name used in error messages.
    """
    mass = _check_mass(mass, body)
    inertia_G = _check_inertia(inertia_G, body)
    return append(repeat(mass, 3), as_lfr(inertia_G))


def _port_vectors(ports, body: str) -> list[np.ndarray]:
    vectors = []
    for k, p in enumerate(ports):
        p = np.asarray(p, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{body}: port {k} position must be a finite 3-vector [m], got {p}")
        vectors.append(p)
    return vectors


def rigid_body_inverse(mass, inertia_G, ports_GP: Sequence, *, body: str = "body") -> LFR:
    """Inverse dynamic model of a rigid body at ``n`` ports plus the external wrench at ``G``.

    Parameters
    ----------
    mass : float or LFR (1x1)
        Mass [kg] (an uncertain mass occurs 3 times).
    inertia_G : array_like (3, 3) or LFR (3x3)
        Inertia at ``G`` in the body frame [kg m^2].
    ports_GP : sequence of array_like (3,)
        Vectors ``G -> P_i`` in the body frame [m].
    body : str
        Name used in error messages.

    Returns
    -------
    LFR
        Static, inputs ``[W_ext,G; W_1; ...; W_n]`` (wrenches applied to the body, [N; N m]),
        outputs ``[xdd_G; xdd_P1; ...; xdd_Pn]`` ([m/s^2; rad/s^2]), all in the body frame.
    """
    vectors = _port_vectors(ports_GP, body)
    taus = [kinematic_matrix(-p) for p in vectors]  # tau_{P_i G}: vector P_i -> G = -GP_i
    mass = _check_mass(mass, body)
    inertia_G = _check_inertia(inertia_G, body)
    if isinstance(mass, LFR) or isinstance(inertia_G, LFR):
        d_inverse = inv(spatial_inertia_lfr(mass, inertia_G, body))
    else:
        d_numeric = np.zeros((6, 6))
        d_numeric[:3, :3] = mass * np.eye(3)
        d_numeric[3:, 3:] = inertia_G
        d_inverse = as_lfr(np.linalg.inv(d_numeric))
    gather = np.hstack([np.eye(6)] + [t.T for t in taus])
    spread = np.vstack([np.eye(6)] + taus)
    return spread @ d_inverse @ gather


def rigid_body_direct(
    mass,
    inertia_G,
    children_GP: Sequence,
    parent_GD=(0.0, 0.0, 0.0),
    *,
    parent_terms: Sequence[tuple[LFR, Sequence[float]]] = (),
    external: bool = False,
    body: str = "body",
) -> LFR:
    """Rigid body with one inverted port ``D`` (direct model at ``D``) and ``n`` child ports.

    Parameters
    ----------
    mass : float or LFR (1x1)
        Mass [kg] (3 occurrences if uncertain).
    inertia_G : array_like (3, 3) or LFR (3x3)
        Inertia at ``G`` [kg m^2] (one occurrence per uncertain diagonal entry).
    children_GP : sequence of array_like (3,)
        Vectors ``G -> P_i`` of the (inverse-model) child ports [m].
    parent_GD : array_like (3,)
        Constant part of the vector ``G -> D`` of the inverted port [m].
    parent_terms : sequence of (LFR, array_like)
        Parameter-dependent parts ``(delta_k, v_k)`` of ``G -> D`` [m] (e.g. RH2's
        ``delta_C1 G2D2 + delta_C2 G2D3``): 4 occurrences of each ``delta_k``.
    external : bool
        Add the external wrench at ``G`` as first input and ``xdd_G`` as first output.
    body : str
        Name used in error messages.

    Returns
    -------
    LFR
        Static, inputs ``[W_ext (if external); W_1; ...; W_n; xdd_D]``, outputs
        ``[xdd_G (if external); xdd_P1; ...; xdd_Pn; W_body/parent,D]``, body frame, SI units.
        ``W_i`` are wrenches applied to the body by its children; the last output is the wrench
        the body applies to its parent at ``D``.
    """
    vectors = _port_vectors(children_GP, body)
    n = len(vectors)
    n_ext = 6 if external else 0
    tau_GD = kinematic_model(parent_GD, parent_terms)
    tau_GD_T = kinematic_model_transposed(parent_GD, parent_terms)
    d_G = spatial_inertia_lfr(mass, inertia_G, body)
    taus = [kinematic_matrix(-p) for p in vectors]  # tau_{P_i G}
    n_pass = n_ext + 6 * n
    # stage 1: [W_ext; W_i; xdd_D] -> [W_ext; W_i; xdd_G]
    stage1 = append(as_lfr(np.eye(n_pass)), tau_GD) if n_pass else tau_GD
    # stage 2: [W_ext; W_i; xdd_G] -> [xdd_G; xdd_Pi; W_net,G],
    # W_net = W_ext + sum tau^T W_i - D_G a_G
    copy_rows = np.zeros((6 + 6 * n, n_pass + 6))
    copy_rows[:6, n_pass:] = np.eye(6)
    for k, t in enumerate(taus):
        copy_rows[6 + 6 * k : 12 + 6 * k, n_pass:] = t
    if n_pass:
        gather = np.hstack(([np.eye(6)] if external else []) + [t.T for t in taus])
        net_row = hstack([as_lfr(gather), -1.0 * d_G])
    else:
        net_row = -1.0 * d_G
    stage2 = vstack([as_lfr(copy_rows), net_row])
    # stage 3: W_net,G -> W_body/parent,D = tau_GD^T W_net
    stage3 = append(as_lfr(np.eye(6 + 6 * n)), tau_GD_T)
    full = stage3 @ stage2 @ stage1  # outputs [xdd_G; xdd_Pi; W_D]
    if not external:
        full = full[6:, :]
    return full


def rigid_link(mass, inertia_G, p_GP, p_GC, *, body: str = "link") -> LFR:
    """Rigid link two-port ``D_{PC}`` between parent point ``P`` and child point ``C``.

    Parameters
    ----------
    mass : float or LFR (1x1)
        Link mass [kg].
    inertia_G : array_like (3, 3) or LFR (3x3)
        Inertia at the link's center of mass ``G`` in the link frame [kg m^2].
    p_GP, p_GC : array_like (3,)
        Vectors ``G -> P`` (parent joint) and ``G -> C`` (child joint) in the link frame [m].

    Returns
    -------
    LFR
        ``[xdd_C; W_P] = [[0, tau_CP], [tau_CP^T, -D_P]] [W_C; xdd_P]`` (static, 12 x 12), with
        ``W_C`` the wrench applied by the child to the link at ``C`` and ``W_P`` the wrench the link
        applies to its parent at ``P``.
    """
    return rigid_body_direct(mass, inertia_G, [p_GC], p_GP, body=body)
