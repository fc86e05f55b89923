"""The ``[control]`` requirements as :func:`~oos_drake.control.systune.systune` goals.

``oos synth`` tunes the attitude controller with :func:`tune_to_requirements` when the
scenario's ``[control]`` asks for margins or a minimum damping
(``ControlRequirements.has_tuning_goals``):

- soft goal: today's weighted H-infinity criterion ``||F_l(P_tot, C)||_inf`` from ``d`` to
  ``e`` (:mod:`oos_drake.control.interconnection`, the value ``gamma`` of the synthesis);
- hard goals: :class:`~oos_drake.control.goals.Margins` (loop at a time, at
  ``loop_opening``) and :class:`~oos_drake.control.goals.Poles` (``min_damping``);

over the mission configurations at the nominal values of the real parameters (the worst-case
search of :func:`~oos_drake.control.synthesis.synthesize` is not run on this path). With
``SystuneOptions.working_set`` (``oos synth --working-set``, 25 by default) the optimizer
tunes on that many configurations, every goal is checked on all of them and the violators are
added (:func:`~oos_drake.control.systune.systune`, step 5): the values recorded in
``controller.json`` hold on every configuration of the array. When
``rate_hz`` is given (it equals the flight software's rate), the controller is tuned
**discrete** at that rate on the loop exactly as the flight software runs it
(:func:`~oos_drake.control.sampled.sampled_interconnection`: plant discretized with its
zero-order hold, filters by their bilinear transforms): the flight software then executes the
tuned controller as it is (:meth:`ControllerSystem.discretize` keeps a discrete controller), and
each goal's value is its value on the exact sampled-data loop (the margins that ``oos margins``
measures on it). A continuous controller discretized afterwards by the flight software is not
what was tuned: the zero-order hold of a PID's derivative ``Kd s / (Tf s + 1)`` at
``Tf = T`` has the gain ``1.46 Kd / Tf`` at the Nyquist frequency (continuous: at most
``Kd / Tf``), ``1.57`` times the continuous one at a quarter of the sample rate.

Structures (``[control] structure``): ``"static"`` -- the 3x6 gain ``u_K = [K_p K_d] y``
started at the baseline; ``"pid"`` -- a PID per axis on the attitude error ``y_att`` with a
derivative filter and an optional roll-off of ``order``; ``"state-space"`` -- a stable
``order``-state controller ``y -> u_K`` (:class:`~oos_drake.control.tunable.TunableSS`).
"""

from __future__ import annotations

import dataclasses

import control
import numpy as np

from oos_drake.control.components import DesignSpecification
from oos_drake.control.goals import Margins, Poles, WeightedGain
from oos_drake.control.interconnection import (
    CONTROLS,
    DISTURBANCES,
    ERRORS,
    MEASUREMENTS,
    weighted_interconnection,
)
from oos_drake.control.sampled import sampled_interconnection
from oos_drake.control.statespace import BatchedStateSpace, connect
from oos_drake.control.systune import SystuneOptions, TuningResult, systune
from oos_drake.control.tunable import TunableGain, TunablePID, TunableSS

__all__ = [
    "WEIGHTED_GAIN",
    "performance_closed_loops",
    "requirement_goals",
    "requirement_controller",
    "tune_to_requirements",
]

WEIGHTED_GAIN = "weighted gain d->e"
LOOP_OPENING_SIGNALS = {"wheel_input": CONTROLS, "measurements": MEASUREMENTS}


def tuning_specification(spec: DesignSpecification, requirements) -> DesignSpecification:
    """``spec`` at the controller's rate when ``requirements.rate_hz`` is given (the
    flight software's rate: the discrete design of :func:`tune_to_requirements`)."""
    if requirements.rate_hz is None:
        return spec
    return dataclasses.replace(spec, flight_software_rate_hz=float(requirements.rate_hz))


def sampling_time(requirements) -> float:
    """Controller sample time ``1 / rate_hz`` [s], ``0`` for a continuous design."""
    return 0.0 if requirements.rate_hz is None else 1.0 / float(requirements.rate_hz)


def requirement_goals(requirements) -> list:
    """Soft weighted gain and the hard goals that ``requirements`` (``[control]``) states.

    Parameters
    ----------
    requirements : oos_drake.scenario.data.ControlRequirements
        ``gain_margin_db`` [dB], ``phase_margin_deg`` [deg], ``loop_opening``,
        ``min_damping`` [-].
    """
    goals = [WeightedGain(DISTURBANCES, ERRORS, kind="soft", name=WEIGHTED_GAIN)]
    if requirements.gain_margin_db is not None:
        goals.append(
            Margins(
                LOOP_OPENING_SIGNALS[requirements.loop_opening],
                requirements.gain_margin_db,
                requirements.phase_margin_deg,
                kind="hard",
                name=f"margins at {requirements.loop_opening}",
            )
        )
    if requirements.min_damping is not None:
        goals.append(Poles(requirements.min_damping, kind="hard", name="closed-loop damping"))
    return goals


def requirement_controller(requirements, K0):
    """The tunable block of ``requirements.structure``, started from the baseline gain.

    Parameters
    ----------
    requirements : oos_drake.scenario.data.ControlRequirements
    K0 : array_like, shape (3, 6)
        Baseline ``[K_p, K_d]`` [N m/rad, N m s/rad] (start of the static gain; its diagonals
        start the PID's ``kp`` and ``kd``).
    """
    K0 = np.asarray(K0, dtype=float)
    ts = sampling_time(requirements)
    if requirements.structure == "static":
        return TunableGain("K", MEASUREMENTS, CONTROLS, initial=K0, sampling_time=ts)
    if requirements.structure == "pid":
        kp, kd = np.diag(K0[:, :3]), np.diag(K0[:, 3:])
        return TunablePID(
            "C",
            MEASUREMENTS[:3],
            CONTROLS,
            terms="PID",
            kp=kp,
            ki=0.01 * kp,
            kd=kd,
            tf=0.1,
            rolloff_order=requirements.order or 0,
            rolloff_frequency=2 * np.pi * 2.0,
            sampling_time=ts,
        )
    if requirements.structure == "state-space":
        return TunableSS("C", MEASUREMENTS, CONTROLS, order=requirements.order, sampling_time=ts)
    raise ValueError(f"control.structure: unknown structure {requirements.structure!r}")


def _interconnection(plants, spec: DesignSpecification, requirements) -> BatchedStateSpace:
    """The weighted interconnection of every configuration of ``plants`` (nominal parameter
    values), discrete at ``requirements.rate_hz`` when given (batched)."""
    N, P = plants.size, len(plants.parameters)
    models = plants.evaluate(np.arange(N), np.broadcast_to(plants.nominal_values, (N, P)))
    if sampling_time(requirements) > 0:
        return sampled_interconnection(models, spec)
    return weighted_interconnection(models, spec).system


def _systems(plants, spec: DesignSpecification, requirements):
    """:func:`_interconnection` as :func:`~oos_drake.control.systune.systune`'s plants."""
    P, ts = _interconnection(plants, spec, requirements), sampling_time(requirements)
    if ts > 0:
        return [
            control.ss(P.A[i], P.B[i], P.C[i], P.D[i], ts, inputs=P.inputs, outputs=P.outputs)
            for i in range(P.A.shape[0])
        ]
    return P


def performance_closed_loops(
    plants, result: TuningResult, spec: DesignSpecification, requirements
) -> BatchedStateSpace:
    """The tuned loops ``d -> e`` (the weighted gain goal's channel) of every configuration
    of ``plants``, at nominal parameter values, in the controller's time domain (discrete at
    ``result.sampling_time`` when it is not 0): the interconnection tuned on, closed with
    ``result.controller``.

    Parameters
    ----------
    plants : oos_drake.control.plants.PlantArray
    result : TuningResult
        :func:`tune_to_requirements`' result on ``plants``.
    spec : DesignSpecification
        The specification tuned with (:func:`tuning_specification`'s).
    requirements : oos_drake.scenario.data.ControlRequirements
    """
    P = _interconnection(plants, spec, requirements)
    sys = result.controller
    K = BatchedStateSpace(
        sys.A, sys.B, sys.C, sys.D, tuple(sys.input_labels), tuple(sys.output_labels)
    )
    return connect([P, K], DISTURBANCES, ERRORS)


def tune_to_requirements(
    plants,
    K0,
    spec: DesignSpecification,
    requirements,
    options: SystuneOptions,
    progress=None,
    between=None,
) -> TuningResult:
    """Tune ``requirements.structure`` against :func:`requirement_goals` over ``plants``.

    Parameters
    ----------
    plants : oos_drake.control.plants.PlantArray
        Mission configurations (evaluated at the nominal parameter values).
    K0 : array_like, shape (3, 6)
        Baseline gain [N m/rad, N m s/rad].
    spec : DesignSpecification
        Weights and components (with ``requirements.rate_hz``: the discrete loop of
        :func:`~oos_drake.control.sampled.sampled_interconnection` at that rate).
    requirements : oos_drake.scenario.data.ControlRequirements
    options : SystuneOptions
        With ``working_set``: tuned on that many configurations, each goal checked on every
        configuration of ``plants`` and the violators added (see :func:`systune`).
    progress : callable, optional
        ``progress(message: str)`` for log lines.
    between : oos_drake.control.plants.PlantArray, optional
        Configurations between those of ``plants`` (e.g. the midpoints) on which the tuned
        controller is only checked (:func:`~oos_drake.control.systune.systune`'s ``verify``:
        ``TuningResult.verified``; a hard goal missed there gives the status
        ``"infeasible"``).

    Returns
    -------
    TuningResult
        ``status`` ``"infeasible"`` when a hard goal is not met (best values reached).
    """
    spec = tuning_specification(spec, requirements)
    verify = None if between is None or between.size == 0 else _systems(between, spec, requirements)
    return systune(
        _systems(plants, spec, requirements),
        requirement_controller(requirements, K0),
        requirement_goals(requirements),
        options=options,
        progress=progress,
        verify=verify,
    )
