"""Independent reference of the scenario tests: the inertia at G1 over the mission from the rigid
kinematics (``rigid_spatial_inertia_at_G1``), against which ``oos model figures``' inertia history
(from the LFR's static gain, :func:`oos_drake.scenario.figures.inertia_history_data`) is held."""

from dataclasses import dataclass

import numpy as np

from oos_drake.scenario.data import Scenario
from oos_drake.scenario.kinematics import rigid_spatial_inertia_at_G1
from oos_drake.scenario.timeline import mission_timeline


@dataclass(frozen=True, eq=False)
class InertiaHistory:
    """Mass properties of the connected system over time, at G1 in R_RH1.

    Attributes
    ----------
    time : (N,) ndarray
        Times [s].
    mass : (N,) ndarray
        Total connected mass [kg].
    center_of_mass : (N, 3) ndarray
        G1 -> system CoM in R_RH1 [m].
    inertia : (N, 3, 3) ndarray
        Inertia tensor at G1 in R_RH1 [kg m^2] (rotational block of ``D_G1``).
    """

    time: np.ndarray
    mass: np.ndarray
    center_of_mass: np.ndarray
    inertia: np.ndarray

    def entries(self) -> dict[str, np.ndarray]:
        """``{"Jxx", "Jyy", "Jzz", "Jxy", "Jxz", "Jyz"}`` -> (N,) tensor entries [kg m^2]."""
        J = self.inertia
        return {
            "Jxx": J[:, 0, 0],
            "Jyy": J[:, 1, 1],
            "Jzz": J[:, 2, 2],
            "Jxy": J[:, 0, 1],
            "Jxz": J[:, 0, 2],
            "Jyz": J[:, 1, 2],
        }


def inertia_history(scenario: Scenario | None = None, times=None) -> InertiaHistory:
    """Inertia tensor at G1 in R_RH1 along the mission (paper Fig. inertias).

    Parameters
    ----------
    scenario : Scenario, optional
        Default: the paper's.
    times : array_like, optional
        Times [s]; default 330 equally spaced times over the mission.
    """
    timeline = mission_timeline(scenario)
    if times is None:
        times = np.linspace(timeline.t_start, timeline.t_end, 330)
    configuration = timeline.configuration(np.atleast_1d(np.asarray(times, dtype=float)))
    D = rigid_spatial_inertia_at_G1(timeline.scenario, configuration)
    mass = D[:, 0, 0]
    # D[:3, 3:] = -m skew(c)  ->  c = vee(D[3:, :3]) / m
    first_moment = np.stack([D[:, 5, 1], D[:, 3, 2], D[:, 4, 0]], axis=-1)
    return InertiaHistory(
        time=configuration.time,
        mass=mass,
        center_of_mass=first_moment / mass[:, None],
        inertia=D[:, 3:, 3:],
    )
