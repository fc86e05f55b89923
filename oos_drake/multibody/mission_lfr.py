"""Uncertain LFRs of the Drake twin at the mission's configurations (``ulinearize`` on the twin).

The twin (:mod:`oos_drake.multibody.scenario_plant`) is placed at a configuration (moments 1-6,
docking phases 7 and 8: :func:`oos_drake.multibody.operating_point.set_operating_point`) and
:func:`oos_drake.multibody.uncertain_linearization.ulinearize` extracts the LFR from the wrench
at G1 to ``[a_G1; wdot]`` with the scenario's real parameters as ``ureal`` blocks:

==========================  =================================================================
``m_<hub>``                 hub mass (body ``oos_scenario::<hub>::<hub>``, quantity ``mass``)
``J{xx,yy,zz}_<hub>``       hub central moments of inertia (``Ixx``, ``Iyy``, ``Izz``)
``w1_<array>``              first cantilever mode of the array (its mode-1 joint, quantity
                            ``frequency``: spring ``k^2 w^2`` and damping ``2 xi w k^2``)
``k_shear_SM<i>``, ...      docking bushing SM1 (frames J7/D2), SM2 (D1/D3): ``force_stiffness``,
                            ``torque_stiffness``, ``force_damping``, ``torque_damping``
==========================  =================================================================

same names, nominal values and ranges as the TITOP LFR (:mod:`oos_drake.scenario.model`) for
the hub and array parameters; the TITOP spring-damper blocks span ``[0, 2 nominal]`` (stiffness
0 is allowed there, where the Drake declaration needs a positive range), so the docking
parameters are declared per case around the case's value.
"""

from __future__ import annotations

from collections.abc import Mapping

from oos_drake.lfr import LFR
from oos_drake.multibody.appendage_sdf import MODE_JOINT
from oos_drake.multibody.operating_point import OperatingPoint, set_operating_point
from oos_drake.multibody.scenario_plant import cached_scenario_diagram
from oos_drake.multibody.scenario_sdf import ASSEMBLY_MODEL
from oos_drake.multibody.uncertain_linearization import PhysicalParameter, ulinearize

__all__ = ["SPRING_QUANTITIES", "mission_parameters", "spring_damper_parameters", "twin_lfr"]

#: TITOP spring-damper block prefix -> bushing quantity.
SPRING_QUANTITIES = {
    "k_shear": "force_stiffness",
    "k_tors": "torque_stiffness",
    "d_shear": "force_damping",
    "d_tors": "torque_damping",
}
_BUSHING_FRAMES = {"SM1": "J7/D2", "SM2": "D1/D3"}


def mission_parameters(scenario=None) -> tuple[PhysicalParameter, ...]:
    """The scenario's real uncertain parameters as Drake declarations (TITOP names and ranges)."""
    from oos_drake.multibody.synthesis_plants import _scenario, uncertain_parameters

    scenario = _scenario(scenario)
    hubs = {hub.name for hub in scenario.hubs.values()}
    arrays = {mount.name for mount in scenario.arrays.values()}
    declared = []
    for p in uncertain_parameters(scenario):
        prefix, owner = p.name.split("_", 1)
        if owner in hubs:
            element = f"{ASSEMBLY_MODEL}::{owner}::{owner}"
            quantity = "mass" if prefix == "m" else "I" + prefix[1:]
        elif owner in arrays and prefix == "w1":
            element = f"{ASSEMBLY_MODEL}::{owner}::{MODE_JOINT.format(1)}"
            quantity = "frequency"
        else:
            raise ValueError(f"no Drake element for the scenario parameter {p.name!r}")
        declared.append(
            PhysicalParameter(p.name, element, quantity, p.nominal, float(p.lower), float(p.upper))
        )
    return tuple(declared)


def spring_damper_parameters(
    values: Mapping[str, float], percent: float = 50.0
) -> tuple[PhysicalParameter, ...]:
    """Bushing parameters named as the TITOP blocks, nominal = ``values``, range +- ``percent``.

    Parameters
    ----------
    values : Mapping[str, float]
        ``{"k_shear_SM1": k, "d_tors_SM2": d, ...}`` [N/m, N m/rad, N s/m, N m s/rad], > 0.
    percent : float
        Half range in percent of the nominal (< 100 keeps the range positive).
    """
    declared = []
    for name, value in sorted(values.items()):
        prefix, _, spring = name.rpartition("_")
        if prefix not in SPRING_QUANTITIES or spring not in _BUSHING_FRAMES:
            raise ValueError(f"unknown spring-damper parameter {name!r}")
        value = float(value)
        half = abs(value) * percent / 100.0
        declared.append(
            PhysicalParameter(
                name, _BUSHING_FRAMES[spring], SPRING_QUANTITIES[prefix], value,
                value - half, value + half,
            )
        )  # fmt: skip
    return tuple(declared)


def twin_lfr(point: OperatingPoint, parameters, *, sdf_directory=None, **options) -> LFR:
    """``ulinearize`` the twin at ``point``: ``[F; T]`` at G1 -> ``[a_G1; wdot]`` (6x6).

    Parameters that do not act at this configuration (the target's while it floats free) are
    dropped (zero repetitions). ``options`` go to :func:`ulinearize`.
    """
    from oos_drake.multibody.scenario_sdf import SDF_DIRECTORY

    directory = str(SDF_DIRECTORY if sdf_directory is None else sdf_directory)
    handles = cached_scenario_diagram(point.connection, directory)
    context = handles.diagram.CreateDefaultContext()
    set_operating_point(handles, context, point)
    options.setdefault("unused", "drop")
    # measured: round-off singular values <= 4.2e-7, true ones >= 9.6e-3 (docking phase 8)
    options.setdefault("rtol", 1e-5)
    return ulinearize(
        handles.diagram, context, parameters, handles.ports.wrench_input,
        f"{handles.ports.hub_output}[0:6]", **options,
    )  # fmt: skip
