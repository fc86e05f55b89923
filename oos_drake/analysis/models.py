"""Closed-loop model arrays of the analysis: the mission (paper M_330) and the docking phases.

``mission_closed_loop`` substitutes the scheduled blocks (arm angles, array angles, connection
switches) of the scenario LFR at equally spaced mission times and closes the loop with the
controller and ``Delta_add``, ``Delta_mul``: ``Delta_tot`` stays uncertain.
``docking_closed_loop`` does the same with the spring-damper LFRs of the docking phases, the
configuration frozen at the phase's instant and the active spring-damper's stiffness swept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.analysis.controller import Controller
from oos_drake.control.analysis_model import close_loop
from oos_drake.control.plants import mission_times  # noqa: F401  (the synthesis's mission grid)
from oos_drake.lfr import LFR, usubs


@dataclass(frozen=True)
class ModelArray:
    """Uncertain closed loops along one scheduling variable.

    Attributes
    ----------
    system : LFR
        Model array ``(N,)``: ``d -> e`` with the blocks of ``Delta_tot``.
    values : numpy.ndarray
        Scheduling value of each model: mission time [s] or stiffness [N/m, N m/rad].
    label : str
        Name of the scheduling variable with its unit (``"time [s]"``, ``"stiffness [N/m]"``).
    study : str
        ``"mission"``, ``"docking-7"`` or ``"docking-8"``.
    """

    system: LFR
    values: np.ndarray
    label: str
    study: str


def _check_source(source: str) -> None:
    if source not in PLANT_SOURCES:
        raise ValueError(f"plant source must be one of {PLANT_SOURCES}, got {source!r}")


#: Sources of the uncertain plants: the TITOP LFR or LFRs extracted from the Drake twin.
PLANT_SOURCES = ("lfr", "drake")


def mission_plants(times, scenario, *, source: str = "lfr", executor=None) -> LFR:
    """The uncertain 6x6 plants ``[F; T] at G1 -> [a; wdot]`` at mission ``times`` [s].

    A model array ``(N,)`` whose blocks are ``Delta_real``: the TITOP LFR with the configuration
    substituted (``source="lfr"``) or the Drake twin's LFRs extracted by ``ulinearize``
    (``source="drake"``, :func:`oos_drake.multibody.mission_lfr.twin_mission_plants`, one
    extraction per time, as tasks of ``executor`` when given: spawned workers).
    """
    from oos_drake.scenario.model import build_mission_model, mission_values

    _check_source(source)
    times = np.atleast_1d(np.asarray(times, dtype=float))
    if source == "drake":
        from oos_drake.multibody.mission_lfr import twin_mission_plants

        return twin_mission_plants(times, scenario, executor=executor)
    return usubs(build_mission_model(scenario), mission_values(times, scenario))


def mission_closed_loop(
    controller: Controller, times, scenario, *, source: str = "lfr", executor=None
) -> ModelArray:
    """``M_hat_N``: the uncertain closed loop at mission ``times`` [s] (plants of
    :func:`mission_plants` from ``source``, extracted on ``executor``)."""
    times = np.atleast_1d(np.asarray(times, dtype=float))
    plant = mission_plants(times, scenario, source=source, executor=executor)
    system = close_loop(plant, controller.system, controller.spec)
    return ModelArray(system, times, "time [s]", "mission")


def phase_configuration(phase: str, scenario):
    """Named configuration of docking phase ``"7"`` or ``"8"`` (timeline)."""
    from oos_drake.scenario.timeline import mission_timeline

    phases = mission_timeline(scenario).docking_phases
    if str(phase) not in phases:
        raise ValueError(f"docking phase must be one of {sorted(phases)}, got {phase!r}")
    return phases[str(phase)]


def docking_closed_loop(
    controller: Controller, phase: str, stiffness, *, scenario, damping=None, source="lfr"
) -> ModelArray:
    """Uncertain closed loop of docking phase 7 or 8 for each swept stiffness (plants of
    :func:`docking_plant`, same parameters)."""
    stiffness = np.atleast_1d(np.asarray(stiffness, dtype=float))
    plant = docking_plant(phase, stiffness, damping=damping, scenario=scenario, source=source)
    system = close_loop(plant, controller.system, controller.spec)
    return ModelArray(system, stiffness, "stiffness [N/m or N m/rad]", f"docking-{phase}")


def docking_springs(phase: str, stiffness, *, scenario, damping=None) -> dict:
    """Spring-dampers of docking phase ``"7"`` or ``"8"`` as the docking study sets them.

    Returns
    -------
    dict
        ``{"SM1" or "SM2": (stiffness, damping)}``: the swept one (phase 7: SM1, phase 8: SM2)
        at ``stiffness`` [N/m = N m/rad, shear and torsion alike] and ``damping`` [N s/m =
        N m s/rad] (default: scenario), and in phase 8 SM1 at the scenario's rigid values.
    """
    settings = scenario.docking
    damping = float(settings.damping if damping is None else damping)
    springs = {"SM1" if str(phase) == "7" else "SM2": (stiffness, damping)}
    if str(phase) == "8":
        springs["SM1"] = (settings.rigid_stiffness, settings.rigid_damping)
    return springs


def docking_plant(phase: str, stiffness, *, scenario, damping=None, source="lfr") -> LFR:
    """Uncertain plant (``Delta_real`` blocks) of docking phase 7 or 8 for each swept stiffness.

    A tree (schema 2): ``phase`` is a docking event of its mission
    (:meth:`oos_drake.scenario.tree_scenario.TreeScenario.docking_plant`, ``damping`` default
    the file's). Phase 7: SM1 (arm tip J7 / target port D2) has stiffness ``k`` (shear [N/m]
    and torsion [N m/rad] alike) and damping ``damping``; SM2 is open. Phase 8: SM2 (D1 / D3)
    is swept, SM1 is the already rigid connection (scenario ``rigid_stiffness``, ``rigid_damping``).

    Parameters
    ----------
    phase : {"7", "8"}
    stiffness : array_like
        Swept stiffness values (paper: 300 values, 0.1 .. 1e5, log spaced).
    damping : float, optional
        Damping of the swept spring-damper [N s/m, N m s/rad] (default: scenario, paper 100).
    scenario : Scenario
    source : {"lfr", "drake"}
        TITOP LFR, or the Drake twin's LFR (one ``ulinearize`` per phase, the stiffness
        substituted: :func:`oos_drake.multibody.mission_lfr.twin_docking_plants`).
    """
    from oos_drake.scenario.model import build_docking_model, configuration_values
    from oos_drake.scenario.tree_scenario import NotForTrees, is_tree

    _check_source(source)
    phase = str(phase)
    if is_tree(scenario):  # a tree's docking event: TreeScenario.docking_plant
        if source == "drake":
            raise NotForTrees("docking: --plant drake is not available for a tree's docking")
        return scenario.docking_plant(phase, stiffness, damping=damping)
    stiffness = np.atleast_1d(np.asarray(stiffness, dtype=float))
    if np.any(stiffness < 0) or not np.all(np.isfinite(stiffness)):
        raise ValueError("docking: stiffness values must be finite and >= 0")
    settings = scenario.docking
    damping = float(settings.damping if damping is None else damping)
    if source == "drake":
        from oos_drake.multibody.mission_lfr import twin_docking_plants

        return twin_docking_plants(phase, stiffness, damping, scenario)
    model = build_docking_model(phase, scenario)
    named = phase_configuration(phase, scenario)
    cfg = named.configuration
    values = configuration_values(cfg.alpha, cfg.theta, cfg.delta_C1, cfg.delta_C2)
    swept = "SM1" if phase == "7" else "SM2"
    springs = docking_springs(phase, stiffness, damping=damping, scenario=scenario)
    for name, (k, d) in springs.items():
        size = stiffness.size if name == swept else None
        values.update(
            {
                f"k_shear_{name}": k,
                f"k_tors_{name}": k,
                f"d_shear_{name}": d if size is None else np.full(size, d),
                f"d_tors_{name}": d if size is None else np.full(size, d),
            }
        )
    present = model.uncertainty
    values = {k: v for k, v in values.items() if k in present}
    return usubs(model, values)
