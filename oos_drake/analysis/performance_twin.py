r"""Worst-case performance confirmed on the twin (``oos confirm``, its performance table).

For each worst-case gain of the analysis (``performance.parquet``: per channel ``e_p`` / ``e_u``
and uncertainty subset, the row of largest certified lower bound) this module

1. recomputes the worst perturbation at that configuration and frequency (the same skewed-mu
   bisection as :func:`oos_drake.analysis.performance.worst_case_gains`, on one model and one
   frequency) and the **worst input**: the right singular vector ``v`` (unit 2-norm, complex,
   over the nine normalized disturbances ``d = [d_ext; n_sst; n_gyro]``) of the perturbed loop's
   channel at the critical frequency ``omega``;
2. simulates the **linear twin**: the perturbed LFR closed loop (complex blocks realized by
   stable interpolants, :func:`perturbed_loop`)
   driven by ``d(t) = Re(v e^{j omega t})`` in scipy until steady state; the phasor of the
   channel's output fitted over the last periods gives the gain the analysis predicts (its
   lower bound, :func:`linear_twin_gain`);
3. predicts the **sampled-data** gain: the exact zero-order-hold loop with the twin's flight
   software (Tustin filters, ``d`` sampled at the flight-software rate as the twin takes it) at
   ``z = e^{j omega dt}`` (:func:`predicted_gain`);
4. runs the **Drake twin** (the nonlinear mission, arm and arrays frozen at the configuration,
   the real parameters at their worst values, the complex blocks as the flight software's
   dynamic perturbation) with the sampled sinusoid ``d_k = Re(v e^{j omega k dt})`` as the
   per-sample unit disturbance and noise table (the flight software scales it with
   ``W_n,ext``, ``W_n,sst``, ``W_n,gyro`` as it scales the random ones), long enough for the
   slowest closed-loop mode to settle; the phasor of the hub attitude (plus the attitude the
   realized ``Delta_add`` adds to the measurement) over the last periods, divided by the
   requirement, is the twin's gain. The table also gives the twin's peak requirement ratio
   ``max_t max_axis |phi| / APE requirement`` over the same periods (the campaign's metric for
   that input).

The row also stores the worst case itself, for the falsification that starts from it
(``oos campaign falsify --confirm``): ``worst perturbation`` (JSON: block -> normalized value,
complex values as ``[re, im]`` pairs), ``worst input`` (JSON: the nine ``[re, im]`` entries of
``v`` in the flight software's noise-table order ``[n_sst; n_gyro; d_ext]``) and
``worst values`` (JSON: the Drake mission's campaign parameters that realize the worst case,
:func:`mission_values`).

A gain ``> 1`` is a requirement violation: a unit disturbance (2-norm over the channels) makes
the pointing error (2-norm over the axes) exceed the APE requirement.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.signal

from oos_drake.campaign.performance import PERFORMANCE_CONFIRMATION_FILE

__all__ = [
    "GainCase",
    "PERFORMANCE_CONFIRMATION_FILE",
    "confirm_gain_case",
    "confirm_performance",
    "linear_twin_gain",
    "read_gain_cases",
    "mission_values",
    "perturbed_loop",
    "phasor",
    "axis_direction",
    "predicted_gain",
    "predicted_response",
    "sampled_response",
    "twin_gain",
    "worst_gain_cases",
]

#: Periods of the critical oscillation the phasors are fitted over [-].
FIT_PERIODS = 4
#: Longest settling time simulated before the fit [s].
MAX_SETTLE = 500.0
#: Settling time in time constants of the slowest closed-loop mode [-].
SETTLE_TIME_CONSTANTS = 7.0
#: Columns of ``performance.parquet`` that :func:`worst_gain_cases` reads.
GAIN_CASE_COLUMNS = (
    "channel",
    "subset",
    "time [s]",
    "frequency [Hz]",
    "gain nominal [-]",
    "gain lower [-]",
    "gain upper [-]",
)


#: Rows of the table (and the printed summary).
PERFORMANCE_CONFIRMATION_COLUMNS = [
    *GAIN_CASE_COLUMNS,
    "gain of the perturbation [-]",
    "gain linear twin [-]",
    "gain linear sampled [-]",
    "gain twin [-]",
    "peak ratio twin [-]",
    "settle [s]",
    "simulated [s]",
    "status",
    "worst perturbation",
    "worst input",
    "worst values",
    "gain largest axis sampled [-]",
    "worst values, largest axis",
]
#: Columns of each worst-case gain's record in the confirmation summary (:func:`summary_line`).
PERFORMANCE_SUMMARY_COLUMNS = (
    "channel",
    "subset",
    "time [s]",
    "frequency [Hz]",
    "gain lower [-]",
    "gain upper [-]",
    "gain linear twin [-]",
    "gain linear sampled [-]",
    "gain twin [-]",
    "peak ratio twin [-]",
    "status",
)
#: LFR disturbance order ``[d_ext; n_sst; n_gyro]`` -> the flight software's noise-table column.
_TABLE_COLUMNS = np.r_[6:9, 0:6]


@dataclass(frozen=True)
class GainCase:
    """One worst-case gain of the analysis (a row of ``performance.parquet``).

    Attributes
    ----------
    channel, subset : str
        ``"e_p"`` / ``"e_u"`` and the uncertainty subset.
    time : float
        Mission time of the configuration [s].
    omega : float
        Critical frequency [rad/s].
    nominal, lower, upper : float
        Nominal gain and the bounds of the worst-case gain there [-].
    """

    channel: str
    subset: str
    time: float
    omega: float
    nominal: float
    lower: float
    upper: float


def worst_gain_cases(table: pd.DataFrame, channels=("e_p", "e_u")) -> list[GainCase]:
    """Per ``(channel, subset)`` the row of largest finite lower bound of ``performance.parquet``
    (an infinite one is a loop the perturbation destabilizes: a stability case, confirmed by
    the stability confirmation)."""
    cases = []
    for (channel, subset), rows in table.groupby(["channel", "subset"], sort=False):
        if channel not in channels:
            continue
        finite = rows[np.isfinite(rows["gain lower [-]"])]
        if finite.empty:
            continue
        r = finite.loc[finite["gain lower [-]"].idxmax()]
        cases.append(
            GainCase(
                str(channel),
                str(subset),
                float(r["time [s]"]),
                2 * np.pi * float(r["frequency [Hz]"]),
                float(r["gain nominal [-]"]),
                float(r["gain lower [-]"]),
                float(r["gain upper [-]"]),
            )
        )
    return cases


# -- the worst perturbation and input ----------------------------------------------------------
def worst_perturbation(closed, case: GainCase, blocks) -> tuple[dict, float]:
    """Normalized worst perturbation of ``case`` on one closed loop ``d -> e`` (``blocks``: the
    subset's block names) and the gain it reaches [-] (the skewed-mu lower bound)."""
    from oos_drake.analysis.performance import CHANNELS, _channel_task, channel_matrices
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.lfr_analysis import block_map, normalized_worst_case

    sub, _, _ = block_map(closed).subset(list(blocks))
    (A, B, C, D, nz, nw, blk) = channel_matrices(closed, [0], CHANNELS[case.channel], blocks)
    lo, _, _, delta = _channel_task((A, B, C, D, nz, nw, blk, np.array([case.omega]), 0.02, 40))
    return normalized_worst_case(sub, parse_blk(sub.blk), delta[0, 0]), float(lo[0, 0])


def channel_direction(loop, rows, omega: float) -> tuple[float, np.ndarray]:
    """Largest singular value of the certain loop's ``rows`` at ``omega`` and its right singular
    vector (the worst input direction, unit 2-norm, phase of its largest entry zero)."""
    n = loop.nstates
    M = np.real(np.asarray(loop.M))
    A, B, C, D = M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]
    G = C[list(rows)] @ np.linalg.solve(1j * omega * np.eye(n) - A, B) + D[list(rows)]
    _, s, Vh = np.linalg.svd(G)
    v = Vh[0].conj()
    v = v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))
    return float(s[0]), v


def perturbed_loop(sys, normalized: dict, omega: float):
    """Certain loop ``F_u(M, Delta)`` with the normalized block values ``normalized`` (complex
    blocks realized by their stable interpolants at ``omega``,
    :func:`oos_drake.analysis.confirm.substitution`; blocks not given nominal). The one way the
    analysis closes a loop on a worst perturbation (the time check and the performance
    confirmation); an unknown block name is a ``ValueError``."""
    from oos_drake.analysis.confirm import Peak, substitution
    from oos_drake.lfr import usubs

    unknown = sorted(set(normalized) - set(sys.uncertainty))
    if unknown:
        raise ValueError(f"perturbed_loop: unknown block(s) {unknown}")
    kinds = {name: spec.kind for name, spec in sys.uncertainty.items()}
    normalized = {k: float(np.real(v)) if kinds[k] == "ureal" else v for k, v in normalized.items()}
    peak = Peak("", "", math.nan, math.nan, omega, 1.0, 1.0, normalized)
    return usubs(sys, substitution(peak, sys.uncertainty, 1.0), normalized=True)


def phasor(t, y, omega: float, *, trend: bool = False) -> np.ndarray:
    """Complex amplitudes ``Y`` of ``y(t) ~ c + Re(Y e^{j omega t})`` (least squares, per column);
    ``trend``: of ``y(t) ~ c + r t + Re(Y e^{j omega t})`` (a drift fitted and left out).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times [s] (a whole number of periods is best).
    y : array_like, shape (n,) or (n, m)
    omega : float
        Frequency [rad/s].
    trend : bool
        Fit a linear drift too.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    columns = [np.ones_like(t), np.cos(omega * t), -np.sin(omega * t)]
    if trend:
        columns.append(t - t.mean())
    coef, *_ = np.linalg.lstsq(np.column_stack(columns), y, rcond=None)
    return coef[1] + 1j * coef[2]


def settle_time(loop, omega: float) -> float:
    """Simulated time before the fit [s]: :data:`SETTLE_TIME_CONSTANTS` time constants of the
    slowest decaying mode of ``loop`` (modes slower than 1e-4 1/s are the structurally marginal
    rigid-body ones the channel does not see), at least two periods, at most
    :data:`MAX_SETTLE`."""
    n = loop.nstates
    rates = -np.linalg.eigvals(np.real(np.asarray(loop.M))[:n, :n]).real if n else np.array([])
    rates = rates[rates > 1e-4]
    slowest = SETTLE_TIME_CONSTANTS / rates.min() if rates.size else 0.0
    return float(min(max(slowest, 2 * 2 * np.pi / omega), MAX_SETTLE))


def linear_twin_gain(
    loop, v, omega: float, rows, *, settle: float | None = None, steps_per_period: int = 400
) -> float:
    """Gain of the linear twin: ``loop`` (a certain LFR ``d -> e``) simulated in scipy.

    The input ``d(t) = Re(v e^{j omega t})`` (piecewise linear between ``steps_per_period``
    points per period, :func:`scipy.signal.lsim`) runs for ``settle`` [s] (default
    :func:`settle_time`) and :data:`FIT_PERIODS` periods; the gain is the 2-norm of the phasor
    of ``e[rows]`` over those periods divided by ``||v||``.
    """
    v = np.asarray(v, dtype=complex)
    period = 2 * np.pi / omega
    settle = settle_time(loop, omega) if settle is None else settle
    n_settle = math.ceil(settle / period)
    dt = period / steps_per_period
    t = np.arange(0, (n_settle + FIT_PERIODS) * steps_per_period + 1) * dt
    d = np.real(np.outer(np.exp(1j * omega * t), v))
    n = loop.nstates
    M = np.real(np.asarray(loop.M))
    A, B, C, D = M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]
    rows = list(rows)
    _, e, _ = scipy.signal.lsim((A, B, C[rows], D[rows]), d, t)
    fit = t >= n_settle * period - 1e-9
    return float(np.linalg.norm(phasor(t[fit], e[fit], omega)) / np.linalg.norm(v))


# -- the sampled-data loop of the twin ---------------------------------------------------------
def _loop_step(plant_d, software, dynamic):
    """The sampled loop as one linear map ``(X, d) -> (X+, [phi; u])`` (matrices), ``X =
    [x_plant; x1; x2; xp]``, ``d`` the unit noise table row ``[n_sst; n_gyro; d_ext]``."""
    Ad, Bd, Cg = plant_d
    n1, n2 = software._n1, software._n2
    M1 = software._M1
    M2 = software._output_stage(np.concatenate([[0.0], np.zeros(9), [math.nan]]))
    np_ = dynamic.A.shape[0] if dynamic is not None else 0
    ng = Ad.shape[0]
    nx = ng + n1 + n2 + np_

    def step(X, d):
        xg, x1, x2 = X[:ng], X[ng : ng + n1], X[ng + n1 : ng + n1 + n2]
        xp = X[ng + n1 + n2 :]
        measured = Cg @ xg
        if np_:
            measured = measured + dynamic.C[3:] @ xp
        out1 = M1 @ np.concatenate([x1, measured, d[0:6]])
        out2 = M2 @ np.concatenate([x2, out1[n1:], d[6:9]])
        T_in, T = out2[n2 : n2 + 3] + out2[n2 + 3 : n2 + 6], out2[n2 + 12 :]  # T_rw + T_dist
        if np_:
            T = T + dynamic.C[:3] @ xp + dynamic.D[:3] @ T_in
            xp = dynamic.A @ xp + dynamic.B @ T_in
        X1 = np.concatenate([Ad @ xg + Bd @ T, out1[:n1], out2[:n2], xp])
        return X1, np.concatenate([(Cg @ xg)[:3], out1[n1:]])

    cols = [step(e, np.zeros(9)) for e in np.eye(nx)]
    A = np.column_stack([c[0] for c in cols])
    C = np.column_stack([c[1] for c in cols])
    ins = [step(np.zeros(nx), e) for e in np.eye(9)]
    B = np.column_stack([c[0] for c in ins])
    D = np.column_stack([c[1] for c in ins])
    return A, B, C, D


def sampled_response(plant_hat, values, software, dynamic, omega: float, requirement_rows):
    """The sampled-data loop's response ``H(e^{j omega dt})`` from the nine unit inputs (LFR
    order) to the channel's rows, scaled (``rows x 9``, complex).

    ``plant_hat``: the uncertain plant ``T -> wdot`` with ``values`` (normalized, complex blocks
    as interpolants) substituted, discretized with a zero-order hold at the flight software's
    period; ``dynamic``: the flight software's realization of ``Delta_mul`` (None without);
    ``requirement_rows``: ``(rows of [phi; u], scale)`` of the channel (``e_p``: phi over
    the APE requirement; ``e_u``: the command, see :func:`_channel_output`).
    """
    from oos_drake.control.sampled import plant_with_integrators
    from oos_drake.lfr import usubs

    period = software.design.period
    P = usubs(plant_hat, values, normalized=True).to_ss()
    Ag, Bg, Cg = plant_with_integrators(P)
    Ad, Bd, *_ = scipy.signal.cont2discrete((Ag, Bg, Cg, np.zeros((6, 3))), period, method="zoh")
    A, B, C, D = _loop_step((Ad, Bd, Cg), software, dynamic)
    z = np.exp(1j * omega * period)
    rows, scale = requirement_rows
    H = C[rows] @ np.linalg.solve(z * np.eye(A.shape[0]) - A, B) + D[rows]
    return H[:, _TABLE_COLUMNS] * scale  # columns in the LFR order


def predicted_gain(plant_hat, worst, design, v, out) -> float:
    """The sampled-data prediction of a worst case for the input ``v``: ``||H v|| / ||v||``
    with ``H`` of :func:`predicted_response`."""
    return _gain(predicted_response(plant_hat, worst, design, out), v)


def _gain(H, v) -> float:
    """``||H v|| / ||v||`` [-] (``v`` complex)."""
    v = np.asarray(v, dtype=complex)
    return float(np.linalg.norm(H @ v) / np.linalg.norm(v))


def predicted_response(plant_hat, worst, design, out) -> np.ndarray:
    """The sampled-data response of a worst case (:func:`sampled_response`): ``Delta_add`` and
    the real blocks in the plant ``plant_hat`` (the analysis' uncertain plant), ``Delta_mul`` in
    the flight software (:func:`~oos_drake.multibody.flight_software.perturbation_block`).

    Parameters
    ----------
    plant_hat : LFR
        The analysis' uncertain plant ``T -> wdot`` at the configuration.
    worst : Peak
        The worst perturbation (normalized) and its frequency ``omega`` [rad/s].
    design : FlightSoftwareDesign
    out : (list, float)
        Rows of ``[phi; u]`` and scale of the channel (:func:`_channel_output`).
    """
    from oos_drake.analysis.confirm import complex_values, substitution
    from oos_drake.control.analysis_model import MULTIPLICATIVE_BLOCKS
    from oos_drake.multibody.flight_software import FlightSoftware, perturbation_block

    mul = complex_values(worst).get("delta_mul")
    mul_block = None if mul is None else perturbation_block(design, worst.omega, delta_mul=mul)
    values = substitution(worst, plant_hat.uncertainty, 1.0)
    if mul_block is not None:
        for name in MULTIPLICATIVE_BLOCKS:
            values[name] = np.zeros((1, 1))
    software = FlightSoftware(design, 6, 6, 0, 0)
    return sampled_response(plant_hat, values, software, mul_block, worst.omega, out)


def axis_direction(H) -> tuple[float, np.ndarray]:
    """The input direction (unit 2-norm, LFR order) that maximizes the largest single row of
    ``H`` (one axis: what a peak requirement on each axis sees) and that row's gain."""
    H = np.asarray(H, dtype=complex)
    norms = np.linalg.norm(H, axis=1)
    row = H[int(np.argmax(norms))]
    return float(norms.max()), np.conj(row) / np.linalg.norm(row)


def _channel_output(channel: str, spec) -> tuple[list, float]:
    """Rows of ``[phi; u]`` of the sampled loop and the scale giving the channel [-]: ``e_p =
    phi / W_p``; ``e_u = W_u u`` (``u`` the torque command at the sample)."""
    if channel == "e_p":
        return [0, 1, 2], 1.0 / spec.pointing_requirement
    return [3, 4, 5], spec.control_weight


# -- the worst case as data ---------------------------------------------------------------------
def _pairs(value):
    """``[re, im]`` pairs of a complex scalar or array (nested lists, JSON-ready)."""
    a = np.asarray(value, dtype=complex)
    return np.stack([a.real, a.imag], axis=-1).tolist()


def mission_values(normalized: dict, specs, v, omega: float) -> dict:
    """The Drake mission's campaign parameters that realize a worst case (the falsification's
    starting point).

    - real blocks: their physical values (:func:`oos_drake.analysis.worst_cases.physical_values`
      at scale 1, clipped to the ranges);
    - complex blocks (``Delta_add``, ``Delta_mul_*``): the mission realizes each as a signed
      scalar ``s`` times an all-pass whose value at the run's frequency is ``-j``; the seed is
      ``s`` of the block's size (2-norm, at most 1) and of the sign of ``Re(j c)`` (for a 3x3
      block ``c``: its trace), the nearest realizable value of that size (the block's phase is
      otherwise lost: the search explores the rest);
    - the input: ``sine_amplitude = 1``, ``sine_frequency = omega / 2 pi``, ``sine_re_*``,
      ``sine_im_*`` the direction ``v`` (table order), ``noise_scale = 0`` (the analysis' unit
      input alone).

    Parameters
    ----------
    normalized : dict
        Block -> normalized worst value (complex blocks complex).
    specs : dict
        The loop's block specs (``sys.uncertainty``).
    v : array_like, shape (9,)
        Worst input direction in the LFR order ``[d_ext; n_sst; n_gyro]`` (complex).
    omega : float
        Critical frequency [rad/s].
    """
    from types import SimpleNamespace

    from oos_drake.analysis.worst_cases import physical_values
    from oos_drake.multibody.mission_sim import SINE_CHANNELS

    real = {k: x for k, x in normalized.items() if specs[k].kind == "ureal"}
    out = physical_values(SimpleNamespace(uncertainty=specs), real, 1.0) if real else {}
    for name, value in normalized.items():
        if name in real:
            continue
        c = np.atleast_2d(np.asarray(value, dtype=complex))
        size = min(float(np.linalg.norm(c, ord=2)), 1.0)
        sign = 1.0 if np.real(1j * np.trace(c)) >= 0 else -1.0
        out[name] = sign * size
    table = np.zeros(9, dtype=complex)
    table[_TABLE_COLUMNS] = np.asarray(v, dtype=complex)
    table = table / np.linalg.norm(table)
    out |= {"noise_scale": 0.0, "sine_amplitude": 1.0, "sine_frequency": omega / (2 * np.pi)}
    for channel, entry in zip(SINE_CHANNELS, table, strict=True):
        out[f"sine_re_{channel}"] = float(entry.real)
        out[f"sine_im_{channel}"] = float(entry.imag)
    return {k: float(x) for k, x in out.items()}


def worst_case_columns(normalized: dict, specs, v, omega: float) -> dict:
    """The row's ``worst perturbation``, ``worst input`` and ``worst values`` (JSON texts,
    module docstring)."""
    import json

    table = np.zeros(9, dtype=complex)
    table[_TABLE_COLUMNS] = np.asarray(v, dtype=complex)
    return {
        "worst perturbation": json.dumps({k: _pairs(x) for k, x in normalized.items()}),
        "worst input": json.dumps(_pairs(table)),
        "worst values": json.dumps(mission_values(normalized, specs, v, omega)),
    }


# -- one case ------------------------------------------------------------------------------------
def confirm_gain_case(case: GainCase, controller, scenario, subsets, options=None):
    """Linear, sampled-data and Drake-twin gains of one worst case (a table row).

    Parameters
    ----------
    case : GainCase
    controller : Controller
    scenario : Scenario
    subsets : dict
        Subset name -> block names (those of the analysis).
    options : ConfirmOptions, optional
        ``max_step`` of the twin's integrator.

    Returns
    -------
    dict
        A row of :data:`PERFORMANCE_CONFIRMATION_COLUMNS`.
    """
    from oos_drake.analysis.confirm import (
        ConfirmOptions,
        Peak,
        _peak_models,
        complex_values,
    )
    from oos_drake.analysis.performance import CHANNELS
    from oos_drake.control.components import DesignSpecification
    from oos_drake.multibody.flight_software import (
        FlightSoftwareDesign,
        perturbation_block,
    )

    options = options or ConfirmOptions()
    peak = Peak("mission", case.subset, case.time, math.nan, case.omega, 1.0, 1.0)
    closed, plant_hat = _peak_models(peak, controller, scenario)
    normalized, gain_found = worst_perturbation(closed, case, subsets[case.subset])
    rows = CHANNELS[case.channel]
    loop = perturbed_loop(closed, normalized, case.omega)
    gain_p, v = channel_direction(loop, rows, case.omega)
    settle = settle_time(loop, case.omega)
    row = {
        "channel": case.channel,
        "subset": case.subset,
        "time [s]": case.time,
        "frequency [Hz]": case.omega / (2 * np.pi),
        "gain nominal [-]": case.nominal,
        "gain lower [-]": case.lower,
        "gain upper [-]": case.upper,
        "gain of the perturbation [-]": gain_p,
        "gain linear twin [-]": linear_twin_gain(loop, v, case.omega, rows, settle=settle),
        "gain linear sampled [-]": math.nan,
        "gain largest axis sampled [-]": math.nan,
        "worst values, largest axis": None,
        "gain twin [-]": math.nan,
        "peak ratio twin [-]": math.nan,
        "settle [s]": settle,
        "simulated [s]": math.nan,
        "status": "",
    } | worst_case_columns(normalized, closed.uncertainty, v, case.omega)
    spec = DesignSpecification.from_requirements(scenario.control)
    design = FlightSoftwareDesign.create(
        controller.K,
        scenario.control.flight_software_rate_hz,
        spec=spec,
        torque_limit=scenario.control.torque_limit,
    )
    if case.omega * design.period >= np.pi:
        row["status"] = "linear only: critical frequency beyond the flight software's Nyquist"
        return row
    worst = Peak("mission", case.subset, case.time, math.nan, case.omega, 1.0, 1.0, normalized)
    blocks = complex_values(worst)
    dynamic = perturbation_block(design, case.omega, **blocks) if blocks else None
    out_rows = _channel_output(case.channel, spec)
    H = predicted_response(plant_hat, worst, design, out_rows)
    row["gain linear sampled [-]"] = _gain(H, v)
    # the same perturbation, the input that is worst for one axis (a peak metric's worst case)
    row["gain largest axis sampled [-]"], axis_v = axis_direction(H)
    row["worst values, largest axis"] = json.dumps(
        mission_values(normalized, closed.uncertainty, axis_v, case.omega)
    )
    twin = _drake_twin_gain(
        worst,
        controller,
        scenario,
        options,
        design,
        dynamic,
        v,
        settle,
        closed.uncertainty,
        out_rows,
    )
    row.update(twin)
    g = row["gain twin [-]"]
    verdict = "violated" if g > 1 else "met"
    row["status"] = (
        f"twin {verdict} ({g:.3g}); sampled-data prediction {row['gain linear sampled [-]']:.3g}"
        + row["status"]
        if np.isfinite(g)
        else row["status"] or "twin run failed"
    )
    return row


def _drake_twin_gain(worst, controller, scenario, options, design, dynamic, v, settle, specs, out):
    """The Drake twin's gain and peak ratio for the sinusoidal worst input (a partial row).

    ``out``: ``(rows of [phi; u], scale)`` of the channel (:func:`_channel_output`).
    """
    import dataclasses

    from oos_drake.analysis.confirm import _Twin
    from oos_drake.multibody.mission_sim import MissionDiverged

    omega = worst.omega
    period = design.period
    cycle = 2 * np.pi / omega
    n_settle = math.ceil(settle / cycle)
    note = ""
    while True:
        duration = (n_settle + FIT_PERIODS) * cycle
        twin_options = dataclasses.replace(
            options, duration=duration, settle=n_settle * cycle, initial_attitude=1e-12
        )
        try:
            twin = _Twin(worst, controller.K, twin_options, scenario, math.nan, specs, design)
            break
        except ValueError as exc:  # no window without a docking event that long: shorten
            if n_settle <= 2:
                return {"status": f"no twin run: {exc}", "simulated [s]": duration}
            n_settle = max(2, (2 * n_settle) // 3)
            note = f"; settle shortened to {n_settle * cycle:.0f} s (mission events)"
    k = np.arange(int(math.ceil(duration / period)) + 2)
    table = np.zeros((k.size, 9))
    table[:, _TABLE_COLUMNS] = np.real(np.outer(np.exp(1j * omega * k * period), v))
    try:
        times, phi, T_rw, u = twin.forced_run(1.0, table)
    except MissionDiverged as exc:
        return {"status": f"twin diverged: {exc}", "simulated [s]": duration}
    return twin_gain(times, phi, T_rw, u, v, omega, design, dynamic, out, n_settle * cycle) | {
        "settle [s]": n_settle * cycle,
        "simulated [s]": duration,
        "status": note,
    }


def twin_gain(times, phi, T_rw, u, v, omega, design, dynamic, out, settle) -> dict:
    """The twin's gain and peak ratio from a forced run's logs (a partial row).

    Parameters
    ----------
    times : ndarray, shape (n,)
        Log times since the run's start [s] (at flight-software samples).
    phi, T_rw, u : ndarray, shape (n, 3)
        Hub roll-pitch-yaw attitude [rad], wheel torque and torque command [N m].
    v : array_like, shape (9,)
        The input direction (LFR order ``[d_ext; n_sst; n_gyro]``, complex).
    omega : float
        Input frequency [rad/s].
    design : FlightSoftwareDesign
        The run's flight software (its period and disturbance filter).
    dynamic : DiscreteBlock or None
        The run's dynamic perturbation (:func:`~oos_drake.multibody.flight_software.
        perturbation_block`); its ``Delta_add`` attitude is added to the hub's (it is part of
        what the analysis' plant ``P_hat`` calls the attitude).
    out : (list, float)
        Rows of ``[phi; u]`` and the scale of the channel (:func:`_channel_output`).
    settle : float
        Logs before this time [s] are the transient (not fitted).

    Returns
    -------
    dict
        ``gain twin [-]`` (phasor 2-norm over the channel's rows, scaled, over ``||v||``) and
        ``peak ratio twin [-]`` (largest centred ``|phi|`` / ``|u|`` after ``settle``, scaled;
        with ``dynamic``, ``phi`` is the hub's without its drift plus the realized
        ``Delta_add``'s steady oscillation: the analysis' attitude).
    """
    fit = (times >= settle - 1e-9) & np.all(np.isfinite(phi), axis=1)
    t = times[fit]
    attitude = phi[fit]
    if dynamic is None:
        Phi = phasor(t, attitude, omega)
    else:
        # The realization's Delta_add attitude is added to the measurement only: its double
        # integrator is unobservable, so the hub drifts by its ramp (the measured sum is
        # regulated): the hub's drift is fitted and left out.
        Phi = phasor(t, attitude, omega, trend=True)
        # Its input is the plant-input torque T_rw + T_dist: the wheel torque from the log
        # (which at t_k holds the update of t_k - dt: Drake publishes before the discrete
        # update of the same time, hence the factor z), the external disturbance from the
        # flight software's filter on the input's d_ext entries.
        z = np.exp(1j * omega * design.period)
        T_in = (
            z * phasor(t, T_rw[fit], omega)
            + _response(design.disturbance, z) @ (np.asarray(v, dtype=complex)[0:3])
        )
        added = _response(dynamic, z, rows=slice(3, 6)) @ T_in
        # the analysis' attitude over the fit, for the peak ratio: the hub's without its drift
        # plus the realized Delta_add's steady oscillation
        oscillation = np.real(np.outer(np.exp(1j * omega * t), Phi))
        drift = np.polynomial.polynomial.polyfit(t - t.mean(), attitude - oscillation, 1)
        attitude = attitude - np.polynomial.polynomial.polyval(t - t.mean(), drift).T
        attitude = attitude + np.real(np.outer(np.exp(1j * omega * t), added))
        Phi = Phi + added
    rows, scale = out
    U = phasor(t, u[fit], omega)
    gain = np.linalg.norm(np.concatenate([Phi, U])[rows]) * scale
    signal = np.concatenate([attitude, u[fit]], axis=1)[:, rows]
    centred = signal - signal.mean(axis=0)
    return {
        "gain twin [-]": float(gain / np.linalg.norm(v)),
        "peak ratio twin [-]": float(np.abs(centred).max() * scale),
    }


def _response(block, z: complex, rows=slice(None)) -> np.ndarray:
    """Frequency response ``C (z I - A)^-1 B + D`` of a discrete block's ``rows`` at ``z``."""
    n = block.A.shape[0]
    C, D = block.C[rows], block.D[rows]
    if n == 0:
        return D.astype(complex)
    return C @ np.linalg.solve(z * np.eye(n) - block.A, block.B) + D


def _gain_task(args):
    from oos_drake.blas import single_threaded_blas

    with single_threaded_blas():  # restored after: ``--workers 1`` runs it in this process
        return confirm_gain_case(*args)


def read_gain_cases(analysis) -> list[GainCase]:
    """The worst-case gains of an ``oos analyze`` folder (:func:`worst_gain_cases` of its
    ``performance.parquet``; none without one)."""
    from pathlib import Path

    from oos_drake.campaign.store import read_table

    path = Path(analysis) / "performance.parquet"
    if not path.is_file():
        return []
    # a folder written before the ``name [unit]`` convention has its columns renamed on read
    return worst_gain_cases(read_table(path, GAIN_CASE_COLUMNS, str(path), legacy=True))


def confirm_performance(cases, controller, scenario, options=None, *, workers=1, scheduler=None):
    """:func:`confirm_gain_case` for every worst-case gain ``cases`` (:func:`read_gain_cases`),
    on ``workers`` processes (``scheduler``: :func:`oos_drake.processes.make_executor`; spawned
    workers, as :func:`oos_drake.analysis.confirm.confirm_peaks`).

    Returns
    -------
    pandas.DataFrame
        ``performance_confirmation.parquet`` (:data:`PERFORMANCE_CONFIRMATION_COLUMNS`; empty
        without cases).
    """
    from oos_drake.analysis.confirm import Peak, _peak_models
    from oos_drake.analysis.subsets import uncertainty_subsets
    from oos_drake.processes import make_executor

    if not cases:
        return pd.DataFrame(columns=PERFORMANCE_CONFIRMATION_COLUMNS)
    first = Peak("mission", "", cases[0].time, math.nan, cases[0].omega, 1.0, 1.0)
    closed, _ = _peak_models(first, controller, scenario)
    subsets = uncertainty_subsets(closed.uncertainty)
    tasks = [(case, controller, scenario, subsets, options) for case in cases]
    with make_executor(max(1, min(workers, len(tasks))), scheduler, method="spawn") as executor:
        futures = [executor.submit(_gain_task, task) for task in tasks]
        rows = [future.result() for future in futures]
    return pd.DataFrame(rows, columns=PERFORMANCE_CONFIRMATION_COLUMNS)


def summary_line(row) -> str:
    """One printed line of a row."""
    return (
        f"{row['channel']:>4s} {row['subset']:>14s} t={row['time [s]']:7.1f} s "
        f"f={row['frequency [Hz]']:8.4g} Hz  lower {row['gain lower [-]']:6.3f}  upper "
        f"{row['gain upper [-]']:6.3f}  linear twin {row['gain linear twin [-]']:6.3f}  sampled "
        f"{row['gain linear sampled [-]']:6.3f}  twin {row['gain twin [-]']:6.3f}  (peak ratio "
        f"{row['peak ratio twin [-]']:.3f})  {row['status']}"
    )
