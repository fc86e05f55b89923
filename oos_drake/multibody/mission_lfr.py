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

import numpy as np

from oos_drake.blas import with_single_threaded_blas
from oos_drake.control.plants import UncertainParameter
from oos_drake.lfr import LFR, usubs
from oos_drake.lfr.core import BlockEntry
from oos_drake.multibody.appendage_sdf import MODE_JOINT
from oos_drake.multibody.operating_point import (
    OperatingPoint,
    operating_point,
    set_operating_point,
)
from oos_drake.multibody.scenario_plant import twin_diagram
from oos_drake.multibody.scenario_sdf import ASSEMBLY_MODEL
from oos_drake.multibody.uncertain_linearization import PhysicalParameter, ulinearize
from oos_drake.scenario.timeline import mission_timeline
from oos_drake.titop.parameters import inertia_names, mass_name, mode_frequency_name

__all__ = [
    "SPRING_QUANTITIES",
    "mission_parameters",
    "spring_damper_parameters",
    "twin_lfr",
    "uncertain_parameters",
]

#: TITOP spring-damper block prefix -> bushing quantity.
SPRING_QUANTITIES = {
    "k_shear": "force_stiffness",
    "k_tors": "torque_stiffness",
    "d_shear": "force_damping",
    "d_tors": "torque_damping",
}
_BUSHING_FRAMES = {"SM1": "J7/D2", "SM2": "D1/D3"}


def uncertain_parameters(scenario):
    """The real uncertain parameters ``Delta_real`` of the scenario, sorted by name.

    Same names, nominal values and ranges as the blocks the mission LFR keeps after the
    configuration substitution (``m_<hub>``, ``J{xx,yy,zz}_<hub>``, ``w1_<array>``), computed
    from the scenario data: ``value = nominal (1 +- percent / 100)``.

    Parameters
    ----------
    scenario : Scenario

    Returns
    -------
    tuple of oos_drake.control.plants.UncertainParameter
    """
    parameters = []

    def add(name, nominal, percent):
        r = float(percent) / 100.0
        if r > 0:
            parameters.append(
                UncertainParameter(name, float(nominal), nominal * (1 - r), nominal * (1 + r))
            )

    for hub in scenario.hubs.values():
        add(mass_name(hub.name), hub.mass, hub.mass_uncertainty_percent)
        diagonal = np.diag(np.asarray(hub.inertia, dtype=float))
        percents = np.broadcast_to(np.asarray(hub.inertia_uncertainty_percent, float), (3,))
        for name, value, percent in zip(inertia_names(hub.name), diagonal, percents, strict=True):
            add(name, value, percent)
    for mount in scenario.arrays.values():
        model = mount.model
        add(
            mode_frequency_name(mount.name, 1),
            float(model.omega[0]),
            model.first_mode_uncertainty_percent,
        )
    return tuple(sorted(parameters, key=lambda p: p.name))


def mission_parameters(scenario) -> tuple[PhysicalParameter, ...]:
    """The scenario's real uncertain parameters as Drake declarations (TITOP names and ranges)."""
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


def twin_lfr(scenario, point: OperatingPoint, parameters, **options) -> LFR:
    """``ulinearize`` the twin of ``scenario`` at ``point``: ``[F; T]`` at G1 -> ``[a_G1; wdot]``
    (6x6).

    Parameters that do not act at this configuration (the target's while it floats free) are
    dropped (zero repetitions). ``options`` go to :func:`ulinearize`.
    """
    handles = twin_diagram(scenario, point.connection)
    context = handles.diagram.CreateDefaultContext()
    set_operating_point(handles, context, point)
    options.setdefault("unused", "drop")
    # measured: round-off singular values <= 4.2e-7, true ones >= 9.6e-3 (docking phase 8)
    options.setdefault("rtol", 1e-5)
    return ulinearize(
        handles.diagram, context, parameters, handles.ports.wrench_input,
        f"{handles.ports.hub_output}[0:6]", **options,
    )  # fmt: skip


#: Pole [rad/s] of the decoupled states that pad lower-order models to the array's order.
PADDING_POLE = -1.0


def stack_models(models) -> LFR:
    """One model array ``(N,)`` from LFRs with different orders and block repetitions.

    Every model gets the union of the blocks (specs must agree), each with its largest
    repetition count, and the largest order: missing uncertain channels are added unconnected
    (zero rows and columns) and missing states as decoupled states at :data:`PADDING_POLE`
    (no input, no output): each model's input-output map is unchanged for every ``Delta``.
    """
    models = list(models)
    if not models:
        raise ValueError("stack_models: no models")
    specs, reps = {}, {}
    for model in models:
        if model.batch_shape:
            raise ValueError("stack_models: models must not be arrays")
        if model.shape != models[0].shape:
            raise ValueError(f"stack_models: shapes differ ({model.shape} vs {models[0].shape})")
        for entry in model.block_entries:
            name = entry.spec.name
            if name in specs and specs[name] != entry.spec:
                raise ValueError(f"stack_models: block {name!r} differs between models")
            specs[name] = entry.spec
            reps[name] = max(reps.get(name, 0), entry.reps)
    names = sorted(specs)
    offsets = dict(zip(names, np.cumsum([0] + [reps[n] for n in names])[:-1], strict=True))
    order = max(model.nstates for model in models)
    nz = sum(reps.values())
    ny, nu = models[0].shape
    stacked = np.zeros((len(models), order + nz + ny, order + nz + nu))
    for k, model in enumerate(models):
        n = model.nstates
        channels = np.concatenate(
            [offsets[e.spec.name] + np.arange(e.reps) for e in model.block_entries] or [[]]
        ).astype(int)
        rows = np.concatenate([np.arange(n), order + channels, order + nz + np.arange(ny)])
        cols = np.concatenate([np.arange(n), order + channels, order + nz + np.arange(nu)])
        stacked[k][np.ix_(rows, cols)] = np.asarray(model.M)
        stacked[k, n:order, n:order] = PADDING_POLE * np.eye(order - n)
    entries = [BlockEntry(specs[n], reps[n]) for n in names]
    return LFR(
        stacked, order, entries,
        input_names=models[0].input_names, output_names=models[0].output_names,
    )  # fmt: skip


def _twin_lfr_at(scenario, time: float) -> LFR:
    """The twin's LFR at mission ``time`` [s] of ``scenario``."""
    point = operating_point(mission_timeline(scenario).configuration(float(time)))
    return twin_lfr(scenario, point, mission_parameters(scenario))


def twin_mission_plants(times, scenario, *, progress=None, executor=None) -> LFR:
    """The twin's uncertain 6x6 plants at mission ``times`` [s] (model array, TITOP blocks).

    Parameters
    ----------
    times : array_like
        Mission times [s] (rigid connections from the timeline's switches).
    scenario : Scenario
        Its TITOP block names and ranges, its twin (sent to the workers as itself: it pickles).
    progress : callable, optional
        ``progress(done, total)``.
    executor : optional
        Where the extractions run, one task per time (:func:`oos_drake.processes.make_executor`;
        a process pool must spawn its workers: Drake's threads do not survive a fork; each
        worker builds the scenario's twin once); ``None``: one after the other
        here. Same LFRs either way, to the last bit (each extraction starts from a fresh
        context, with its own seeded checks, on one BLAS thread as the executor's workers: a
        threaded OpenBLAS rounds some products differently, 1 ulp in 71 of 13 872 entries of
        the paper's three plants with numpy 2.4.6).
    """
    times = np.atleast_1d(np.asarray(times, dtype=float))
    if executor is None:
        extract = with_single_threaded_blas(_twin_lfr_at)
        jobs = (extract(scenario, t) for t in times)
    else:
        futures = [executor.submit(_twin_lfr_at, scenario, float(t)) for t in times]
        jobs = (future.result() for future in futures)
    models = []
    for model in jobs:
        models.append(model)
        if progress is not None:
            progress(len(models), times.size)
    return stack_models(models)


def twin_docking_plants(phase: str, stiffness, damping: float, scenario) -> LFR:
    """The twin's uncertain plants of docking phase 7 or 8 over swept ``stiffness`` values.

    One extraction per phase: the swept spring-damper's shear and torsion stiffness are
    declared as parameters over ``[min, max]`` of the sweep (the dependence is affine, the LFR
    exact over the whole range, as checked at random points) and substituted, so the model
    array keeps only the hub and array parameters, like the TITOP docking study. Phase 7: SM1
    swept, SM2 open; phase 8: SM2 swept, SM1 at the scenario's rigid stiffness and damping.

    Parameters
    ----------
    phase : {"7", "8"}
    stiffness : array_like
        Swept stiffness [N/m = N m/rad], > 0.
    damping : float
        Damping of the swept spring-damper [N s/m = N m s/rad].
    scenario : Scenario
    """
    stiffness = np.atleast_1d(np.asarray(stiffness, dtype=float))
    if not np.all(np.isfinite(stiffness)) or np.any(stiffness <= 0):
        raise ValueError("twin_docking_plants: stiffness values must be finite and > 0")
    phases = mission_timeline(scenario).docking_phases
    if str(phase) not in phases:
        raise ValueError(f"docking phase must be one of {sorted(phases)}, got {phase!r}")
    named = phases[str(phase)]
    swept = "SM1" if str(phase) == "7" else "SM2"
    low, high = float(stiffness.min()), float(stiffness.max())
    if high <= low:
        high = 2.0 * low
    nominal = float(np.sqrt(low * high))
    springs = {swept: (nominal, float(damping))}
    if str(phase) == "8":
        docking = scenario.docking
        springs["SM1"] = (docking.rigid_stiffness, docking.rigid_damping)
    point = operating_point(named.configuration, springs, label=f"phase {phase}")
    declared = mission_parameters(scenario) + tuple(
        PhysicalParameter(f"{prefix}_{swept}", _BUSHING_FRAMES[swept], SPRING_QUANTITIES[prefix],
                          nominal, 0.5 * low, 2.0 * high)
        for prefix in ("k_shear", "k_tors")
    )  # fmt: skip
    lfr = twin_lfr(scenario, point, declared)
    return usubs(lfr, {f"k_shear_{swept}": stiffness, f"k_tors_{swept}": stiffness})
