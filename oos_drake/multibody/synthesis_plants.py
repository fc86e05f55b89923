"""Drake plant arrays for the H-infinity synthesis (``oos synth --plant drake``).

The synthesis (:mod:`oos_drake.control.synthesis`) needs, for every mission configuration ``i``
and every value of the real uncertain parameters ``Delta_real``, the rotational plant
``T_ext,G1 -> wdot`` as state-space matrices. This module gives it, as LFRs, from the Drake twin
instead of the TITOP LFR (:class:`DrakePlantSource`; the control package makes the plant array
of them: :func:`oos_drake.control.plants.lfr_source_plants`), the same way:

- nominal plants: the twin is placed at configuration ``i`` (mission time ``t_i``; arm and array
  drive angles locked, connection from the docking switches) and linearized once by
  :func:`oos_drake.multibody.operating_point.linearize_at`; the unreachable and unobservable
  states (chaser rigid-body motion, a free target) are pruned structurally and the 3x3 block
  ``[T] -> [wdot]`` is kept (~10 ms per configuration): :attr:`DrakePlantSource.nominal`, one
  certain LFR per configuration;
- plants at other parameter values (the worst-case search): configuration ``i``'s uncertain LFR
  is extracted from the twin by ``ulinearize`` (:meth:`DrakePlantSource.lfr`,
  :func:`oos_drake.multibody.mission_lfr.twin_lfr`, the TITOP block names, nominal values and
  ranges) the first time the search visits ``i``, kept, and the values are substituted into it
  (:func:`oos_drake.control.plants.lfr_statespace`), exactly as the TITOP path substitutes them
  into its LFR. An extraction (29 Taylor linearizations and the acceleration probes) costs as
  much as ~38 relinearizations at single parameter points (``benchmarks/
  bench_synthesis_plants.py``); a search round evaluates ~90 points per configuration it visits
  (a few per round) and later rounds reuse the extraction. Nothing is relinearized per point.
- every model of the array has the same number of states (the largest pruned order, 48 for the
  paper): models with fewer states (free target: the target's modes are not reachable) are padded
  with decoupled states at :data:`PADDING_POLE` ``= -1 rad/s`` (``B = 0``, ``C = 0``; done by the
  control package's plant array): the transfer function, hence every
  closed-loop H-infinity norm, is unchanged. The LFR array carries those target modes as
  decoupled states too.

:func:`rotational_plant` with parameter ``values`` (written into the **Context parameters** of
the cached diagram by :func:`apply_physical_values`, no rebuild) is the independent reference the
tests hold the extracted LFRs to:

===============================  ==============================================================
``m_RH2``, ``J{xx,yy,zz}_RH2``   target hub spatial inertia (link frame at its centre of mass
                                 G2, products of inertia nominal),
                                 ``RigidBody.SetSpatialInertiaInBodyFrame``
``w1_SA<k>``                     first cantilever mode of array k: the mode body's hinge spring
                                 ``k^2 w^2`` and damping ``2 xi w k^2`` scaled by
                                 ``(w / w_0)^2`` and ``w / w_0`` (same ``xi``, same participation:
                                 the LFR's ``w1`` block occurs in both terms)
===============================  ==============================================================
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from oos_drake.lfr import LFR
from oos_drake.multibody.appendage_sdf import MODE_JOINT
from oos_drake.multibody.linearization import structural_prune
from oos_drake.multibody.mission_lfr import (
    PADDING_POLE,
    mission_parameters,
    twin_lfr,
    uncertain_parameters,
)
from oos_drake.multibody.operating_point import linearize_at, operating_point
from oos_drake.multibody.plant_parts import (
    revolute_spring,
    set_central_inertia,
    set_mode_frequency,
)
from oos_drake.multibody.scenario_plant import ScenarioDiagram, twin_diagram
from oos_drake.multibody.scenario_sdf import ASSEMBLY_MODEL
from oos_drake.scenario.timeline import mission_timeline
from oos_drake.titop.parameters import inertia_names, mass_name, mode_frequency_name

__all__ = [
    "PADDING_POLE",
    "apply_physical_values",
    "rotational_plant",
    "DrakePlantSource",
]


def apply_physical_values(
    handles: ScenarioDiagram, context, values: Mapping[str, float], scenario
) -> None:
    """Write real-parameter values into a root ``context`` of ``handles.diagram`` (no rebuild).

    Parameters
    ----------
    handles : ScenarioDiagram
        A cached scenario diagram.
    context : Context
        Its root context (other parameters keep their values; call on a fresh context).
    values : Mapping[str, float]
        Physical values by block name: ``m_RH2`` [kg], ``Jxx_RH2``/``Jyy_RH2``/``Jzz_RH2``
        [kg m^2] (diagonal of the inertia at G2 in ``R_RH2``), ``w1_SA<k>`` [rad/s].
    scenario : Scenario
        The twin's scenario (its hubs' and arrays' names and nominal frequencies).

    Raises
    ------
    ValueError
        Unknown parameter name, or a non-finite or non-positive value.
    """
    plant = handles.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)
    hub_names = {}
    for hub in scenario.hubs.values():
        hub_names[mass_name(hub.name)] = (hub.name, None)
        for axis, name in enumerate(inertia_names(hub.name)):
            hub_names[name] = (hub.name, axis)
    array_names = {mode_frequency_name(m.name, 1): m for m in scenario.arrays.values()}
    hubs_touched = {}  # hub name -> (mass, {axis: moment}), written at once (physical together)
    for name, value in values.items():
        value = float(value)
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"physical value of {name!r} must be finite and > 0, got {value}")
        if name in hub_names:
            hub_name, axis = hub_names[name]
            mass, moments = hubs_touched.setdefault(hub_name, (None, {}))
            if axis is None:
                hubs_touched[hub_name] = (value, moments)
            else:
                moments[axis] = value
        elif name in array_names:
            mount = array_names[name]
            instance = plant.GetModelInstanceByName(f"{ASSEMBLY_MODEL}::{mount.name}")
            joint = plant.GetJointByName(MODE_JOINT.format(1), instance)
            spring = revolute_spring(plant, joint)
            if spring is None:
                raise ValueError(f"no RevoluteSpring on joint {joint.name()!r} of the Drake twin")
            set_mode_frequency(spring, joint, plant_context, value / float(mount.model.omega[0]))
        else:
            known = sorted(hub_names) + sorted(array_names)
            raise ValueError(f"unknown real parameter {name!r} for the Drake twin; known: {known}")
    for hub_name, (mass, moments) in hubs_touched.items():
        instance = plant.GetModelInstanceByName(f"{ASSEMBLY_MODEL}::{hub_name}")
        body = plant.GetBodyByName(hub_name, instance)
        set_central_inertia(body, plant_context, mass, moments)


def rotational_plant(
    configuration, scenario, values: Mapping[str, float] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Linearize the twin of ``scenario`` at one configuration: pruned ``T_ext,G1 -> wdot``
    (3x3).

    Parameters
    ----------
    configuration : oos_drake.scenario.timeline.Configuration
        One (non-batch) configuration; rigid connections from its switches.
    scenario : Scenario
        The twin's scenario (:func:`~oos_drake.multibody.scenario_plant.twin_diagram`).
    values : Mapping[str, float], optional
        Physical values of real parameters (see :func:`apply_physical_values`); others nominal.

    Returns
    -------
    tuple of numpy.ndarray
        ``(A, B, C, D)``: inputs ``Tx, Ty, Tz`` [N m], outputs ``wdot_x..z`` [rad/s^2].
    """
    point = operating_point(configuration)
    handles = twin_diagram(scenario, point.connection)
    context = handles.diagram.CreateDefaultContext()
    if values:
        apply_physical_values(handles, context, values, scenario)
    system = structural_prune(linearize_at(point, handles, context)[3:6, 3:6])
    return tuple(np.asarray(M, dtype=float) for M in (system.A, system.B, system.C, system.D))


class DrakePlantSource:
    """Drake twin plants per configuration as LFRs: nominal linearizations (certain LFRs) and,
    on demand, the uncertain LFR extracted by ``ulinearize``.

    Parameters
    ----------
    times : array_like, shape (N,)
        Mission times [s] of the configurations.
    scenario : Scenario
        The plants' scenario (its own twin:
        :func:`~oos_drake.multibody.scenario_plant.twin_diagram`).
    progress : callable, optional
        ``progress(done, total)`` during the nominal linearizations.

    Attributes
    ----------
    nominal : tuple of oos_drake.lfr.LFR
        Each configuration's pruned plant ``T -> wdot`` at the nominal parameter values (a
        certain LFR; orders differ with the pruning).
    parameters : tuple of oos_drake.control.plants.UncertainParameter
        The scenario's real uncertain parameters.
    build_time_s : float
        Wall time of the nominal linearizations [s].
    extractions : int
        LFRs extracted so far (at most one per configuration).
    extraction_time_s : float
        Wall time of those extractions [s].
    """

    def __init__(
        self,
        times: Sequence[float],
        scenario,
        *,
        progress: Callable | None = None,
    ):
        self.scenario = scenario
        self.times = np.asarray(times, dtype=float).ravel()
        if self.times.size == 0 or not np.all(np.isfinite(self.times)):
            raise ValueError(f"DrakePlantSource: times must be finite and non-empty, got {times}")
        timeline = mission_timeline(self.scenario)
        batch = timeline.configuration(self.times)
        self.configurations = [batch[i] for i in range(self.times.size)]
        self.parameters = uncertain_parameters(self.scenario)
        self.declared = mission_parameters(self.scenario)
        self._lfrs: dict[int, LFR] = {}
        self.extractions = 0
        self.extraction_time_s = 0.0
        wall = time.perf_counter()
        raw = []
        for i, configuration in enumerate(self.configurations):
            raw.append(rotational_plant(configuration, self.scenario))
            if progress is not None:
                progress(i + 1, self.times.size)
        self.linearizations = len(raw)
        self.nominal = tuple(LFR.from_ss(*m) for m in raw)
        self.build_time_s = time.perf_counter() - wall

    def lfr(self, index: int) -> LFR:
        """The uncertain plant ``T -> wdot`` of configuration ``index`` (extracted once).

        ``ulinearize`` of the twin (:func:`~oos_drake.multibody.mission_lfr.twin_lfr`) with the
        scenario's real parameters; the ones that do not act at this configuration (a free
        target's) are absent.
        """
        index = int(index)
        if index not in self._lfrs:
            wall = time.perf_counter()
            point = operating_point(self.configurations[index])
            self._lfrs[index] = twin_lfr(self.scenario, point, self.declared)[3:6, 3:6]
            self.extractions += 1
            self.extraction_time_s += time.perf_counter() - wall
        return self._lfrs[index]

    def statistics(self) -> dict:
        """Cost of the models so far: linearizations, extractions and their times [s]."""
        return {
            "nominal_linearizations": self.linearizations,
            "nominal_linearization_time_s": round(self.build_time_s, 3),
            "lfr_extractions": self.extractions,
            "lfr_extraction_time_s": round(self.extraction_time_s, 3),
        }
