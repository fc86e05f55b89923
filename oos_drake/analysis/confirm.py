r"""Confirm each certified worst case of the analysis on the nonlinear Drake twin (``oos confirm``).

For every certified peak of ``stability_peaks.parquet`` the analysis saved the normalized worst
perturbation ``Delta_*`` (``peak_perturbations.npz``): substituted into the LFR it puts a
closed-loop pole on the imaginary axis at the critical frequency ``omega``. Along the ray
``alpha Delta_*`` this module locates the stability boundary three ways, each at fixed parameter
values (for a fixed perturbation the loop is LTI):

1. **linear, continuous** (the analysis' own loop): eigenvalues of the closed-loop LFR with the
   real parameters at ``alpha delta_i`` and each complex block replaced by ``alpha`` times a
   stable interpolant of its worst value at ``omega``
   (:func:`oos_drake.robust.interpolant.lti_interpolant`, MATLAB ``wcu``'s all-pass sections).
   Expected boundary: ``alpha = 1``.
2. **linear, sampled-data** (the loop the Drake twin runs): the same perturbed continuous plant
   ``T -> [phi; omega]`` discretized exactly with a zero-order hold at the flight software's
   period and closed with the discrete flight software as it runs
   (:meth:`~oos_drake.multibody.flight_software.FlightSoftware.linear_update`: Tustin filters,
   torque computed and applied at the sample, no computation delay), with ``Delta_mul`` where
   the twin has it (below). Eigenvalues on the unit circle give its boundary ``alpha`` and
   crossing frequency.
3. **nonlinear**: the Drake mission twin (``MissionSimulation``) with the arm and arrays frozen
   at the peak's configuration (``MissionTimeline.frozen``), the real parameters written as
   physical values, started from a small attitude error without noise. The decay rate and the
   frequency of the dominant oscillation of the hub attitude after the transient are identified
   by the matrix pencil (:mod:`oos_drake.analysis.oscillation`); a bisection on ``alpha`` to
   ``ConfirmOptions.rtol`` locates the sign change of the decay rate.

Complex blocks on the twin (:func:`oos_drake.multibody.flight_software.perturbation_block`,
scaled by ``alpha`` per run): ``Delta_mul`` (on the wheel torque) is the discrete interpolant
of its worst value, computed by the flight software at the sample and held with the torque
(it takes the worst value at ``e^{j omega dt}`` exactly); ``Delta_add`` (an angular
acceleration ``W_add Delta_add(s) T``, which a multibody plant cannot take as such) is added to
the measured attitude and rate as the exact zero-order-hold response of
``[1/s^2; 1/s] W_add Delta_add(s)`` to the held torque: the loop the flight software closes is
that of the plant ``P + W_add Delta_add(s)`` behind the hold. The linear sampled prediction
uses the same realization (``Delta_add`` continuous behind the hold, ``Delta_mul`` in the
flight software: the same loop up to six unobservable integrator states, a double integrator
per axis, at ``z = 1``); a note gives the
boundary with ``Delta_mul`` behind the hold as well (its interpolant then also acts on the
hold's harmonics). The hub attitude of such a run carries the offset ``-dphi`` of the realized
acceleration (the loop regulates the measured sum), a slow mode the identification does not
follow.

Docking peaks: the twin is frozen at the docking phase's configuration (its time in the
scenario) with the docking spring-dampers held at the peak's stiffness and the study's damping
(:func:`oos_drake.analysis.models.docking_springs`: phase 7 SM1 swept, SM2 open; phase 8 SM2
swept, SM1 rigid) for the whole run (``MissionSimulation.run(bushings=...)``). A tree's
docking peak (``docking-<event>``): the tree's twin frozen at the event's configuration, the
target on its floating joint held by one bushing per spring-damper of the event (the swept one
at the peak's stiffness and the file's damping, one still holding the target at its file
values; coefficients the file declares uncertain at their values along the ray).

Physical validity: a worst perturbation may lie outside the physical domain (non-positive
mass, an inertia breaking the triangle inequality, a non-positive modal frequency, negative
stiffness or damping). :func:`physical_alpha_max` gives the largest ``alpha`` along the ray
that is still a physical body; beyond it no simulation is run (Drake refuses some of these
bodies, and a non-physical instability is no statement about the spacecraft).

Limits: a peak whose complex blocks have their critical frequency at or beyond the flight
software's Nyquist frequency has no discrete realization and keeps the linear predictions. A
peak at infinite frequency is an ill-posed loop (the perturbation makes a mass matrix
singular): it has no oscillation to confirm; its physical limit is reported instead.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.signal

__all__ = [
    "BodyInertia",
    "ConfirmOptions",
    "ConfirmationOptions",
    "ConfirmationResult",
    "Peak",
    "boundary_along_ray",
    "compute_confirmation",
    "confirm_peaks",
    "physical_alpha_max",
    "physical_violation",
    "read_peaks",
]

PEAKS_FILE = "stability_peaks.parquet"
PERTURBATIONS_FILE = "peak_perturbations.npz"
CONFIRMATION_FILE = "confirmation.parquet"
HISTORIES_FILE = "confirmation_histories.parquet"
#: Agreement asked of a confirmation: boundary and frequency within 3 % (issue 17).
AGREEMENT = 0.03
AXES = ("x", "y", "z")
#: Wanted logging rate of a confirmation run [Hz]: the rate used is the fastest one at most
#: this that divides the scenario's flight-software rate (``multibody.mission.logging_rate``:
#: 10 Hz at the paper's 10 Hz, 5 Hz at 5 Hz, 10 Hz at 100 Hz).
CONFIRM_LOG_RATE_HZ = 10.0
#: Growth rate below which a linear loop counts as stable [1/s]: the plants' structurally
#: marginal rigid-body modes (translations of the free system, not seen by the attitude loop)
#: come out of the eigenvalue solver at +-1e-6; a time constant of 1e5 s is no instability
#: over a 1500 s mission.
GROWTH_TOLERANCE = 1e-5


#: Largest share of the wheels' torque limit that the first command of a confirmation run may
#: take [-] (:meth:`ConfirmOptions.within_torque_limit`): the run stays clear of the saturation.
LINEAR_TORQUE_FRACTION = 0.25


@dataclass(frozen=True)
class ConfirmOptions:
    """Options of the nonlinear confirmation.

    Attributes
    ----------
    duration : float
        Simulated time of one run [s].
    settle : float
        Start of the identification window after the run's start [s] (the transient is cut).
    initial_attitude : float
        Initial hub attitude error on each axis [rad] (small: the loop stays linear).
    rtol : float
        Relative width of the final bisection bracket on ``alpha`` [-].
    max_step : float
        Longest integrator step [s] (fixed Radau3 steps). Steps of one 10 Hz period damp a
        0.8 Hz oscillation numerically: at the modal peak's sampled-data boundary of the
        default analysis the decay rate is -0.0074 1/s with 0.1 s steps, -0.0009 1/s with
        0.05 s and +0.0001 1/s with 0.025 s (``benchmarks/bench_confirm.py``); with a slope
        of about 0.7 (1/s) per unit alpha, 0.05 s moves the boundary by about 0.2 %.
    bracket : float
        Half-width of the first bracket around the sampled-data prediction [-] (relative).
    alpha_limit : float
        Largest ``alpha`` searched [-].
    cycles : float
        Fewest periods of the predicted oscillation in the identification window [-]: a peak
        slower than ``cycles / (duration - settle)`` gets a longer run (and a settling time of
        at least one period), see :meth:`for_frequency`.
    """

    duration: float = 45.0
    settle: float = 8.0
    initial_attitude: float = 1e-3
    rtol: float = 0.005
    max_step: float = 0.05
    bracket: float = 0.03
    alpha_limit: float = 4.0
    cycles: float = 8.0

    def for_frequency(self, frequency_hz: float) -> ConfirmOptions:
        """These options with the run long enough for an oscillation at ``frequency_hz`` [Hz]:
        ``settle >= 1 / f`` and ``duration - settle >= cycles / f`` (unchanged when already
        so, or when the frequency is not finite and positive).

        The decay rate of the dominant oscillation (:func:`_verdict`) is fitted on the window
        after ``settle``; the default 37 s holds 13 periods of the paper's 0.36 Hz peaks but
        half of one at 0.0125 Hz, where a decaying oscillation looks like growth.
        """
        if not (np.isfinite(frequency_hz) and frequency_hz > 0):
            return self
        period = 1.0 / frequency_hz
        settle = max(self.settle, period)
        duration = max(self.duration, settle + self.cycles * period)
        if (settle, duration) == (self.settle, self.duration):
            return self
        return dataclasses.replace(self, settle=settle, duration=duration)

    def for_peak(self, sampled_hz: float, critical_hz: float) -> ConfirmOptions:
        """:meth:`for_frequency` of a peak's predicted oscillation: the sampled-data loop's
        frequency at its boundary [Hz], else the critical frequency [Hz]."""
        return self.for_frequency(sampled_hz if np.isfinite(sampled_hz) else critical_hz)

    def within_torque_limit(self, system, torque_limit: float) -> ConfirmOptions:
        """These options with an initial attitude error whose first command stays within
        :data:`LINEAR_TORQUE_FRACTION` of the wheels' ``torque_limit`` [N m].

        The runs identify a linear loop's oscillation: a first command beyond the saturation
        makes the loop nonlinear from the start (geo_satellite's gains, up to 781 N m/rad
        against 0.2 N m, met 1e-3 rad with 0.6 N m). ``system`` is the controller
        (:class:`~oos_drake.control.interconnection.ControllerSystem`); its direct
        feedthrough from the attitude measurement gives the first command of an error of
        ``initial_attitude`` on every axis (the worst axis counted). Unchanged when that is
        already small enough.
        """
        gain = float(np.abs(np.asarray(system.D, dtype=float)[:, :3]).sum(axis=1).max())
        if not (gain > 0 and np.isfinite(torque_limit)):
            return self
        attitude = LINEAR_TORQUE_FRACTION * float(torque_limit) / gain
        if attitude >= self.initial_attitude:
            return self
        return dataclasses.replace(self, initial_attitude=attitude)

    def __post_init__(self):
        names = ("duration", "settle", "initial_attitude", "rtol", "max_step", "bracket", "cycles")
        for name in (*names, "alpha_limit"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"confirm option {name} must be > 0, got {value!r}")
        if self.settle >= self.duration:
            raise ValueError(
                f"confirm option settle ({self.settle} s) must be below duration "
                f"({self.duration} s)"
            )


@dataclass(frozen=True)
class Peak:
    """A certified peak of the analysis and its worst perturbation.

    Attributes
    ----------
    study, subset : str
        ``"mission"`` / ``"docking-7"`` / ``"docking-8"`` and the uncertainty subset.
    time : float
        Mission time of the configuration [s] (NaN for docking studies).
    stiffness : float
        Swept docking stiffness [N/m or N m/rad] (NaN for the mission).
    omega : float
        Critical frequency [rad/s] (``inf``: an ill-posed loop).
    mu_lower, mu_upper : float
        Certified bounds [-].
    perturbation : Mapping[str, float or ndarray]
        Normalized worst value per block (real scalars; complex matrices).
    """

    study: str
    subset: str
    time: float
    stiffness: float
    omega: float
    mu_lower: float
    mu_upper: float
    perturbation: Mapping[str, object] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """``study|subset``."""
        return f"{self.study}|{self.subset}"

    @property
    def has_complex(self) -> bool:
        """Whether the worst perturbation has complex (dynamic) blocks."""
        return any(np.ndim(v) > 0 for v in self.perturbation.values())


def read_peaks(analysis: str | Path) -> list[Peak]:
    """The certified peaks of an ``oos analyze`` folder (``mu_lower > 0``).

    Raises
    ------
    ValueError
        Missing folder or files, or a peak without its saved perturbation.
    """
    folder = Path(analysis)
    if not folder.is_dir():
        raise ValueError(f"--analysis {folder}: folder not found")
    for name in (PEAKS_FILE, PERTURBATIONS_FILE):
        if not (folder / name).is_file():
            raise ValueError(f"--analysis {folder}: {name} not found (run `oos analyze` first)")
    from oos_drake.robust.tables import upgrade_columns

    table = upgrade_columns(pd.read_parquet(folder / PEAKS_FILE))  # old folders too
    saved = np.load(folder / PERTURBATIONS_FILE)
    peaks = []
    for _, row in table.iterrows():
        if not row["mu lower [-]"] > 0:
            continue
        key = f"{row['study']}|{row['subset']}|"
        if key + "omega [rad/s]" not in saved.files:
            raise ValueError(f"{folder / PERTURBATIONS_FILE}: no perturbation for {key[:-1]}")
        perturbation = {}
        for item in saved.files:
            if item.startswith(key) and item not in (key + "model", key + "omega [rad/s]"):
                value = saved[item]
                perturbation[item[len(key) :]] = float(value) if value.ndim == 0 else value
        peaks.append(
            Peak(
                study=str(row["study"]),
                subset=str(row["subset"]),
                time=float(row["time [s]"]),
                stiffness=float(row.get("stiffness [N/m or N m/rad]", math.nan)),
                omega=float(saved[key + "omega [rad/s]"]),
                mu_lower=float(row["mu lower [-]"]),
                mu_upper=float(row["mu upper [-]"]),
                perturbation=perturbation,
            )
        )
    return peaks


# -- physical validity along the ray --------------------------------------------------------------
@dataclass(frozen=True)
class BodyInertia:
    """Inertia blocks of one body, for the checks of a rigid body's inertia tensor.

    Attributes
    ----------
    diagonal : tuple of str
        Block names of ``Ixx, Iyy, Izz`` at the centre of mass [kg m^2].
    tensor : ndarray, shape (3, 3)
        Nominal tensor [kg m^2] (its products of inertia are kept; blocks replace the diagonal).
    """

    diagonal: tuple[str, str, str]
    tensor: np.ndarray


def physical_violation(
    values: Mapping[str, float], quantities: Mapping[str, str], bodies=()
) -> str:
    """What makes physical parameter ``values`` not a physical system ('' when they are one).

    Parameters
    ----------
    values : Mapping[str, float]
        Physical value per block [the block's unit].
    quantities : Mapping[str, str]
        Block name -> quantity (``"mass"``, ``"inertia"``, ``"modal frequency"``,
        ``"stiffness"``, ``"damping"``; others are not checked).
    bodies : sequence of BodyInertia
        Inertia tensors to check: positive principal moments satisfying the triangle
        inequality ``I_1 + I_2 >= I_3``.
    """
    positive = {"mass", "inertia", "modal frequency"}
    non_negative = {"stiffness", "damping"}
    for name, value in values.items():
        quantity = quantities.get(name, "")
        if quantity in positive and not value > 0:
            return f"{name} = {value:.4g} <= 0 ({quantity})"
        if quantity in non_negative and not value >= 0:
            return f"{name} = {value:.4g} < 0 ({quantity})"
    for body in bodies:
        if not any(n in values for n in body.diagonal):
            continue
        tensor = np.array(body.tensor, dtype=float)
        for i, n in enumerate(body.diagonal):
            tensor[i, i] = values.get(n, tensor[i, i])
        moments = np.sort(np.linalg.eigvalsh(0.5 * (tensor + tensor.T)))
        if moments[0] <= 0 or moments[0] + moments[1] < moments[2]:
            return (
                f"inertia {', '.join(body.diagonal)}: principal moments "
                f"{np.array2string(moments, precision=4)} break the triangle inequality"
            )
    return ""


def ray_values(specs: Mapping, direction: Mapping[str, float], alpha: float) -> dict:
    """Physical values of the real blocks at ``alpha`` times the normalized ``direction``."""
    return {n: float(specs[n].to_physical(alpha * d)) for n, d in direction.items()}


def physical_alpha_max(
    specs: Mapping,
    direction: Mapping[str, float],
    bodies=(),
    *,
    alpha_limit: float = 4.0,
    tol: float = 1e-6,
) -> tuple[float, str]:
    """Largest ``alpha`` along the ray for which the real parameters are a physical system.

    Parameters
    ----------
    specs : Mapping
        Block name -> ``ureal`` spec (``to_physical``, ``quantity``).
    direction : Mapping[str, float]
        Normalized worst value per real block [-].
    bodies : sequence of BodyInertia
    alpha_limit : float
        Search end [-]: ``inf`` is returned when the ray is physical up to it.
    tol : float
        Absolute accuracy of the returned ``alpha`` [-].

    Returns
    -------
    alpha : float
        First ``alpha`` at which the parameters stop being physical (``inf``: not before
        ``alpha_limit``).
    reason : str
        The violation just beyond ``alpha`` ('' if none).
    """
    quantities = {n: specs[n].quantity for n in direction}

    def bad(alpha):
        return physical_violation(ray_values(specs, direction, alpha), quantities, bodies)

    grid = np.linspace(0.0, alpha_limit, 401)
    first = next((a for a in grid if bad(a)), None)
    if first is None:
        return math.inf, ""
    lo, hi = first - grid[1], first
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if bad(mid) else (mid, hi)
    return lo, bad(hi)


# -- linear predictions ---------------------------------------------------------------------------
def boundary_along_ray(
    unstable: Callable[[float], bool], alpha_limit: float, *, steps: int = 80, rtol: float = 1e-4
) -> float:
    """First ``alpha`` in ``(0, alpha_limit]`` where ``unstable(alpha)`` turns true (inf if
    none): a grid of ``steps`` points, then bisection to ``rtol``."""
    grid = np.linspace(alpha_limit / steps, alpha_limit, steps)
    previous = 0.0
    for alpha in grid:
        if unstable(alpha):
            lo, hi = previous, alpha
            while hi - lo > rtol * max(hi, grid[0]):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
            return 0.5 * (lo + hi)
        previous = alpha
    return math.inf


def substitution(peak: Peak, specs: Mapping, alpha: float, *, dt: float | None = None) -> dict:
    """Normalized values of every block at ``alpha`` along the peak's ray: real blocks scaled,
    complex blocks as ``alpha`` times their interpolant at the critical frequency (blocks the
    peak's subset leaves out at zero)."""
    from oos_drake.robust.interpolant import lti_interpolant

    values = {}
    for name, spec in specs.items():
        value = peak.perturbation.get(name)
        if spec.kind == "ureal":
            values[name] = 0.0 if value is None else alpha * float(value)
        elif value is None:
            values[name] = np.zeros(spec.shape)
        elif np.isinf(peak.omega):
            values[name] = alpha * np.real(value)
        else:
            values[name] = alpha * lti_interpolant(value, peak.omega, dt=dt)
    return values


def _continuous_abscissa(closed, peak: Peak, alpha: float) -> tuple[float, float]:
    from oos_drake.lfr import usubs

    try:
        loop = usubs(closed, substitution(peak, closed.uncertainty, alpha), normalized=True)
    except (ValueError, np.linalg.LinAlgError):  # ill-posed: I - D Delta singular
        return math.inf, math.inf
    poles = np.linalg.eigvals(np.asarray(loop.to_ss().A))
    k = int(np.argmax(poles.real))
    return float(poles[k].real), abs(float(poles[k].imag))


def complex_values(peak: Peak) -> dict:
    """The peak's worst complex blocks as the flight software takes them: ``{"delta_mul":
    3x3, "delta_add": 3x3}`` (normalized [-]; a block the subset leaves out is absent;
    :func:`~oos_drake.multibody.flight_software.complex_blocks`)."""
    from oos_drake.multibody.flight_software import complex_blocks

    return complex_blocks(peak.perturbation)


def sampled_loop_poles(plant_hat, peak: Peak, alpha: float, software, mul_block=None):
    """Poles of the exact sampled-data loop (discrete, ``z``) at ``alpha`` along the ray.

    ``plant_hat``: the uncertain plant ``T -> wdot`` (3x3) with its real and complex blocks;
    the perturbed plant is augmented with ``w = int wdot``, ``phi = int w`` (small angles: the
    roll-pitch-yaw rates are the body rates), discretized with a zero-order hold at the flight
    software's period and closed with ``software``'s update
    (:meth:`~oos_drake.multibody.flight_software.FlightSoftware.linear_update`, feedthrough at
    the sample).

    ``mul_block``: ``Delta_mul`` as the twin realizes it, the discrete interpolant in the flight
    software before the hold (``perturbation_block(design, omega, delta_mul=...)`` at
    ``alpha = 1``, scaled here); ``Delta_add`` stays the continuous interpolant in the plant
    behind the hold, the same loop as the twin's measurement-side realization up to its six
    unobservable integrator states at ``z = 1``. None: every complex block continuous in the
    plant (the analysis' loop with a hold; ``Delta_mul``'s interpolant then also acts on the
    hold's harmonics).
    """
    from oos_drake.control.analysis_model import MULTIPLICATIVE_BLOCKS
    from oos_drake.control.sampled import plant_with_integrators
    from oos_drake.lfr import usubs
    from oos_drake.multibody.flight_software import DiscreteBlock

    period = software.design.period
    values = substitution(peak, plant_hat.uncertainty, alpha)
    dynamic = None
    if mul_block is not None:
        for name in MULTIPLICATIVE_BLOCKS:
            values[name] = np.zeros((1, 1))
        # the interpolant of alpha Delta is alpha times that of Delta (same sections)
        b = mul_block
        dynamic = DiscreteBlock(b.A, b.B, alpha * b.C, alpha * b.D)
    fsw = software.linear_update(dynamic=dynamic)
    P = usubs(plant_hat, values, normalized=True).to_ss()
    Ag, Bg, Cg = plant_with_integrators(P)  # T -> [phi; w]
    Ad, Bd, *_ = scipy.signal.cont2discrete((Ag, Bg, Cg, np.zeros((6, 3))), period, method="zoh")
    Ac, Bc, Cc, Dc = fsw.A, fsw.B, fsw.C, fsw.D
    closed = np.block([[Ad + Bd @ Dc @ Cg, Bd @ Cc], [Bc @ Cg, Ac]])
    return np.linalg.eigvals(closed)


# -- nonlinear twin -------------------------------------------------------------------------------
def _mission_window(sim, t_peak: float, duration: float) -> float:
    """Start [s] of a window of ``duration`` near ``t_peak`` that no docking event (capture,
    stiffness ramps) falls into: the connection state of the peak's time, held throughout.

    A peak inside a ramp moves after it (the connection is then made); a window that would run
    into the next event ends before it.
    """
    start = min(float(t_peak), sim.duration - duration)
    for a, b in sim.schedule(sim.resolve(None)).ramp_intervals():
        if a - 1e-9 <= t_peak < b:
            start = b + 0.5
        elif start < a < start + duration:
            start = a - duration - 0.5
    if start < 0.0 or start + duration > sim.duration:
        raise ValueError(
            f"confirm: no {duration:.4g} s window without a docking event near t = {t_peak:.6g} s"
        )
    return start


def confirm_mission_options(scenario, options: ConfirmOptions):
    """The twin's mission options of a confirmation run: the scenario's flight software (rate
    and torque bound), ``options.max_step``, logging at the fastest rate at most
    :data:`CONFIRM_LOG_RATE_HZ` that divides the flight-software rate (any rate works).

    Returns
    -------
    oos_drake.multibody.mission.MissionOptions
    """
    from oos_drake.multibody.mission import MissionOptions, logging_rate

    control_rate = scenario.control.flight_software_rate_hz
    return MissionOptions(
        log_rate=logging_rate(control_rate, CONFIRM_LOG_RATE_HZ),
        max_step=options.max_step,
        control_rate=control_rate,
        torque_limit=scenario.control.torque_limit,
    )


class _MissionTwin:
    """One frozen Drake mission (built once per peak) and runs along the peak's ray.

    A mission peak freezes the arm and arrays at its time; a docking peak freezes them at its
    phase's time and holds the docking spring-dampers at the peak's stiffness (the docking
    study's settings, :func:`oos_drake.analysis.models.docking_springs`). The peak's complex
    blocks are the flight software's dynamic perturbation
    (:func:`~oos_drake.multibody.flight_software.perturbation_block`), scaled with ``alpha``.
    """

    def __init__(
        self,
        peak: Peak,
        K,
        options: ConfirmOptions,
        scenario,
        near_hz: float,
        specs: Mapping,
        design,
    ):
        from oos_drake.multibody.flight_software import perturbation_block
        from oos_drake.multibody.mission import make_mission_diagram
        from oos_drake.multibody.mission_sim import MissionSimulation
        from oos_drake.multibody.scenario_sdf import scenario_sdf_directory
        from oos_drake.scenario.timeline import mission_timeline

        mission_options = confirm_mission_options(scenario, options)
        self.peak, self.specs = peak, specs
        self.direction = {n: v for n, v in peak.perturbation.items() if specs[n].kind == "ureal"}
        self.complex = complex_values(peak)
        self.bushings = None
        time = peak.time
        if peak.study != "mission":
            from oos_drake.analysis.models import docking_springs

            phase = peak.study.removeprefix("docking-")
            time = next(p.time for p in scenario.mission.docking_phases if p.name == phase)
            springs = docking_springs(phase, peak.stiffness, scenario=scenario)
            self.bushings = {n: (k, k, d, d) for n, (k, d) in springs.items()}
        states = 0
        if self.complex:
            # the state count of the realization does not depend on alpha > 0
            states = perturbation_block(design, peak.omega, **self.complex).nstates
        timeline = mission_timeline(scenario).frozen(time)
        sdf, self._sdf = scenario_sdf_directory(scenario)
        handles = make_mission_diagram(
            mission_options,
            K=K,
            timeline=timeline,
            scenario=scenario,
            sdf_directory=sdf,
            perturbation_states=states,
        )
        self.sim = MissionSimulation(handles=handles)
        self.options = options
        if self.bushings is None:
            self.start = _mission_window(self.sim, time, options.duration)
        else:  # the connection is held: no event in the window but the phase's own instant
            self.start = float(time)
        self.hub_q = self.sim.handles.hub_joint.position_start()
        self.near_hz = near_hz  # the oscillation the verdict follows [Hz] (NaN: the dominant one)

    def realization(self, alpha: float):
        """The flight software's dynamic perturbation at ``alpha`` (None without complex
        blocks)."""
        from oos_drake.multibody.flight_software import perturbation_block

        if not self.complex:
            return None
        design = self.sim.handles.flight_software.design
        scaled = {k: alpha * v for k, v in self.complex.items()}
        return perturbation_block(design, self.peak.omega, **scaled)

    def _simulate(self, alpha: float, noise_table: np.ndarray, phi0: float):
        """One run at ``alpha`` with the unit noise table ``noise_table`` (``(n, 9)``) and the
        initial attitude error ``phi0`` [rad] on each axis: ``(diverged, root context)``."""
        from oos_drake.multibody.mission_sim import MissionDiverged

        o = self.options
        values = ray_values(self.specs, self.direction, alpha)
        run_values = values | {f"phi0_{a}": phi0 for a in AXES}
        holder = {}
        fsw = self.sim.handles.flight_software
        block = self.realization(alpha)

        def on_start(context):
            holder["context"] = context
            fsw.set_dynamic_perturbation(fsw.GetMyMutableContextFromRoot(context), block)

        try:
            self.sim.run(
                run_values,
                0,
                self.start,
                self.start + o.duration,
                log=False,
                noise_table=noise_table,
                on_start=on_start,
                within_ranges=False,
                bushings=self.bushings,
            )
        except MissionDiverged:
            return True, holder["context"]
        return False, holder["context"]

    def forced_run(self, alpha: float, noise_table: np.ndarray):
        """A run at ``alpha`` from rest driven by ``noise_table`` (``(n, 9)`` unit
        ``[n_sst; n_gyro; d_ext]`` per flight-software sample, the window's first sample first).

        Returns
        -------
        times : ndarray, shape (n,)
            Log times since the window start [s].
        phi : ndarray, shape (n, 3)
            Hub roll-pitch-yaw attitude [rad].
        T_rw, u : ndarray, shape (n, 3)
            Wheel torque and torque command [N m] (the flight software's log).

        Raises
        ------
        MissionDiverged
            The run diverged.
        """
        from oos_drake.multibody.mission_sim import MissionDiverged

        diverged, context = self._simulate(alpha, noise_table, 0.0)
        if diverged:
            raise MissionDiverged(f"the forced run at alpha = {alpha:g} diverged")
        times, states, torques = self.sim.logs(context)
        phi = states[self.hub_q : self.hub_q + 3].T
        return times - self.start, phi, torques[3:6].T, torques[0:3].T

    def run(self, alpha: float):
        """``(growing, Oscillation or None, history DataFrame)`` of one run at ``alpha``:
        ``growing`` when the run diverged, the dominant oscillation grows or, without any
        oscillation, the attitude's peak over the last quarter of the window exceeds that of
        the second."""
        o = self.options
        diverged, context = self._simulate(alpha, np.zeros((1, 9)), o.initial_attitude)
        times, states = self.sim.state_log(context)
        phi = states[self.hub_q : self.hub_q + 3].T
        return _verdict(times - self.start, phi, diverged, o, self.near_hz)


#: Slowest oscillation the verdict counts [Hz] (slower poles are drifts), unless the expected
#: oscillation is slower (:func:`_slowest_oscillation`).
F_MIN_HZ = 0.02


def _slowest_oscillation(near_hz) -> float:
    """Lowest frequency counted as an oscillation [Hz]: :data:`F_MIN_HZ`, or half the expected
    frequency ``near_hz`` [Hz] when that is slower (a 0.0125 Hz peak is not a drift)."""
    if near_hz is not None and np.isfinite(near_hz) and near_hz > 0:
        return min(F_MIN_HZ, 0.5 * float(near_hz))
    return F_MIN_HZ


def _verdict(times: np.ndarray, phi: np.ndarray, diverged: bool, o: ConfirmOptions, near_hz):
    """``(growing, Oscillation or None, history)`` of a run's attitude ``phi`` [rad] (``(n,
    3)``) at ``times`` [s] since the run's start (:meth:`_MissionTwin.run`)."""
    from oos_drake.analysis.oscillation import dominant_oscillation

    history = pd.DataFrame(
        {"time [s]": times} | {f"phi_{a} [rad]": phi[:, i] for i, a in enumerate(AXES)}
    )
    window = (times >= o.settle) & np.all(np.isfinite(phi), axis=1)
    oscillation = None
    if np.count_nonzero(window) >= 40:
        try:
            oscillation = dominant_oscillation(
                times[window], phi[window], near_hz=near_hz, f_min=_slowest_oscillation(near_hz)
            )
        except ValueError:
            oscillation = None
    if diverged or oscillation is not None:
        return diverged or oscillation.decay_rate > 0, oscillation, history
    quarters = np.array_split(np.abs(phi[window]).max(axis=1), 4)
    return bool(quarters[3].max() > quarters[1].max()), None, history


class _TreeTwin:
    """The twin of a schema-2 tree for one peak (:mod:`oos_drake.multibody.tree_twin`): the
    tree's SDF with the real parameters at ``alpha`` along the peak's ray written into its data
    (rebuilt per ``alpha``), its revolute joints frozen at the timeline's angles at the peak's
    time, the target welded at its port when the phase at that time captures or docks it (as
    the mission model welds it: :func:`~oos_drake.multibody.tree_twin.mating_at`), closed by
    the scenario's flight software with the peak's complex blocks realized in it
    (:func:`~oos_drake.multibody.flight_software.perturbation_block`, scaled with ``alpha``).
    The same interface as :class:`_MissionTwin` (``run``, ``forced_run``).

    A docking peak (``docking-<phase>``, the study of a docking event,
    :meth:`~oos_drake.scenario.tree_scenario.TreeScenario.docking_plant`): the joints frozen at
    the event's configuration, the target on its floating joint held by one bushing per
    spring-damper of the event (:meth:`~oos_drake.scenario.tree_scenario.TreeScenario.
    docking_event`): the swept one at the peak's stiffness (shear and torsion) and the file's
    damping, a spring-damper still holding the target at its file values; the coefficients the
    file declares uncertain at their values along the ray, as the tree's own blocks."""

    def __init__(self, peak: Peak, K, options, scenario, near_hz, specs, design):
        from oos_drake.multibody.mission import logging_rate
        from oos_drake.multibody.tree_twin import mating_at
        from oos_drake.scenario.tree_scenario import NotForTrees

        if scenario.timeline is None:
            raise NotForTrees(
                f"confirm: scenario {scenario.name} has tip-pose waypoints: no timeline to "
                "freeze its twin at"
            )
        self.peak, self.specs, self.options, self.near_hz = peak, specs, options, near_hz
        self.tree, self.design = scenario.tree, design
        self.springs = ()
        time = peak.time
        if peak.study != "mission":
            phase = peak.study.removeprefix("docking-")
            events = {p.name: p for p in scenario.mission.docking_phases}
            if phase not in events:
                raise ValueError(
                    f"confirm: {peak.study}: {phase!r} is not a docking event of scenario "
                    f"{scenario.name} (docking phases: {', '.join(events) or 'none'})"
                )
            time = events[phase].time
            docking, held = scenario.docking_event(phase)
            swept = dataclasses.replace(docking, k_shear=peak.stiffness, k_tors=peak.stiffness)
            self.springs = (swept, *held)
        self.time = time
        self.angles = scenario.timeline.angles(time)
        self.mating = mating_at(scenario.timeline, time) if not self.springs else None
        self.direction = {n: v for n, v in peak.perturbation.items() if specs[n].kind == "ureal"}
        self.complex = complex_values(peak)
        self.log_rate = logging_rate(1.0 / design.period, CONFIRM_LOG_RATE_HZ)
        self.start = 0.0
        self._twins = {}

    def parameters(self, alpha: float):
        """``(tree values, springs)`` at ``alpha`` along the ray: the physical values of the
        tree's and the target's blocks (masses, inertias, mode frequencies), and the docking
        spring-dampers with their declared-uncertain coefficients (``k_shear_<label>``, ...)
        at their values (the others as set in :meth:`__init__`)."""
        from oos_drake.scenario.tree_model import docking_block_names

        values = ray_values(self.specs, self.direction, alpha)
        springs = []
        for spring in self.springs:
            names = docking_block_names(spring)
            given = {k: values.pop(n) for k, n in names.items() if n in values}
            if spring is self.springs[0]:  # the swept stiffness is the peak's, not a block's
                given = {k: v for k, v in given.items() if k not in ("k_shear", "k_tors")}
            springs.append(dataclasses.replace(spring, **given))
        return values, tuple(springs)

    def realization(self, alpha: float):
        """The flight software's dynamic perturbation at ``alpha`` (None without complex
        blocks)."""
        from oos_drake.multibody.flight_software import perturbation_block

        if not self.complex:
            return None
        scaled = {k: alpha * v for k, v in self.complex.items()}
        return perturbation_block(self.design, self.peak.omega, **scaled)

    def twin(self, alpha: float):
        """The closed-loop tree twin with the real parameters at ``alpha`` (built once)."""
        from oos_drake.multibody.tree_twin import build_tree_twin, tree_with_values

        if alpha not in self._twins:
            values, springs = self.parameters(alpha)
            # the realization's state count may differ between alphas (an entry's phase at
            # round-off from 0 or pi is a static gain in one SVD, a section in another): each
            # alpha has its own twin, sized for its own realization
            block = self.realization(alpha)
            self._twins[alpha] = build_tree_twin(
                tree_with_values(self.tree, values),
                self.design,
                self.angles,
                log_rate=self.log_rate,
                perturbation_states=0 if block is None else block.nstates,
                mating=self.mating,
                docking=springs,
            )
        return self._twins[alpha]

    def _simulate(self, alpha: float, noise_table, phi0: float):
        from oos_drake.multibody.tree_twin import run_tree_twin

        o = self.options
        return run_tree_twin(
            self.twin(alpha),
            o.duration,
            initial_attitude=phi0,
            noise_table=noise_table,
            dynamic=self.realization(alpha),
            max_step=min(o.max_step, self.design.period),
        )

    def forced_run(self, alpha: float, noise_table: np.ndarray):
        """As :meth:`_MissionTwin.forced_run`: ``(times, phi, T_rw, u)``."""
        from oos_drake.multibody.mission_sim import MissionDiverged

        run = self._simulate(alpha, noise_table, 0.0)
        if run.diverged:
            raise MissionDiverged(f"the forced run at alpha = {alpha:g} diverged")
        return run.times, run.phi, run.torques[:, 3:6], run.torques[:, 0:3]

    def run(self, alpha: float):
        """As :meth:`_MissionTwin.run`."""
        run = self._simulate(alpha, np.zeros((1, 9)), self.options.initial_attitude)
        return _verdict(run.times, run.phi, run.diverged, self.options, self.near_hz)


def _Twin(peak: Peak, K, options: ConfirmOptions, scenario, near_hz, specs, design):  # noqa: N802
    """The twin of a peak: :class:`_TreeTwin` for a schema-2 tree, else
    :class:`_MissionTwin` (the paper's Drake mission)."""
    from oos_drake.scenario.tree_scenario import is_tree

    twin = _TreeTwin if is_tree(scenario) else _MissionTwin
    return twin(peak, K, options, scenario, near_hz, specs, design)


def _nonlinear_boundary(twin, guess: float, alpha_top: float):
    """Bisection of the decay rate's sign change near ``guess``, below ``alpha_top``."""
    o = twin.options
    runs = {}

    def unstable(alpha):
        runs[alpha] = twin.run(alpha)
        return runs[alpha][0]

    lo = max(guess * (1.0 - o.bracket), 1e-3)
    hi = min(guess * (1.0 + o.bracket), alpha_top)
    while unstable(lo) and lo > 1e-2:
        hi, lo = lo, lo * (1.0 - 3 * o.bracket)
    if lo <= 1e-2 and runs[lo][0]:
        return 0.0, runs
    while not unstable(hi):
        if hi >= alpha_top:
            return math.inf, runs  # stable up to the top of the ray
        lo, hi = hi, min(hi * (1.0 + 3 * o.bracket), alpha_top)
    while hi - lo > o.rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return 0.5 * (lo + hi), runs


# -- one peak --------------------------------------------------------------------------------------
def _peak_models(peak: Peak, controller, scenario):
    from oos_drake.analysis.models import docking_plant, mission_plants
    from oos_drake.control.analysis_model import close_loop, uncertain_plant

    if peak.study == "mission":
        plant = mission_plants([peak.time], scenario).model(0)
    else:
        phase = peak.study.removeprefix("docking-")
        plant = docking_plant(phase, [peak.stiffness], scenario=scenario).model(0)
    return (
        close_loop(plant, controller.system, controller.spec),
        uncertain_plant(plant, controller.spec),
    )


def _inertia_bodies(scenario) -> tuple[BodyInertia, ...]:
    """The rigid bodies whose inertia blocks the physical check follows: the target hub RH2
    of the paper's topology, every rigid body of a tree (and of its targets)."""
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):
        trees = (scenario.tree, *scenario.tree.targets.values())
        return tuple(
            BodyInertia(
                (f"Jxx_{b.name}", f"Jyy_{b.name}", f"Jzz_{b.name}"),
                np.asarray(b.inertia, dtype=float),
            )
            for tree in trees
            for b in tree.bodies
            if b.kind == "rigid"
        )
    hub = scenario.hubs["RH2"]
    return (BodyInertia(("Jxx_RH2", "Jyy_RH2", "Jzz_RH2"), np.asarray(hub.inertia, dtype=float)),)


def confirm_peak(peak: Peak, controller, scenario, options: ConfirmOptions):
    """Linear predictions, physical limit and nonlinear boundary of one peak.

    Parameters
    ----------
    peak : Peak
    controller : Controller
    scenario : Scenario
        The analysis' scenario: the twin, its flight software and the linear models are built
        from it.
    options : ConfirmOptions

    Returns
    -------
    row : dict
        One row of ``confirmation.parquet``.
    histories : pandas.DataFrame
        Attitude histories of the runs on both sides of the boundary.
    """
    from oos_drake.multibody.flight_software import (
        FlightSoftware,
        FlightSoftwareDesign,
        perturbation_block,
    )

    closed, plant_hat = _peak_models(peak, controller, scenario)
    specs = closed.uncertainty
    direction = {n: v for n, v in peak.perturbation.items() if specs[n].kind == "ureal"}
    notes = []
    # 1. continuous linear loop
    alpha_c = boundary_along_ray(
        lambda a: _continuous_abscissa(closed, peak, a)[0] > GROWTH_TOLERANCE, options.alpha_limit
    )
    f_c = (
        _continuous_abscissa(closed, peak, alpha_c * (1 + 1e-3))[1] / (2 * np.pi)
        if np.isfinite(alpha_c) and np.isfinite(peak.omega)
        else math.nan  # beyond an ill-posed boundary the new pole comes back real, from infinity
    )
    if np.isfinite(alpha_c) and alpha_c < 1.0 - options.rtol:
        # the saved worst case is critical at alpha = 1: a crossing before it is one the analysis
        # did not see (between its analyzed frequencies, or at another frequency)
        crossing = _continuous_abscissa(closed, peak, alpha_c * (1 + 1e-3))[1] / (2 * np.pi)
        implied = peak.mu_lower / alpha_c
        notes.append(
            f"the continuous loop is unstable from alpha = {alpha_c:.4g} (a pole crosses near "
            f"{crossing:.4g} Hz): mu >= {implied:.4g}"
            + (
                f", ABOVE the analysis' upper bound {peak.mu_upper:.4g} (a peak between its "
                "analyzed frequencies: oos analyze --grid-only does not cover them)"
                if implied > peak.mu_upper
                else ""
            )
        )
    # 2. sampled-data linear loop with the twin's flight software (its components are the
    # scenario's [control] data, as make_mission_diagram builds them)
    from oos_drake.control.components import DesignSpecification

    twin_spec = DesignSpecification.from_requirements(scenario.control)
    if dataclasses.replace(controller.spec, sampled=False) != twin_spec:
        notes.append("the controller's design specification is not the twin's (scenario) one")
    design = FlightSoftwareDesign.create(
        controller.system,
        scenario.control.flight_software_rate_hz,
        spec=twin_spec,
        torque_limit=scenario.control.torque_limit,
    )
    software = FlightSoftware(design, 6, 6, 0, 0)
    period = design.period
    nyquist = np.isfinite(peak.omega) and peak.omega * period >= np.pi
    if peak.has_complex and nyquist:
        notes.append("critical frequency at or beyond the flight software's Nyquist frequency")

    mul = complex_values(peak).get("delta_mul")
    mul_block = (
        None if mul is None or nyquist else perturbation_block(design, peak.omega, delta_mul=mul)
    )

    def sampled_boundary(mul_block):
        def unstable(alpha):
            try:  # near an ill-posed point the plant's fastest pole overflows the hold's expm
                with np.errstate(over="ignore", invalid="ignore"):
                    poles = sampled_loop_poles(plant_hat, peak, alpha, software, mul_block)
            except (ValueError, np.linalg.LinAlgError):
                return True
            return bool(np.log(np.abs(poles).max()) / period > GROWTH_TOLERANCE)

        alpha = boundary_along_ray(unstable, options.alpha_limit)
        frequency = math.nan
        if np.isfinite(alpha) and np.isfinite(peak.omega):
            poles = sampled_loop_poles(plant_hat, peak, alpha * (1 + 1e-3), software, mul_block)
            z = poles[np.argmax(np.abs(poles))]
            frequency = abs(np.angle(z)) / (2 * np.pi * period)
        return alpha, frequency

    alpha_s, f_s = math.nan, math.nan
    if not (peak.has_complex and nyquist):
        alpha_s, f_s = sampled_boundary(mul_block)
    if mul_block is not None:
        # the twin computes Delta_mul at the sample, before the hold; the analysis' loop with a
        # hold has it behind the hold (its interpolant then also filters the hold's harmonics)
        alpha_h, f_h = sampled_boundary(None)
        notes.append(
            f"with Delta_mul behind the hold (continuous interpolant) the sampled loop's "
            f"boundary is alpha = {alpha_h:.4f} at {f_h:.4f} Hz"
        )
    if not np.isfinite(peak.omega):
        notes.append(
            "infinite frequency: the loop becomes ill-posed (a mass matrix singular) at alpha "
            "= 1, a pole leaves through infinity: no oscillation to identify"
        )
    # 3. physical limit of the real parameters
    alpha_phys, reason = physical_alpha_max(
        specs, direction, _inertia_bodies(scenario), alpha_limit=options.alpha_limit
    )
    row = {
        "study": peak.study,
        "subset": peak.subset,
        "time [s]": peak.time,
        "stiffness [N/m or N m/rad]": peak.stiffness,
        "critical frequency [Hz]": peak.omega / (2 * np.pi),
        "mu lower [-]": peak.mu_lower,
        "mu upper [-]": peak.mu_upper,
        "alpha linear continuous [-]": alpha_c,
        "frequency linear continuous [Hz]": f_c,
        "alpha linear sampled [-]": alpha_s,
        "frequency linear sampled [Hz]": f_s,
        "alpha physical max [-]": alpha_phys,
        "physical limit": reason,
        "alpha nonlinear [-]": math.nan,
        "oscillation frequency [Hz]": math.nan,
        "decay rate below [1/s]": math.nan,
        "decay rate above [1/s]": math.nan,
        "nonlinear runs": 0,
    }
    histories = pd.DataFrame()
    if peak.has_complex and nyquist:
        row["status"] = "linear only: complex blocks beyond the flight software's Nyquist frequency"
    else:
        run_options = options.for_peak(f_s, peak.omega / (2 * np.pi)).within_torque_limit(
            controller.system, design.torque_limit
        )
        twin = _Twin(peak, controller.system, run_options, scenario, f_s, specs, design)
        top = min(alpha_phys * (1 - 1e-3), options.alpha_limit)
        guess = alpha_s if np.isfinite(alpha_s) else 1.0
        if guess >= top:
            runs = {top: twin.run(top)}
            alpha_n = math.inf
            if runs[top][0]:  # unstable below the prediction: search under the top
                alpha_n, below = _nonlinear_boundary(twin, top, top)
                runs |= below
        else:
            alpha_n, runs = _nonlinear_boundary(twin, guess, top)
        row["nonlinear runs"] = len(runs)
        stable = [a for a, r in runs.items() if not r[0]]
        unstable = [a for a, r in runs.items() if r[0]]
        parts = []
        if stable:
            a = max(stable)
            parts.append(runs[a][2].assign(side="stable", **{"alpha [-]": a}))
            row["decay rate below [1/s]"] = runs[a][1].decay_rate if runs[a][1] else math.nan
        if unstable:
            a = min(unstable)
            parts.append(runs[a][2].assign(side="unstable", **{"alpha [-]": a}))
            osc = runs[a][1]
            row["decay rate above [1/s]"] = osc.decay_rate if osc else math.nan
        # the oscillation frequency closest to the boundary (the run nearest to it)
        near = min(runs, key=lambda a: abs(a - alpha_n) if np.isfinite(alpha_n) else -a)
        if runs[near][1] is not None:
            row["oscillation frequency [Hz]"] = runs[near][1].frequency
        row["alpha nonlinear [-]"] = alpha_n
        if parts:
            histories = pd.concat(parts, ignore_index=True).assign(
                study=peak.study, subset=peak.subset
            )
        row["status"] = _status(row, alpha_n, np.isfinite(peak.omega))
    row["notes"] = "; ".join(notes)
    return row, histories


def _status(row: Mapping, alpha_n: float, finite: bool) -> str:
    """Verdict of one nonlinear confirmation (:data:`AGREEMENT` on alpha and frequency)."""
    if np.isinf(alpha_n):
        limit = "stable up to the physical limit"
        return limit if finite else f"ill-posed at infinite frequency; {limit}"
    if not finite:
        return "ill-posed at infinite frequency; unstable below the physical limit"

    def close(a, b):
        return abs(a / b - 1.0) <= AGREEMENT

    f = row["oscillation frequency [Hz]"]
    if not (
        close(alpha_n, row["alpha linear sampled [-]"])
        and close(f, row["frequency linear sampled [Hz]"])
    ):
        return "mismatch with the sampled-data loop"
    if close(f, row["critical frequency [Hz]"]):
        return "confirmed"
    return (
        "confirmed on the sampled-data loop; its crossing frequency differs from the continuous one"
    )


def _confirm_task(args):
    from oos_drake.blas import single_threaded_blas

    with single_threaded_blas():  # restored after: ``--workers 1`` runs it in this process
        return confirm_peak(*args)


def confirm_peaks(
    peaks, controller, scenario, options: ConfirmOptions, *, workers=1, scheduler=None, quiet=False
):
    """:func:`confirm_peak` for every peak on ``workers`` processes (the scenario is sent to
    them as itself: it pickles).

    ``scheduler``: where they run (:func:`oos_drake.processes.make_executor`; the local pool's
    workers are spawned, not forked: Drake's threads do not survive a fork).

    Returns
    -------
    table : pandas.DataFrame
        One row per peak (``confirmation.parquet``).
    histories : pandas.DataFrame
        Attitude histories on both sides of each nonlinear boundary.
    """
    from tqdm import tqdm

    from oos_drake.processes import make_executor

    tasks = [(peak, controller, scenario, options) for peak in peaks]
    with make_executor(max(1, min(workers, len(tasks))), scheduler, method="spawn") as executor:
        futures = [executor.submit(_confirm_task, task) for task in tasks]
        for future in tqdm(
            executor.as_completed(futures), total=len(futures), desc="confirm", disable=quiet
        ):
            future.result()  # a failed peak stops the confirmation as soon as it fails
        results = [future.result() for future in futures]
    histories = [history for _, history in results if not history.empty]
    table = pd.DataFrame([row for row, _ in results])
    return table, pd.concat(histories, ignore_index=True) if histories else pd.DataFrame()


#: Columns of each peak's record in the confirmation summary (:meth:`ConfirmationResult.summary`).
PEAK_SUMMARY_COLUMNS = (
    "study",
    "subset",
    "critical frequency [Hz]",
    "alpha linear continuous [-]",
    "alpha linear sampled [-]",
    "alpha physical max [-]",
    "alpha nonlinear [-]",
    "oscillation frequency [Hz]",
    "status",
)


@dataclass(frozen=True)
class ConfirmationOptions:
    """What the confirmation stage computes (``oos confirm``'s options; the analysis folder,
    the controller and the scenario apart).

    Attributes
    ----------
    twin : ConfirmOptions
        The nonlinear confirmation's runs (``--alpha-limit``; the rest at their defaults).
    workers : int
        Worker processes, one peak or worst-case gain each (``--workers``).
    scheduler : str or None
        Where they run (``--scheduler``; :func:`oos_drake.processes.make_executor`).
    progress : bool
        tqdm progress bar of the peaks (``not --quiet``).
    """

    twin: ConfirmOptions = field(default_factory=ConfirmOptions)
    workers: int = 1
    scheduler: str | None = None
    progress: bool = True

    def __post_init__(self):
        from oos_drake.processes import check_workers

        check_workers(self.workers)


@dataclass(frozen=True)
class ConfirmationResult:
    """The confirmation stage of one analysis (:func:`compute_confirmation`): what
    ``oos confirm`` writes, as one frozen object (no file, no figure).

    Attributes
    ----------
    controller : Controller
        The analysis' controller.
    scenario : Scenario
        The analysis' scenario (the twin's).
    options : ConfirmationOptions
        What was computed.
    confirmation : pandas.DataFrame
        One row per certified peak (:func:`confirm_peak`; ``confirmation.parquet``).
    histories : pandas.DataFrame
        Hub attitude histories on both sides of each nonlinear boundary
        (``confirmation_histories.parquet``; empty without nonlinear runs).
    performance : pandas.DataFrame
        One row per worst-case gain of the analysis
        (:func:`oos_drake.analysis.performance_twin.confirm_performance`;
        ``performance_confirmation.parquet``).
    seconds : float
        Wall time of the computation [s].
    """

    controller: object
    scenario: object
    options: ConfirmationOptions
    confirmation: pd.DataFrame
    histories: pd.DataFrame
    performance: pd.DataFrame
    seconds: float

    def tables(self) -> dict[str, pd.DataFrame]:
        """File stem -> table: ``confirmation``, ``confirmation_histories`` and
        ``performance_confirmation`` (each written, empty ones included)."""
        return {
            Path(CONFIRMATION_FILE).stem: self.confirmation,
            Path(HISTORIES_FILE).stem: self.histories,
            "performance_confirmation": self.performance,
        }

    def peak_histories(self) -> list[tuple[pd.Series, pd.DataFrame]]:
        """``(row, histories)`` of each peak of :attr:`confirmation` with nonlinear runs, in
        table order (one figure each)."""
        pairs = []
        if self.histories.empty:
            return pairs
        for _, row in self.confirmation.iterrows():
            part = self.histories[
                (self.histories["study"] == row["study"])
                & (self.histories["subset"] == row["subset"])
            ]
            if not part.empty:
                pairs.append((row, part))
        return pairs

    def warnings(self) -> list[str]:
        """One line per crossing the analysis missed (a note saying ``ABOVE`` its upper
        bound): ``"<study> <subset>: <note>"``."""
        lines = []
        for _, row in self.confirmation.iterrows():
            for note in str(row["notes"]).split("; "):
                if "ABOVE" in note:
                    lines.append(f"{row['study']} {row['subset']}: {note}")
        return lines

    def summary(self) -> dict:
        """The record of the stage (what ``oos confirm`` prints): scenario, controller, each
        peak's boundaries and status (:data:`PEAK_SUMMARY_COLUMNS`), the warnings, each
        worst-case gain on the twin and the wall time [s]."""
        from oos_drake.analysis.performance_twin import PERFORMANCE_SUMMARY_COLUMNS

        peaks = self.confirmation
        performance = self.performance
        return {
            "scenario": {"name": self.scenario.name, "source": str(self.scenario.source)},
            "controller": {"label": self.controller.label, "source": self.controller.source},
            "peaks": peaks[list(PEAK_SUMMARY_COLUMNS)].to_dict(orient="records")
            if not peaks.empty
            else [],
            "warnings": self.warnings(),
            "performance": performance[list(PERFORMANCE_SUMMARY_COLUMNS)].to_dict(orient="records"),
            "time_s": round(self.seconds, 2),
        }


def compute_confirmation(
    peaks, gain_cases, controller, scenario, options: ConfirmationOptions
) -> ConfirmationResult:
    """The confirmation stage: :func:`confirm_peaks` for the certified ``peaks`` and
    :func:`~oos_drake.analysis.performance_twin.confirm_performance` for the worst-case
    ``gain_cases``, on ``options.workers`` processes; nothing written
    (:func:`~oos_drake.analysis.writers.write_confirmation` writes the result).

    Parameters
    ----------
    peaks : list of Peak
        The analysis' certified peaks (:func:`read_peaks`).
    gain_cases : list of GainCase
        Its worst-case gains
        (:func:`~oos_drake.analysis.performance_twin.read_gain_cases`).
    controller : Controller
        The analysis' controller.
    scenario : Scenario
        The analysis' scenario: the twin and the linear models are built from it.
    options : ConfirmationOptions

    Returns
    -------
    ConfirmationResult
    """
    import time

    from oos_drake.analysis.performance_twin import confirm_performance

    start = time.perf_counter()
    parallel = {"workers": options.workers, "scheduler": options.scheduler}
    table, histories = confirm_peaks(
        peaks, controller, scenario, options.twin, quiet=not options.progress, **parallel
    )
    performance = confirm_performance(gain_cases, controller, scenario, **parallel)
    return ConfirmationResult(
        controller=controller,
        scenario=scenario,
        options=options,
        confirmation=table,
        histories=histories,
        performance=performance,
        seconds=time.perf_counter() - start,
    )
