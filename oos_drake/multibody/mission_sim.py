"""Run one closed-loop mission simulation: dispersed values in, metrics and time series out.

:class:`MissionSimulation` runs on a mission diagram built once
(:func:`~oos_drake.multibody.mission.make_mission_diagram`) and runs any window of the mission
from a fresh context: the run is a pure function of ``(values, seed, window)``, so a rerun
reproduces its metrics exactly.

Mission events (paper data, ``oos_drake/scenario/data/paper.toml``):

============  ========  ====================================================================
event         time [s]  what happens in the simulation
============  ========  ====================================================================
``capture``   255       the (free, decoupled) target is placed so that D2 meets the arm tip J7
                        with J7's velocity; SM1 stiffness ramps log-linearly from 0.1 to its
                        dispersed value (``k_shear_SM1``, ``k_tors_SM1``) over ``ramp_duration``
                        with damping ``d_shear_SM1``, ``d_tors_SM1`` from the contact on
``docking``   880       SM2 (D1 - D3) ramps up the same way, then SM1 ramps down to 0
                        (the arm is released and retreats)
``tilt``      1100      the chaser arrays start their half-turn
============  ========  ====================================================================

A window that starts after an event starts in the corresponding connected state (target on the
arm tip, or on the hub). The hub starts at the dispersed attitude and body rate errors.

Window starts are not momentum-continuations of a run from t = 0: the arm, arrays and target
start on their trajectories (joint angles and rates of the timeline), the hub at the dispersed
attitude ``phi0`` and rate ``w0`` (nominal: at rest), whereas a run from t = 0 reaches the same
time with the hub carrying what the earlier motions and the controller left. Measured on the
nominal case without noise, baseline gains (``benchmarks/bench_mission_sim.py
--window-start-study``): the run from t = 0 has a hub rate of 1.2e-4 rad/s at 235 s and
1e-6 rad/s at 580 s; the APE over [255, 315] s is 1.45 mrad from t = 0, 1.87 mrad (+29 %) from
a window starting at 235 s and 1.37 mrad (-6 %) from 195 s; over [600, 660] s 0.28 mrad from
t = 0, 0.21 mrad from 580 s and 0.26 mrad from 540 s. The largest attitude difference is
0.5 mrad with a 20 s lead (6 % of the 7.9 mrad requirement) and 0.1 mrad with a 60 s lead. The
campaign's initial-error dispersions (``phi0`` std 1 mrad, ``w0`` std 1e-4 rad/s in
the shipped spec ``paper.toml``) are of the size of this residual; a longer ``before`` in the window
brings a window closer to the continuation, at the price of simulated time.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import pandas as pd
from pydrake.math import RollPitchYaw
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator

from oos_drake.lfr.blocks import RANGE_RTOL
from oos_drake.multibody.flight_software import LOG_SIGNALS, NOISE_CHANNELS
from oos_drake.multibody.mission import ARRAYS, MissionDiagram
from oos_drake.multibody.plant_parts import set_central_inertia, set_mode_frequency
from oos_drake.multibody.scenario_plant import set_bushing
from oos_drake.scenario.model import physical_blocks

__all__ = [
    "MissionDiverged",
    "MissionParameter",
    "MissionResult",
    "MissionSimulation",
    "METRIC_UNITS",
    "SIGNAL_UNITS",
    "SINE_CHANNELS",
    "disturbance_parameters",
    "disturbance_table",
    "mission_parameters",
    "sine_table",
]

AXES = ("x", "y", "z")


class MissionDiverged(RuntimeError):
    """The run left the model's domain (attitude beyond the limit, integrator failure)."""


@dataclass(frozen=True)
class MissionParameter:
    """A dispersible parameter of the mission simulation.

    Attributes
    ----------
    name : str
        Uncertain-block name (as in the LFR model) or initial-condition / seed name.
    unit : str
        Unit of the physical value (an uncertain block's own unit).
    nominal, lower, upper : float
        Nominal value and valid range [unit].
    quantity : str
        What the parameter is: the uncertain block's quantity (``"mass"``, ``"inertia"``,
        ``"modal frequency"``, ``"stiffness"``, ``"damping"``, ``"additive dynamics"``,
        ``"multiplicative dynamics"``, see :data:`oos_drake.lfr.blocks.QUANTITIES`), or
        ``"initial condition"`` / ``"seed"``.
    description : str
        One line.
    """

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    quantity: str
    description: str


#: Valid range of the bushing stiffness [N/m or N m/rad] and damping [N s/m or N m s/rad] in the
#: Drake mission (wider than the LFR docking blocks' ``[0, 2 x nominal]``: the bushing model
#: holds from a loose capture to a stiff weld).
BUSHING_RANGES = {"stiffness": (0.1, 1e6), "damping": (0.0, 1e4)}


def mission_parameters(scenario) -> tuple[MissionParameter, ...]:
    """Every dispersible parameter, with nominal values and ranges from the scenario data.

    The uncertain physical parameters are the scenario model's own blocks
    (:func:`oos_drake.scenario.model.physical_blocks`): the target hub's mass and inertias, the
    arrays' first mode frequencies and the docking spring-dampers, with the blocks' units,
    quantities, nominal values and ranges (the bushings' ranges are :data:`BUSHING_RANGES`).
    """
    blocks = physical_blocks(scenario)
    descriptions = {"m_RH2": "target hub mass"}
    for axis in ("xx", "yy", "zz"):
        descriptions[f"J{axis}_RH2"] = f"target hub inertia J{axis} at G2"
    for array in ARRAYS:
        descriptions[f"w1_{array}"] = f"first cantilever mode frequency of {array}"
    for sm in ("SM1", "SM2"):
        descriptions |= {
            f"k_shear_{sm}": f"{sm} final shear stiffness",
            f"k_tors_{sm}": f"{sm} final torsional stiffness",
            f"d_shear_{sm}": f"{sm} shear damping",
            f"d_tors_{sm}": f"{sm} torsional damping",
        }
    params = []
    for name, description in descriptions.items():
        block = blocks[name]
        lower, upper = BUSHING_RANGES.get(block.quantity, block.range)
        params.append(
            MissionParameter(
                name, block.unit, block.nominal, lower, upper, block.quantity, description
            )
        )

    def centred(name, unit, bound, quantity, description):
        """A parameter of nominal 0 and range ``[-bound, bound]``."""
        return MissionParameter(name, unit, 0.0, -bound, bound, quantity, description)

    for prefix, unit, bound, what in (
        ("phi0", "rad", 0.05, "attitude error"),
        ("w0", "rad/s", 0.01, "body rate error"),
    ):
        params += [
            centred(f"{prefix}_{a}", unit, bound, "initial condition", f"initial hub {what} ({a})")
            for a in AXES
        ]
    params.append(
        MissionParameter(
            "noise_seed",
            "-",
            0.0,
            0.0,
            2.0**31,
            "seed",
            "seed of sensor noise and disturbances (0: the run seed)",
        )
    )
    params += [
        centred(
            f"Delta_mul_{row}{col}",
            "-",
            1.0,
            "multiplicative dynamics",
            f"entry {row}{col} of the multiplicative actuator all-pass perturbation",
        )
        for row in AXES
        for col in AXES
    ]
    description = "scale of the additive plant all-pass perturbation"
    params.append(centred("Delta_add", "-", 1.0, "additive dynamics", description))
    return tuple(params) + disturbance_parameters()


#: Noise-table channels (the flight software's order: star tracker, gyro, external torque).
SINE_CHANNELS = tuple(f"{source}_{a}" for source in ("n_sst", "n_gyro", "d_ext") for a in AXES)
#: Largest sinusoid frequency [Hz] (the flight software samples it: above its Nyquist
#: frequency the sinusoid aliases).
SINE_MAX_FREQUENCY = 50.0


def disturbance_parameters() -> tuple[MissionParameter, ...]:
    """The parameters of the run's disturbance and noise inputs (module :func:`noise_table`).

    ``noise_scale`` scales the random unit sequences (1: the paper's noise levels, 0: none);
    ``sine_amplitude`` [-], ``sine_frequency`` [Hz] and the complex direction
    ``sine_re_<channel>``, ``sine_im_<channel>`` (channels :data:`SINE_CHANNELS`) define the
    sinusoid added to them (nominal: none).
    """
    quantity = "disturbance"
    params = [
        MissionParameter(
            "noise_scale",
            "-",
            1.0,
            0.0,
            10.0,
            quantity,
            "scale of the random sensor noise and disturbance sequences (1: the scenario's)",
        ),
        MissionParameter(
            "sine_amplitude",
            "-",
            0.0,
            0.0,
            10.0,
            quantity,
            "amplitude of the sinusoidal input over its unit direction (1: the analysis' "
            "unit input, shaped by the noise and disturbance weights)",
        ),
        MissionParameter(
            "sine_frequency",
            "Hz",
            0.1,
            1.0e-4,
            SINE_MAX_FREQUENCY,
            quantity,
            "frequency of the sinusoidal input",
        ),
    ]
    for part, what in (("re", "real"), ("im", "imaginary")):
        params += [
            MissionParameter(
                f"sine_{part}_{channel}",
                "-",
                0.0,
                -1.0,
                1.0,
                quantity,
                f"{what} part of the sinusoid's direction on {channel} (normalized to unit norm)",
            )
            for channel in SINE_CHANNELS
        ]
    return tuple(params)


def sine_table(values: Mapping[str, float], times: np.ndarray) -> np.ndarray:
    """The sinusoidal input at the flight software's samples (unit noise-table columns).

    .. math::

        d(t_k) = a \\, \\mathrm{Re}\\left(\\frac{c}{\\|c\\|_2} e^{j 2 \\pi f t_k}\\right)

    with ``a`` = ``sine_amplitude``, ``f`` = ``sine_frequency`` [Hz], ``c`` the complex
    direction of the ``sine_re_*``, ``sine_im_*`` values and ``t_k`` the mission time of the
    sample [s]; zero when ``a = 0`` or ``c = 0``. A unit amplitude is a unit 2-norm phasor over
    the nine unit inputs: the analysis' normalized disturbance ``d`` (the flight software scales
    the columns with the noise and disturbance weights, as it scales the random sequences).

    Parameters
    ----------
    values : mapping
        Resolved parameter values (:meth:`MissionSimulation.resolve`).
    times : numpy.ndarray, shape (n,)
        Sample times [s].

    Returns
    -------
    numpy.ndarray, shape (n, 9)
    """
    c = np.array([values[f"sine_re_{ch}"] + 1j * values[f"sine_im_{ch}"] for ch in SINE_CHANNELS])
    norm = float(np.linalg.norm(c))
    amplitude = float(values["sine_amplitude"])
    if amplitude == 0.0 or norm == 0.0:
        return np.zeros((np.size(times), NOISE_CHANNELS))
    phase = np.exp(2j * np.pi * float(values["sine_frequency"]) * np.asarray(times, float))
    return amplitude * np.real(np.outer(phase, c / norm))


def disturbance_table(
    values: Mapping[str, float], noise_table: np.ndarray, start: float, rate: float
) -> np.ndarray:
    """The flight software's unit input table of a run: the random ``noise_table`` (rows: one
    per sample) scaled by ``noise_scale``, plus the sinusoid of :func:`sine_table` (row ``k`` at
    ``start + k / rate`` [s]); the mission's and a tree twin's
    (:mod:`oos_drake.campaign.tree_simulator`).

    Parameters
    ----------
    values : mapping
        ``noise_scale``, ``sine_amplitude`` and the sinusoid's parameters (:func:`sine_table`).
    noise_table : numpy.ndarray, shape (n, 9)
        Unit ``[n_sst; n_gyro; d_ext]`` per flight-software sample.
    start : float
        Mission time of the first row [s].
    rate : float
        Flight-software rate [Hz].
    """
    table = np.asarray(noise_table, dtype=float)
    if values["noise_scale"] != 1.0:
        table = values["noise_scale"] * table
    if values["sine_amplitude"] != 0.0:
        table = table + sine_table(values, float(start) + np.arange(table.shape[0]) / rate)
    return table


METRIC_UNITS = MappingProxyType(
    {
        "ape": "rad",
        "rms_attitude": "rad",
        "peak_torque": "N m",
        "peak_applied_torque": "N m",
        "max_force_SM1": "N",
        "max_force_SM2": "N",
        "max_tracking_error": "rad",
    }
)


def _signal_units() -> dict[str, str]:
    units = {}
    for prefix, unit in (
        ("phi", "rad"),
        ("w", "rad/s"),
        ("u", "N m"),
        ("T_rw", "N m"),
        ("T", "N m"),
        ("T_dist", "N m"),
    ):
        units.update({f"{prefix}_{a}": unit for a in AXES})
    for sm in ("SM1", "SM2"):
        units[f"F_{sm}"] = "N"
        units[f"M_{sm}"] = "N m"
    for array in ARRAYS:
        units.update({f"q{i}_{array}": "rad" for i in range(1, 7)})
    return units


SIGNAL_UNITS = MappingProxyType(_signal_units())


@dataclass(frozen=True, eq=False)
class MissionResult:
    """Outcome of one run.

    Attributes
    ----------
    metrics : Mapping[str, float]
        See :data:`METRIC_UNITS`.
    timeseries : pandas.DataFrame
        ``"time [s]"`` and one ``"name [unit]"`` column per :data:`SIGNAL_UNITS` entry.
    wall_time : float
        Wall-clock time of the simulation [s] (without building the context and the log table).
    cpu_time : float
        Processor time of this process over the same span [s] (the one-core figure on a shared
        machine).
    steps : int
        Integrator steps taken.
    statistics : Mapping[str, float]
        Drake's integrator statistics of the run (``GetStatisticsSummary``: derivative
        evaluations, Newton-Raphson iterations, Jacobian evaluations, matrix factorizations,
        each for the integrator and its error estimator).
    """

    metrics: Mapping[str, float]
    timeseries: pd.DataFrame
    wall_time: float
    cpu_time: float
    steps: int
    statistics: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True)
class _Schedule:
    """Docking bushing settings over time (piecewise constant)."""

    t_capture: float
    t_docking: float
    duration: float
    steps: int
    k0: float
    values: Mapping[str, float]
    #: Settings held over the whole run instead of the mission's (``settings`` format).
    frozen: Mapping[str, tuple[float, float, float, float]] | None = None

    def _ramp(self, t, t0, k_from, k_to):
        i = min(int(math.floor((t - t0) / self.duration * self.steps + 1e-9)), self.steps - 1)
        frac = i / (self.steps - 1) if self.steps > 1 else 1.0
        return k_from * (k_to / k_from) ** frac

    def _ramped(self, t, t0, setting, up: bool):
        """``setting`` with its two stiffnesses on the ramp from ``t0``: from ``k0`` up to them
        (``up``) or from them down to ``k0``; the dampings are kept."""
        k_shear, k_tors, d_shear, d_tors = setting
        ends = [(self.k0, k) if up else (k, self.k0) for k in (k_shear, k_tors)]
        return (*(self._ramp(t, t0, *pair) for pair in ends), d_shear, d_tors)

    def settings(self, t: float) -> dict[str, tuple[float, float, float, float]]:
        """``{"SM1": (k_shear, k_tors, d_shear, d_tors), "SM2": ...}`` at time ``t``."""
        v, R = self.values, self.duration
        out = {"SM1": (0.0, 0.0, 0.0, 0.0), "SM2": (0.0, 0.0, 0.0, 0.0)}
        if self.frozen is not None:
            return out | dict(self.frozen)
        sm1 = (v["k_shear_SM1"], v["k_tors_SM1"], v["d_shear_SM1"], v["d_tors_SM1"])
        sm2 = (v["k_shear_SM2"], v["k_tors_SM2"], v["d_shear_SM2"], v["d_tors_SM2"])
        if t < self.t_capture:
            return out
        if t < self.t_capture + R:
            out["SM1"] = self._ramped(t, self.t_capture, sm1, up=True)
            return out
        if t < self.t_docking:
            out["SM1"] = sm1
            return out
        if t < self.t_docking + R:
            out["SM1"] = sm1
            out["SM2"] = self._ramped(t, self.t_docking, sm2, up=True)
            return out
        out["SM2"] = sm2
        if t < self.t_docking + 2 * R:
            out["SM1"] = self._ramped(t, self.t_docking + R, sm1, up=False)
        return out

    def ramp_intervals(self) -> list[tuple[float, float]]:
        """``[(start, end)]`` of the stiffness ramps [s]: capture (SM1 up), docking (SM2 up,
        then SM1 down)."""
        R = self.duration
        if self.frozen is not None:
            return []
        return [(self.t_capture, self.t_capture + R), (self.t_docking, self.t_docking + 2 * R)]

    def breakpoints(self, start: float, end: float) -> list[float]:
        """Times in ``(start, end)`` where the settings change."""
        R, n = self.duration, self.steps
        if self.frozen is not None:
            return []
        times = [self.t_capture + i * R / n for i in range(n + 1)]
        times += [self.t_docking + i * R / n for i in range(2 * n + 1)]
        return sorted(t for t in set(times) if start < t < end)


class MissionSimulation:
    """The mission diagram of one process and the runs on it.

    Parameters
    ----------
    handles : MissionDiagram
        The diagram (:func:`~oos_drake.multibody.mission.make_mission_diagram`: its scenario,
        its options).
    """

    def __init__(self, handles: MissionDiagram):
        self.handles = handles
        self.options = self.handles.options
        scenario = self.handles.scenario
        self.parameters = mission_parameters(scenario)
        self._by_name = {p.name: p for p in self.parameters}
        mission = scenario.mission
        self.events = MappingProxyType(
            {
                "capture": float(mission.first_docking_time),
                "docking": float(mission.second_docking_time),
                "tilt": float(mission.tilt_start_time),
            }
        )
        self.duration = float(mission.t_end - mission.t_start)

    # -- values ---------------------------------------------------------------------------------
    def resolve(
        self, values: Mapping[str, float] | None, *, within_ranges: bool = True
    ) -> dict[str, float]:
        """Nominal values overridden by ``values``; unknown names or values out of range raise.

        ``within_ranges=False`` accepts any finite value (a worst case beyond the uncertainty
        ranges; whether it is a physical body is the caller's check, and Drake refuses some).
        """
        out = {p.name: float(p.nominal) for p in self.parameters}
        for name, value in dict(values or {}).items():
            if name not in self._by_name:
                raise ValueError(f"mission: unknown parameter {name!r}; known: {', '.join(out)}")
            p = self._by_name[name]
            value = float(value)
            # a bound written in decimal may miss the block's computed range by round-off
            slack = RANGE_RTOL * max(1.0, abs(p.lower), abs(p.upper))
            if not math.isfinite(value):
                raise ValueError(f"mission: {name} = {value!r} is not a finite number")
            if not within_ranges:
                out[name] = value
                continue
            if not p.lower - slack <= value <= p.upper + slack:
                raise ValueError(
                    f"mission: {name} = {value:g} {p.unit} outside [{p.lower:g}, {p.upper:g}]"
                )
            out[name] = min(max(value, p.lower), p.upper)
        return out

    def schedule(self, values: Mapping[str, float], bushings=None) -> _Schedule:
        """Docking bushing schedule of a run (``bushings``: settings held throughout, see
        :meth:`run`)."""
        o = self.options
        if bushings is not None:
            unknown = set(bushings) - {"SM1", "SM2"}
            if unknown:
                raise ValueError(f"mission: unknown bushing(s) {sorted(unknown)}; known: SM1, SM2")
            for name, setting in bushings.items():
                if len(setting) != 4 or not all(math.isfinite(v) and v >= 0 for v in setting):
                    raise ValueError(
                        f"mission: bushing {name} settings must be 4 finite values >= 0 "
                        f"(k_shear, k_tors, d_shear, d_tors), got {setting!r}"
                    )
            bushings = MappingProxyType({k: tuple(map(float, v)) for k, v in bushings.items()})
        return _Schedule(
            self.events["capture"],
            self.events["docking"],
            o.ramp_duration,
            int(o.ramp_steps),
            o.ramp_start_stiffness,
            dict(values),
            bushings,
        )

    def apply_parameters(
        self, context, values: Mapping[str, float], perturbation_frequency_hz: float = math.nan
    ) -> None:
        """Write the model parameters (target inertia, mode frequencies, perturbations) into a
        root ``context``; the LTI perturbations' all-pass turns at ``perturbation_frequency_hz``
        [Hz] (see :meth:`run`)."""
        h = self.handles
        pc = h.plant.GetMyMutableContextFromRoot(context)
        moments = {0: values["Jxx_RH2"], 1: values["Jyy_RH2"], 2: values["Jzz_RH2"]}
        set_central_inertia(h.target_body, pc, values["m_RH2"], moments)
        for array in ARRAYS:
            ratio = values[f"w1_{array}"] / self._by_name[f"w1_{array}"].nominal
            set_mode_frequency(h.mode_springs[array][0], h.mode_joints[array][0], pc, ratio)
        h.flight_software.set_perturbations(
            h.flight_software.GetMyMutableContextFromRoot(context),
            [[values[f"Delta_mul_{r}{c}"] for c in AXES] for r in AXES],
            values["Delta_add"],
            perturbation_frequency_hz,
        )

    def _set_bushings(self, context, settings) -> None:
        pc = self.handles.plant.GetMyMutableContextFromRoot(context)
        for name, setting in settings.items():
            set_bushing(self.handles.bushings[name], pc, setting)

    def _place_target(self, context, on: str) -> None:
        """Put the target so that D2 = J7 (``on="arm"``) or D3 = D1 (``on="hub"``), moving with
        that frame."""
        h = self.handles
        pc = h.plant.GetMyMutableContextFromRoot(context)
        f = h.frames
        port, mate = ("D2", "J7") if on == "arm" else ("D3", "D1")
        X_WM = f[mate].CalcPoseInWorld(pc)
        X_WG2 = X_WM @ f[port].GetFixedPoseInBodyFrame().inverse()
        h.target_joint.SetPose(pc, X_WG2)
        V_WM = f[mate].CalcSpatialVelocityInWorld(pc)
        p_MG2_W = X_WG2.translation() - X_WM.translation()
        V_WG2 = V_WM.Shift(p_MG2_W)
        h.target_joint.set_angular_velocity(pc, V_WG2.rotational())
        h.target_joint.set_translational_velocity(pc, V_WG2.translational())

    def initial_context(
        self,
        values: Mapping[str, float],
        seed: int,
        start: float,
        end: float,
        noise_table: np.ndarray | None = None,
        perturbation_frequency_hz: float = math.nan,
        *,
        within_ranges: bool = True,
        bushings=None,
    ):
        """A root context at the window start with every value applied (see the module doc).

        ``noise_table`` (``(n, 9)``: unit ``[n_sst; n_gyro; d_ext]`` per sample) replaces the
        seeded Gaussian noise (deterministic inputs for tests); either is scaled by
        ``noise_scale`` and the sinusoid of :func:`sine_table` (row ``k`` at ``start + k /
        control_rate``) is added; ``perturbation_frequency_hz``,
        ``bushings``: see :meth:`run`; ``within_ranges`` as in :meth:`resolve`.
        """
        h = self.handles
        values = self.resolve(values, within_ranges=within_ranges)
        context = h.diagram.CreateDefaultContext()
        context.SetTime(float(start))
        pc = h.plant.GetMyMutableContextFromRoot(context)
        self.apply_parameters(context, values, perturbation_frequency_hz)
        t = float(start)
        config = h.timeline.configuration(t)
        rates = h.timeline.rates(t)
        for joint, angle, rate in zip(h.arm_joints, config.alpha, rates.alpha_dot, strict=True):
            joint.set_angle(pc, angle)
            joint.set_angular_rate(pc, rate)
        for joint, angle, rate in zip(h.drive_joints, config.theta, rates.theta_dot, strict=True):
            joint.set_angle(pc, angle)
            joint.set_angular_rate(pc, rate)
        phi0 = np.array([values[f"phi0_{a}"] for a in AXES])
        w0_B = np.array([values[f"w0_{a}"] for a in AXES])
        h.hub_joint.set_angles(pc, phi0)
        R_WB = RollPitchYaw(phi0).ToRotationMatrix().matrix()
        h.hub_joint.set_angular_velocity(pc, R_WB @ w0_B)
        schedule = self.schedule(values, bushings)
        if t < self.events["capture"]:
            # decoupled: put the target at its grasp pose (it is reset at the capture anyway)
            grasp = h.timeline.configuration(self.events["capture"])
            saved = [j.get_angle(pc) for j in h.arm_joints]
            for joint, angle in zip(h.arm_joints, grasp.alpha, strict=True):
                joint.set_angle(pc, angle)
            self._place_target(context, "arm")
            h.target_joint.set_angular_velocity(pc, np.zeros(3))
            h.target_joint.set_translational_velocity(pc, np.zeros(3))
            for joint, angle in zip(h.arm_joints, saved, strict=True):
                joint.set_angle(pc, angle)
        elif t < self.events["docking"] + self.options.ramp_duration:
            self._place_target(context, "arm")
        else:
            self._place_target(context, "hub")
        self._set_bushings(context, schedule.settings(t))
        fsw = h.flight_software
        fsw_context = fsw.GetMyMutableContextFromRoot(context)
        noise_seed = int(values["noise_seed"]) or int(seed)
        n = int(math.ceil((end - start) * self.options.control_rate)) + 2
        if noise_table is None:
            noise_table = np.random.default_rng(noise_seed).standard_normal((n, NOISE_CHANNELS))
        noise_table = disturbance_table(values, noise_table, start, self.options.control_rate)
        fsw.set_noise(fsw_context, noise_table)
        # sensor filters start at their steady state for the initial measurement
        state = fsw_context.get_mutable_discrete_state(0).get_mutable_value()
        s = fsw.state_slices
        d = fsw.design
        for block, name, u in ((d.star_tracker, "star_tracker", phi0), (d.gyro, "gyro", w0_B)):
            state[s[name]] = np.linalg.solve(np.eye(block.nstates) - block.A, block.B @ u)
        return context, values, schedule

    # -- run ------------------------------------------------------------------------------------
    def run(
        self,
        values: Mapping[str, float] | None = None,
        seed: int = 0,
        start: float = 0.0,
        end: float | None = None,
        *,
        log: bool = True,
        noise_table: np.ndarray | None = None,
        on_start: Callable[[object], None] | None = None,
        within_ranges: bool = True,
        perturbation_frequency_hz: float = math.nan,
        bushings: Mapping[str, tuple[float, float, float, float]] | None = None,
    ) -> MissionResult:
        """Simulate ``[start, end]`` of the mission (default: all of it).

        ``values`` are physical parameter values (missing ones nominal), ``seed`` seeds the
        sensor noise and disturbance (unless ``noise_seed`` is dispersed), ``noise_table``
        replaces them by a given ``(n, 9)`` unit table (see :meth:`initial_context`).
        ``perturbation_frequency_hz`` [Hz] is where the all-pass realizing the LTI perturbations
        ``Delta_add``, ``Delta_mul_*`` has its -90 deg phase: the critical frequency of the region
        the run explores (:func:`~oos_drake.multibody.flight_software.allpass_block`; ``inf``:
        static). It is required (not NaN) when one of those scalars is nonzero.
        ``on_start(context)`` is called with the run's root context before the first step; a
        caller that keeps it can read the logs afterwards with :meth:`state_log`, also when the
        run diverged (the replay does this). ``within_ranges=False`` accepts values beyond the
        parameters' ranges (see :meth:`resolve`). ``bushings`` (``{"SM1": (k_shear, k_tors,
        d_shear, d_tors), "SM2": ...}`` [N/m, N m/rad, N s/m, N m s/rad], a missing one open)
        holds the docking connections at those settings for the whole window instead of the
        mission's schedule (a docking phase frozen, as the docking study analyzes it); the
        window must then not contain the capture.

        Raises
        ------
        MissionDiverged
            Hub attitude beyond ``divergence_limit``, non-finite state or integrator failure.
        ValueError
            Unknown parameter, value out of range, or a window outside the mission.
        """
        end = self.duration if end is None else float(end)
        start = float(start)
        if not (0.0 <= start < end <= self.duration + 1e-9):
            raise ValueError(f"mission window [{start}, {end}] s outside [0, {self.duration}] s")
        h, o = self.handles, self.options
        context, values, schedule = self.initial_context(
            values,
            seed,
            start,
            end,
            noise_table,
            perturbation_frequency_hz,
            within_ranges=within_ranges,
            bushings=bushings,
        )
        if bushings is not None and start < self.events["capture"] < end:
            raise ValueError(
                f"mission: a window with frozen bushings must not contain the capture at "
                f"{self.events['capture']} s"
            )
        if on_start is not None:
            on_start(context)
        simulator = Simulator(h.diagram, context)
        ResetIntegratorFromFlags(simulator, o.integrator, o.step)
        integrator = simulator.get_mutable_integrator()
        integrator.set_target_accuracy(o.accuracy)
        integrator.set_fixed_step_mode(o.fixed_step)
        simulator.Initialize()
        fsw = h.flight_software
        fsw_context = fsw.GetMyContextFromRoot(context)
        stops = set(schedule.breakpoints(start, end))
        stops.update(np.arange(start + o.check_interval, end, o.check_interval).tolist())
        if start < self.events["capture"] < end:
            stops.add(self.events["capture"])
        stops = sorted(stops) + [end]
        step, ramp_step = o.step, min(o.step, 1.0 / (o.control_rate * o.ramp_substeps))
        ramps = schedule.ramp_intervals()
        t_wall, t_cpu = _time.perf_counter(), _time.process_time()
        for stop in stops:
            # the stops include the ramp ends, so a segment is inside a ramp or outside all
            now = context.get_time()
            in_ramp = any(a - 1e-9 <= now and stop <= b + 1e-9 for a, b in ramps)
            integrator.set_maximum_step_size(ramp_step if in_ramp else step)
            try:
                simulator.AdvanceTo(stop)
            except RuntimeError as exc:
                raise MissionDiverged(
                    f"integrator failed near t = {context.get_time():.3f} s: "
                    f"{str(exc).splitlines()[0]}"
                ) from exc
            max_phi = fsw.metrics(fsw_context)["max_phi"]
            if not np.all(np.isfinite(max_phi)) or max_phi.max() > o.divergence_limit:
                raise MissionDiverged(
                    f"hub attitude {max_phi.max():.3g} rad beyond the {o.divergence_limit} rad "
                    f"limit by t = {stop:.1f} s"
                )
            if stop == self.events["capture"]:
                self._place_target(context, "arm")
            if stop < end:
                self._set_bushings(context, schedule.settings(stop))
        wall, cpu = _time.perf_counter() - t_wall, _time.process_time() - t_cpu
        metrics_raw = fsw.metrics(fsw_context)
        timeseries = self._timeseries(context, schedule) if log else pd.DataFrame()
        samples = max(metrics_raw["samples"], 1.0)
        metrics = {
            "ape": float(metrics_raw["max_phi"].max()),
            "rms_attitude": float(np.sqrt(metrics_raw["sumsq_phi"].sum() / (3.0 * samples))),
            "peak_torque": float(metrics_raw["max_u"].max()),
            "peak_applied_torque": float(metrics_raw["max_T"].max()),
            "max_force_SM1": float(timeseries["F_SM1 [N]"].max()) if log else math.nan,
            "max_force_SM2": float(timeseries["F_SM2 [N]"].max()) if log else math.nan,
            "max_tracking_error": self._tracking_error(context) if log else math.nan,
        }
        statistics = MappingProxyType(
            {str(k): float(v) for k, v in integrator.GetStatisticsSummary()}
        )
        return MissionResult(
            MappingProxyType(metrics),
            timeseries,
            wall,
            cpu,
            int(integrator.get_num_steps_taken()),
            statistics,
        )

    def state_log(self, context) -> tuple[np.ndarray, np.ndarray]:
        """Logged plant states of the run that owns root ``context``.

        Returns
        -------
        times : ndarray, shape (n,)
            Sample times [s] (every ``1 / log_rate`` s from the window start).
        states : ndarray, shape (nq + nv, n)
            MultibodyPlant state ``[q; v]`` at those times.
        """
        log = self.handles.state_logger.FindLog(context)
        return np.array(log.sample_times()), np.array(log.data())

    def logs(self, context):
        """``(times, states, torques)``: :meth:`state_log` and the flight software's torque log
        (``(12, n)``: ``u``, ``T_rw``, ``T``, ``T_dist`` [N m], 3 axes each)."""
        times, states = self.state_log(context)
        return times, states, self.handles.torque_logger.FindLog(context).data()

    def _tracking_error(self, context) -> float:
        h = self.handles
        times, x, _ = self.logs(context)
        if times.size == 0:
            return math.nan
        q_arm = np.stack([x[j.position_start()] for j in h.arm_joints], axis=1)
        reference = h.timeline.arm(np.clip(times, 0.0, self.duration))
        return float(np.abs(q_arm - reference).max())

    def _timeseries(self, context, schedule: _Schedule) -> pd.DataFrame:
        h = self.handles
        plant = h.plant
        times, x, torques = self.logs(context)
        nq = plant.num_positions()
        qs, vs = h.hub_joint.position_start(), nq + h.hub_joint.velocity_start()
        columns = {"time [s]": times}
        rpy = x[qs : qs + 3]
        w_W = x[vs : vs + 3]
        w_B = np.empty_like(w_W)
        for k in range(times.size):
            R = RollPitchYaw(rpy[:, k]).ToRotationMatrix().matrix()
            w_B[:, k] = R.T @ w_W[:, k]
        for i, a in enumerate(AXES):
            columns[f"phi_{a} [rad]"] = rpy[i]
            columns[f"w_{a} [rad/s]"] = w_B[i]
        for j, prefix in enumerate(LOG_SIGNALS):
            for i, a in enumerate(AXES):
                columns[f"{prefix}_{a} [N m]"] = torques[3 * j + i]
        root = h.diagram.CreateDefaultContext()
        forces = {sm: np.zeros((2, times.size)) for sm in h.bushings}
        pc_root = plant.GetMyMutableContextFromRoot(root)
        for k, t in enumerate(times):
            plant.SetPositionsAndVelocities(pc_root, x[:, k])
            self._set_bushings(root, schedule.settings(float(t)))
            for sm, bushing in h.bushings.items():
                F = bushing.CalcBushingSpatialForceOnFrameC(pc_root)
                forces[sm][0, k] = np.linalg.norm(F.translational())
                forces[sm][1, k] = np.linalg.norm(F.rotational())
        for sm in h.bushings:
            columns[f"F_{sm} [N]"] = forces[sm][0]
            columns[f"M_{sm} [N m]"] = forces[sm][1]
        for array in ARRAYS:
            for i, joint in enumerate(h.mode_joints[array], start=1):
                columns[f"q{i}_{array} [rad]"] = x[joint.position_start()]
        order = ["time [s]"] + [f"{name} [{unit}]" for name, unit in SIGNAL_UNITS.items()]
        return pd.DataFrame(columns)[order]
