"""The paper's baseline attitude controller (section 3.1).

.. math::

    u = K_{att} \\begin{bmatrix} \\phi_{ref} - \\phi \\\\ \\omega_{ref} - \\omega \\end{bmatrix},
    \\quad K_{att} = [\\omega_{att}^2 J_{tot},\\; 2 \\xi_{att} \\omega_{att} J_{tot}]

tuned on the inertia ``J_tot`` of the coupled system at the first docking (t = 255 s), with
``xi_att = 1`` and ``omega_att = 2 pi 0.01`` rad/s: a critically damped PD per principal axis.
"""

from __future__ import annotations

import numpy as np

from oos_drake.control.statespace import BatchedStateSpace

#: Baseline natural frequency [rad/s] (paper: 0.01 Hz).
OMEGA_ATT = 2.0 * np.pi * 0.01
#: Baseline damping ratio [-] (paper: 1).
XI_ATT = 1.0
#: Time of the first docking, where the baseline is tuned [s].
TUNING_TIME_S = 255.0


def baseline_gains(J_tot, omega_att: float = OMEGA_ATT, xi_att: float = XI_ATT) -> np.ndarray:
    """Return ``K_att = [omega^2 J_tot, 2 xi omega J_tot]`` (3x6).

    Parameters
    ----------
    J_tot : array_like, shape (3, 3)
        Total inertia of the coupled system at G1 in R_RH1 [kg m^2].
    omega_att : float
        Natural frequency [rad/s].
    xi_att : float
        Damping ratio [-].

    Returns
    -------
    numpy.ndarray, shape (3, 6)
        ``[K_p, K_d]``: ``K_p`` [N m/rad], ``K_d`` [N m s/rad].
    """
    J = np.asarray(J_tot, dtype=float)
    if J.shape != (3, 3):
        raise ValueError(f"baseline: J_tot must be 3x3, got shape {J.shape}")
    if not np.allclose(J, J.T, rtol=1e-8, atol=1e-10) or np.linalg.eigvalsh(J).min() <= 0:
        raise ValueError("baseline: J_tot must be symmetric positive definite")
    if omega_att <= 0 or xi_att <= 0:
        raise ValueError(
            f"baseline: omega_att and xi_att must be positive, got {omega_att}, {xi_att}"
        )
    return np.hstack([omega_att**2 * J, 2.0 * xi_att * omega_att * J])


def inertia_from_plant(plant: BatchedStateSpace) -> np.ndarray:
    """Inertia seen by the torques, ``J = G(0)^-1`` of the plant ``T -> wdot`` [kg m^2].

    For a free-floating flexible spacecraft the static gain of ``T_ext -> wdot`` is the inverse
    of the total inertia (the rotational Schur complement when the centre of mass is not at G1).
    Batched over leading dimensions; symmetrized.
    """
    A, B, C, D = plant.A, plant.B, plant.C, plant.D
    if plant.nstates:
        G0 = D - C @ np.linalg.solve(A, B)
    else:
        G0 = D
    J = np.linalg.inv(G0)
    return 0.5 * (J + np.swapaxes(J, -1, -2))


def baseline_for(plants, tuning_time: float = TUNING_TIME_S) -> np.ndarray:
    """Baseline gain tuned on the configuration of ``plants`` (a ``PlantArray``) closest to
    ``tuning_time`` [s] (the first docking: the paper's 255 s, a scenario's
    ``mission.first_docking_time``)."""
    table = plants.configurations
    if "time [s]" in table:
        k = int(np.argmin(np.abs(table["time [s]"].to_numpy() - tuning_time)))
    else:
        k = 0
    J = inertia_from_plant(plants.evaluate([k]))[0]
    return baseline_gains(J)


def scenario_baseline_gains(scenario) -> np.ndarray:
    """The paper's baseline gain (section 3.1) on ``scenario``: the one derivation.

    ``K_att = [omega_att^2 J_tot, 2 xi_att omega_att J_tot]`` (:func:`baseline_gains`,
    ``omega_att = 2 pi 0.01`` rad/s, ``xi_att = 1``) with ``J_tot = G(0)^-1`` the total inertia
    seen by the torques (:func:`inertia_from_plant`) of the scenario's nominal model
    ``T_ext,G1 -> wdot`` at its first docking (``mission.first_docking_time``). On the paper's
    scenario this equals the Schur complement of the rigid spatial inertia at G1 to 1e-14
    (``tests/test_baseline_once.py``). Both the analysis (``oos analyze`` without
    ``--controller``) and the Drake mission (``oos mission`` without ``--controller``) call it.

    Parameters
    ----------
    scenario : Scenario
        Loaded scenario (paper or tree).

    Returns
    -------
    numpy.ndarray, shape (3, 6)
        ``[K_p, K_d]``: ``K_p`` [N m/rad], ``K_d`` [N m s/rad].
    """
    from oos_drake.control.analysis_model import rotational_channels
    from oos_drake.control.interconnection import plant_statespace
    from oos_drake.lfr import usubs
    from oos_drake.scenario.model import build_mission_model, mission_values

    tuning_time = float(scenario.mission.first_docking_time)
    plant = usubs(build_mission_model(scenario), mission_values([tuning_time], scenario)).model(0)
    nominal = rotational_channels(plant).nominal
    n = nominal.nstates
    M = np.asarray(nominal.M, dtype=float)
    J = inertia_from_plant(plant_statespace(M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]))
    return baseline_gains(J, OMEGA_ATT, XI_ATT)
