"""Plant model arrays for the synthesis: configurations times real uncertain parameters.

The synthesis needs, for any configuration index ``i`` (a mission waypoint) and any value of the
real uncertain parameters ``delta`` (physical values inside their ranges), the 3x3 rotational
plant ``T_ext,G1 -> wdot`` as state-space matrices. :class:`PlantArray` provides that through
one vectorized callable, whatever the source (LFR substitution, Drake linearization, or the
synthetic flexible spacecraft of :func:`synthetic_flexible_plants` used in tests).

A :class:`PlantArray` is built here and does not leave the synthesis' callers: other packages
hand this module LFRs (:func:`from_lfr`: an uncertain LFR and its schedule;
:func:`lfr_source_plants`: certain LFRs per configuration and a callable returning a
configuration's uncertain LFR, the Drake twin's form), and the application names a source
(:func:`make_plants`: ``"lfr"``, ``"drake"``, ``"synthetic"``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from oos_drake.control.analysis_model import rotational_channels
from oos_drake.control.interconnection import plant_statespace
from oos_drake.control.statespace import BatchedStateSpace
from oos_drake.lfr import LFR, usubs
from oos_drake.titop.spatial import rotation_matrix


@dataclass(frozen=True)
class UncertainParameter:
    """A real uncertain parameter of the plant (physical units of the model).

    Attributes
    ----------
    name : str
        Block name (becomes a column name in tables).
    nominal, lower, upper : float
        Nominal value and range (``lower <= nominal <= upper``).
    """

    name: str
    nominal: float
    lower: float
    upper: float

    def __post_init__(self):
        if not self.lower <= self.nominal <= self.upper:
            raise ValueError(
                f"uncertain parameter {self.name!r}: nominal {self.nominal} outside "
                f"[{self.lower}, {self.upper}]"
            )


@dataclass(frozen=True)
class PlantArray:
    """Configurations x real uncertainty -> batched plants ``T -> wdot``.

    Parameters
    ----------
    configurations : pandas.DataFrame
        One row per configuration (e.g. column ``time [s]``); row ``i`` is configuration ``i``.
    parameters : tuple of UncertainParameter
        The real uncertain parameters (may be empty).
    build : callable
        ``build(config_index (K,), values (K, P)) -> (A, B, C, D)`` with leading dimension K
        (physical parameter values, columns in ``parameters`` order).
    source : str
        Where the models come from (``"synthetic"``, ``"lfr"``, ``"drake"``).
    statistics : callable, optional
        ``statistics() -> dict``: what building the models has cost so far (e.g. the Drake
        source's linearizations and LFR extractions, with their times [s]).
    """

    configurations: pd.DataFrame
    parameters: tuple[UncertainParameter, ...]
    build: Callable
    source: str = "unknown"
    statistics: Callable | None = None

    @property
    def size(self) -> int:
        """Number of configurations."""
        return len(self.configurations)

    @property
    def nominal_values(self) -> np.ndarray:
        """Nominal parameter values, shape (P,)."""
        return np.array([p.nominal for p in self.parameters], dtype=float)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper parameter bounds, shapes (P,)."""
        return (
            np.array([p.lower for p in self.parameters], dtype=float),
            np.array([p.upper for p in self.parameters], dtype=float),
        )

    def evaluate(self, config_index, values=None) -> BatchedStateSpace:
        """Return the plants at configurations ``config_index`` and parameters ``values``.

        Parameters
        ----------
        config_index : array_like of int, shape (K,)
        values : array_like, shape (K, P), optional
            Physical parameter values (nominal when omitted).
        """
        index = np.atleast_1d(np.asarray(config_index, dtype=int))
        if index.size and (index.min() < 0 or index.max() >= self.size):
            raise ValueError(f"configuration index out of range 0..{self.size - 1}: {index}")
        P = len(self.parameters)
        if values is None:
            values = np.broadcast_to(self.nominal_values, (index.size, P))
        values = np.asarray(values, dtype=float).reshape(index.size, P)
        lower, upper = self.bounds
        tol = 1e-9 * np.maximum(1.0, np.abs(upper - lower))
        if np.any(values < lower - tol) or np.any(values > upper + tol):
            bad = int(np.argmax(np.any((values < lower - tol) | (values > upper + tol), axis=0)))
            raise ValueError(
                f"value of uncertain parameter {self.parameters[bad].name!r} out of range"
            )
        return plant_statespace(*self.build(index, values))

    def subset(self, config_index) -> PlantArray:
        """The array of the configurations ``config_index`` only (renumbered from 0)."""
        index = np.atleast_1d(np.asarray(config_index, dtype=int))
        if index.size and (index.min() < 0 or index.max() >= self.size):
            raise ValueError(f"configuration index out of range 0..{self.size - 1}: {index}")
        build = self.build
        return replace(
            self,
            configurations=self.configurations.iloc[index].reset_index(drop=True),
            build=lambda i, values: build(index[np.asarray(i, dtype=int)], values),
        )

    def nominal(self) -> BatchedStateSpace:
        """All configurations at nominal parameters."""
        return self.evaluate(np.arange(self.size))

    def fingerprint(self) -> str:
        """SHA-256 of the nominal model data and the parameter ranges (identifies the models)."""
        sys = self.nominal()
        digest = hashlib.sha256()
        for M in (sys.A, sys.B, sys.C, sys.D):
            digest.update(np.ascontiguousarray(np.round(M, 12)).tobytes())
        for p in self.parameters:
            digest.update(f"{p.name}:{p.nominal!r}:{p.lower!r}:{p.upper!r}".encode())
        return digest.hexdigest()


def flexible_rotational_plant(J_residual, L, frequencies, damping):
    """State-space of a rigid hub with cantilevered flexible modes, ``T -> wdot`` (batched).

    The hybrid model ``[J_tot L; L^T I][wdot; eta''] + [0; 2 xi w eta' + w^2 eta] = [T; 0]``
    with ``J_tot = J_residual + L L^T`` gives
    ``wdot = J_residual^-1 (T + L (2 xi w eta' + w^2 eta))``.

    Parameters
    ----------
    J_residual : array_like, shape (..., 3, 3)
        Residual (high-frequency) inertia ``J_tot - L L^T`` [kg m^2], positive definite.
    L : array_like, shape (..., 3, k)
        Modal participation factors [sqrt(kg) m].
    frequencies : array_like, shape (..., k)
        Cantilevered modal frequencies [rad/s].
    damping : float or array_like, shape (..., k)
        Modal damping ratios [-].

    Returns
    -------
    tuple of numpy.ndarray
        ``(A, B, C, D)`` with states ``[eta; eta_dot]``.
    """
    J0 = np.asarray(J_residual, dtype=float)
    L = np.asarray(L, dtype=float)
    w = np.asarray(frequencies, dtype=float)
    xi = np.broadcast_to(np.asarray(damping, dtype=float), w.shape)
    k = w.shape[-1]
    J0inv = np.linalg.inv(J0)
    Omega2 = w[..., :, None] * np.eye(k) * w[..., :, None]
    Xi = 2.0 * (xi * w)[..., :, None] * np.eye(k)
    LT = np.swapaxes(L, -1, -2)
    G = LT @ J0inv  # (k, 3)
    batch = np.broadcast_shapes(J0.shape[:-2], L.shape[:-2], w.shape[:-1])
    A = np.zeros(batch + (2 * k, 2 * k))
    A[..., :k, k:] = np.eye(k)
    A[..., k:, :k] = -(G @ L @ Omega2) - Omega2
    A[..., k:, k:] = -(G @ L @ Xi) - Xi
    B = np.zeros(batch + (2 * k, 3))
    B[..., k:, :] = -G
    C = np.concatenate([J0inv @ L @ Omega2, J0inv @ L @ Xi], axis=-1)
    D = np.broadcast_to(J0inv, batch + (3, 3)).copy()
    return A, B, C, D


def synthetic_flexible_plants(
    n_configurations: int = 20,
    *,
    modes: int = 3,
    uncertain: bool = True,
    rng: np.random.Generator | None = None,
) -> PlantArray:
    """A synthetic mission: varying inertia and lightly damped modes, like the paper's.

    The total inertia grows from ~60 to ~ 250 kg m^2 and back along the configurations (the
    arm carrying the target), its principal axes turn, and ``modes`` appendage modes between
    1.2 and 6 Hz (damping 0.01) sweep with the configuration. Real uncertainty (when
    ``uncertain``): the first modal frequency ``+-20 %`` and a target-inertia scaling
    ``+-10 %`` (two parameters).

    Parameters
    ----------
    n_configurations : int
        Number of configurations (equally spaced "times" in [0, 1500] s).
    modes : int
        Number of flexible modes.
    uncertain : bool
        Whether to expose the two real uncertain parameters.
    rng : numpy.random.Generator, optional
        Fixes the participation directions (default seed 0).
    """
    rng = rng or np.random.default_rng(0)
    t = np.linspace(0.0, 1500.0, n_configurations)
    phase = np.clip((t - 255.0) / (880.0 - 255.0), 0.0, 1.0)
    docked = (t >= 255.0).astype(float)
    base = np.diag([60.0, 65.0, 55.0])
    target = np.diag([140.0, 190.0, 120.0])
    angles = 0.6 * phase + 0.2 * np.sin(2 * np.pi * t / 1500.0)
    L_dirs = rng.normal(size=(3, modes))
    L_dirs /= np.linalg.norm(L_dirs, axis=0)
    mode_hz = np.geomspace(1.2, 6.0, modes)

    def build(index, values):
        values = np.asarray(values, dtype=float)
        freq_scale = values[:, 0] if values.shape[1] else np.ones(index.size)
        inertia_scale = values[:, 1] if values.shape[1] else np.ones(index.size)
        R = rotation_matrix((0.0, 0.0, 1.0), angles[index])
        carried = docked[index, None, None] * (1.0 - 0.6 * phase[index, None, None])
        J_tot = base + carried * inertia_scale[:, None, None] * (R @ target @ np.swapaxes(R, 1, 2))
        weights = np.sqrt(
            np.array([12.0, 9.0, 6.0, 4.0, 3.0, 2.0][:modes] + [2.0] * max(0, modes - 6))
        )
        L = (R @ L_dirs) * weights
        w = 2 * np.pi * mode_hz * (1.0 + 0.25 * np.sin(np.pi * phase[index]))[:, None]
        w = w.copy()
        w[:, 0] *= freq_scale
        J_residual = J_tot - L @ np.swapaxes(L, 1, 2)
        return flexible_rotational_plant(J_residual, L, w, 0.01)

    parameters = (
        (
            UncertainParameter("w1_scale", 1.0, 0.8, 1.2),
            UncertainParameter("target_inertia_scale", 1.0, 0.9, 1.1),
        )
        if uncertain
        else ()
    )
    return PlantArray(pd.DataFrame({"time [s]": t}), parameters, build, "synthetic")


def lfr_statespace(model, values: dict):
    """``(A, B, C, D)`` of an LFR with every block substituted by PHYSICAL ``values``.

    Parameters
    ----------
    model : oos_drake.lfr.LFR
        Uncertain plant whose blocks are all ``ureal`` (one model or a model array ``(K,)``).
    values : dict
        Block name -> physical values, shape (K,) (every block of ``model``; extra names are
        an error of :func:`oos_drake.lfr.usubs`).

    Returns
    -------
    tuple of numpy.ndarray
        ``(A, B, C, D)`` with leading dimension K.
    """
    sizes = {np.asarray(v).shape for v in values.values()}
    if values:
        model = usubs(model, values)
    n = model.nstates
    M = np.asarray(model.M, dtype=float)
    if M.ndim == 2:
        K = next(iter(sizes))[0] if sizes else 1
        M = np.broadcast_to(M, (K,) + M.shape)
    return M[..., :n, :n], M[..., :n, n:], M[..., n:, :n], M[..., n:, n:]


def from_lfr(
    model,
    configuration_values: dict,
    configurations: pd.DataFrame | None = None,
    *,
    source: str = "lfr",
) -> PlantArray:
    """A :class:`PlantArray` from an uncertain LFR and per-configuration scheduled values.

    Parameters
    ----------
    model : oos_drake.lfr.LFR
        The plant: either the 3x3 channels ``T_ext,G1 -> wdot`` or the full 6x6 model
        ``W_ext,G1 -> [a; wdot]`` (its rotational block ``[3:6, 3:6]`` is taken).
    configuration_values : dict
        Scheduled block name -> PHYSICAL values, shape (N,) (e.g.
        ``oos_drake.scenario.model.mission_values(times)``); substituted once.
    configurations : pandas.DataFrame, optional
        One row per configuration (e.g. ``time_s``).
    source : str
        Label stored with the results.

    Returns
    -------
    PlantArray
        Parameters: the blocks left after substitution (must be ``ureal``: ``Delta_real``),
        with their physical nominal values and ranges. The plants at given parameter values
        are the LFR with those values substituted (:func:`lfr_statespace`).
    """
    if not isinstance(model, LFR):
        raise ValueError(f"from_lfr: expected an oos_drake.lfr.LFR, got {type(model).__name__}")
    model = rotational_channels(model)
    sizes = {np.asarray(v).shape for v in configuration_values.values()}
    if len(sizes) != 1 or len(next(iter(sizes))) != 1:
        raise ValueError("from_lfr: every configuration value must be a 1-D array of equal length")
    N = next(iter(sizes))[0]
    scheduled = usubs(model, configuration_values)
    if not scheduled.batch_shape:
        scheduled = scheduled.model(np.zeros(N, dtype=int))
    blocks = scheduled.blocks
    kinds = set(blocks["kind"]) - {"ureal"}
    if kinds:
        raise ValueError(
            f"from_lfr: only ureal blocks may remain for synthesis, found {sorted(kinds)}"
        )
    parameters = tuple(
        UncertainParameter(row.name, float(row.nominal), float(row.range[0]), float(row.range[1]))
        for row in blocks.itertuples()
    )
    names = [p.name for p in parameters]

    def build(index, values):
        sub = scheduled.model(np.asarray(index, dtype=int))
        return lfr_statespace(sub, {name: values[:, j] for j, name in enumerate(names)})

    configurations = (
        configurations if configurations is not None else pd.DataFrame({"index": np.arange(N)})
    )
    return PlantArray(configurations, parameters, build, source)


def _pad(A, B, C, D, order: int, pole: float):
    """Pad ``(A, B, C, D)`` (leading batch dimensions allowed) to ``order`` states with
    decoupled states at ``pole`` [rad/s] (``B = 0``, ``C = 0``: the transfer function is
    unchanged)."""
    n = A.shape[-1]
    if n > order:
        raise ValueError(f"plant has {n} states, more than the array order {order}")
    if n == order:
        return A, B, C, D
    batch = A.shape[:-2]
    A2 = np.zeros(batch + (order, order))
    A2[..., :n, :n] = A
    A2[..., n:, n:] = pole * np.eye(order - n)
    B2 = np.zeros(batch + (order, B.shape[-1]))
    B2[..., :n, :] = B
    C2 = np.zeros(batch + (C.shape[-2], order))
    C2[..., :n] = C
    return A2, B2, C2, D


def lfr_source_plants(
    configurations: pd.DataFrame,
    nominal,
    uncertain: Callable,
    parameters: tuple[UncertainParameter, ...],
    *,
    padding_pole: float,
    source: str,
    statistics: Callable | None = None,
) -> PlantArray:
    """A :class:`PlantArray` from certain LFRs per configuration and, lazily, their uncertain
    LFRs (the Drake twin's form: nominal linearizations, LFRs extracted on demand).

    Parameters
    ----------
    configurations : pandas.DataFrame
        One row per configuration (e.g. ``time [s]``).
    nominal : sequence of oos_drake.lfr.LFR
        Configuration ``i``'s certain plant ``T -> wdot`` at the nominal parameter values (no
        uncertain block; orders may differ).
    uncertain : callable
        ``uncertain(i) -> LFR``: configuration ``i``'s uncertain plant ``T -> wdot`` (``ureal``
        blocks named as ``parameters``; the ones that do not act there may be absent; at most
        the array's order), called when a plant of ``i`` away from the nominal values is needed
        (the source may cache it).
    parameters : tuple of UncertainParameter
        The real uncertain parameters (physical nominal values and ranges).
    padding_pole : float
        Pole [rad/s] of the decoupled states that bring every model to the largest order of
        ``nominal`` (the transfer functions are unchanged).
    source : str
        Label stored with the results (e.g. ``"drake"``).
    statistics : callable, optional
        ``statistics() -> dict``: what building the models has cost so far.

    Returns
    -------
    PlantArray
        Rows at the nominal values are the ``nominal`` plants; the others are their
        configuration's uncertain LFR with the values substituted (:func:`lfr_statespace`).
    """
    models = list(nominal)
    if not models or any(not isinstance(m, LFR) or m.uncertainty for m in models):
        raise ValueError("lfr_source_plants: nominal must be certain LFRs, at least one")
    order = max(m.nstates for m in models)
    padded = [
        _pad(*(np.asarray(M, dtype=float) for M in (m.A, m.B, m.C, m.D)), order, padding_pole)
        for m in models
    ]
    matrices = tuple(np.stack([m[k] for m in padded]) for k in range(4))
    nominal_values = np.array([p.nominal for p in parameters], dtype=float)
    names = [p.name for p in parameters]

    def build(index, values):
        index = np.asarray(index, dtype=int).ravel()
        values = np.asarray(values, dtype=float).reshape(index.size, len(parameters))
        A, B, C, D = (M[index] for M in matrices)  # copies (fancy indexing)
        perturbed = np.any(values != nominal_values, axis=1)
        for i in np.unique(index[perturbed]):
            rows = np.flatnonzero(perturbed & (index == i))
            model = uncertain(i)
            present = model.uncertainty
            substituted = lfr_statespace(
                model, {n: values[rows, j] for j, n in enumerate(names) if n in present}
            )
            for M, S in zip((A, B, C, D), _pad(*substituted, order, padding_pole), strict=True):
                M[rows] = S
        return A, B, C, D

    return PlantArray(configurations, tuple(parameters), build, source, statistics)


#: The sources of a synthesis model array (:func:`make_plants`, ``oos synth --plant``).
PLANTS = ("lfr", "drake", "synthetic")


def make_plants(
    kind: str, configurations: int, scenario, *, drake: Callable | None = None
) -> PlantArray:
    """The synthesis model array of ``scenario`` from source ``kind``.

    Parameters
    ----------
    kind : str
        ``"lfr"`` (the scenario's LFR, :func:`scenario_plants`), ``"drake"`` (the Drake twin,
        through ``drake``) or ``"synthetic"`` (:func:`synthetic_flexible_plants`, tests).
    configurations : int
        Equally spaced mission configurations (:func:`mission_times`), at least 1.
    scenario : Scenario
        Unused by ``"synthetic"``.
    drake : callable, optional
        ``drake(times) -> PlantArray`` for ``"drake"`` (the application passes the twin's
        LFRs through :func:`lfr_source_plants`; this package never imports pydrake).
    """
    if kind == "lfr":
        return scenario_plants(configurations, scenario)
    if kind == "drake":
        if drake is None:
            raise ValueError("--plant drake: no Drake source given")
        return drake(mission_times(configurations, scenario))
    if kind == "synthetic":
        return synthetic_flexible_plants(configurations)
    raise ValueError(f"--plant must be lfr, drake or synthetic, got {kind!r}")


def between_plants(
    plants: PlantArray, check_density: int, kind: str, scenario, *, drake: Callable | None = None
) -> PlantArray | None:
    """The configurations between those of ``plants`` where the hard goals are checked:
    ``check_density - 1`` evenly spaced in each interval (the array of source ``kind``
    (:func:`make_plants`) built on ``(N - 1) * check_density + 1`` mission times, those of
    ``plants`` left out); None with ``check_density`` 1 or a single configuration."""
    d, N = check_density, plants.size
    if d <= 1 or N <= 1:
        return None
    dense = make_plants(kind, (N - 1) * d + 1, scenario, drake=drake)
    return dense.subset([i for i in range(dense.size) if i % d])


def scenario_plants(configurations: int, scenario) -> PlantArray:
    """The scenario's model array: its LFR substituted at equally spaced mission times."""
    from oos_drake.scenario.model import build_mission_model, mission_values

    times = mission_times(configurations, scenario)
    model = build_mission_model(scenario)
    return from_lfr(
        model, mission_values(times, scenario), pd.DataFrame({"time [s]": times}), source="lfr"
    )


def mission_times(configurations: int, scenario) -> np.ndarray:
    """The synthesis configurations: ``configurations`` equally spaced mission times [s] of
    ``scenario``'s mission."""
    if configurations < 1:
        raise ValueError(f"--configurations must be >= 1, got {configurations}")
    mission = scenario.mission
    return np.linspace(mission.t_start, mission.t_end, configurations)
