"""Dispersion distributions of campaign parameters, in physical units.

Each distribution maps uniform variates to values through its inverse CDF (``ppf``), so the same
object serves plain Monte Carlo (``u`` i.i.d. uniform) and Latin hypercube sampling (``u``
stratified), and gives its density (``pdf``) so that the mu-guided sampler can weight its
proposals by the likelihood ratio. Spec syntax (TOML inline tables)::

    J_hub    = { distribution = "uniform", low = 300.0, high = 700.0 }
    f_array  = { distribution = "normal", mean = 0.3, std = 0.05 }          # truncated to range
    k_dock   = { distribution = "log-uniform", low = 1e2, high = 1e5 }
    c_dock   = { distribution = "fixed", value = 50.0 }
    theta0   = { distribution = "choice", values = [-0.002, 0.0, 0.002], probabilities = [...] }
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from oos_drake.campaign.simulator import Parameter


class _Law:
    """What every law has besides ``ppf`` and ``pdf``: its support and its spec entry."""

    @property
    def support(self) -> tuple[float, float]:
        """Smallest and largest value [unit of the parameter]."""
        return self.low, self.high

    def to_dict(self) -> dict[str, Any]:
        """The spec's inline table: ``distribution`` and the fields (tuples as lists)."""
        fields = {k: list(v) if isinstance(v, tuple) else v for k, v in vars(self).items()}
        return {"distribution": self.kind} | fields


@dataclass(frozen=True)
class _Interval(_Law):
    """A law on ``[low, high]`` [unit of the parameter]."""

    low: float
    high: float


@dataclass(frozen=True)
class Uniform(_Interval):
    """Uniform on ``[low, high]`` [unit of the parameter]."""

    kind = "uniform"

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return self.low + np.asarray(u) * (self.high - self.low)

    def pdf(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        inside = (x >= self.low) & (x <= self.high)
        return np.where(inside, 1.0 / (self.high - self.low), 0.0)


@dataclass(frozen=True)
class LogUniform(_Interval):
    """Log-uniform on ``[low, high]``, ``0 < low < high``: ``log x`` is uniform."""

    kind = "log-uniform"

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return np.exp(math.log(self.low) + np.asarray(u) * math.log(self.high / self.low))

    def pdf(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        inside = (x >= self.low) & (x <= self.high)
        safe = np.where(inside, x, 1.0)
        return np.where(inside, 1.0 / (safe * math.log(self.high / self.low)), 0.0)


@dataclass(frozen=True)
class TruncatedNormal(_Law):
    """Normal(``mean``, ``std``) truncated to ``[low, high]`` (the parameter range by default)."""

    mean: float
    std: float
    low: float
    high: float
    kind = "normal"

    @property
    def law(self):
        """The frozen ``scipy.stats.truncnorm`` law (log-space tails: no underflow far out)."""
        import scipy.stats  # seconds to import: only where a normal law is used

        a = (self.low - self.mean) / self.std
        b = (self.high - self.mean) / self.std
        return scipy.stats.truncnorm(a, b, loc=self.mean, scale=self.std)

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return np.clip(self.law.ppf(np.asarray(u, dtype=float)), self.low, self.high)

    def pdf(self, x: np.ndarray) -> np.ndarray:
        return self.law.pdf(np.asarray(x, dtype=float))


@dataclass(frozen=True)
class Fixed(_Law):
    """A single value (degenerate distribution); its ``pdf`` is 1 so likelihood ratios ignore it."""

    value: float
    kind = "fixed"

    def ppf(self, u: np.ndarray) -> np.ndarray:
        return np.full(np.shape(u), float(self.value))

    def pdf(self, x: np.ndarray) -> np.ndarray:
        return np.ones(np.shape(x))

    @property
    def support(self) -> tuple[float, float]:
        return self.value, self.value


@dataclass(frozen=True)
class Choice(_Law):
    """Discrete values with probabilities (equal by default); ``pdf`` is the probability mass."""

    values: tuple[float, ...]
    probabilities: tuple[float, ...]
    kind = "choice"

    def ppf(self, u: np.ndarray) -> np.ndarray:
        edges = np.cumsum(self.probabilities)
        index = np.searchsorted(edges, np.asarray(u) * edges[-1], side="right")
        return np.asarray(self.values, dtype=float)[np.minimum(index, len(self.values) - 1)]

    def pdf(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        mass = np.zeros(x.shape)
        for value, probability in zip(self.values, self.probabilities, strict=True):
            mass = mass + np.where(x == value, probability, 0.0)
        return mass

    @property
    def support(self) -> tuple[float, float]:
        return min(self.values), max(self.values)


Distribution = Uniform | LogUniform | TruncatedNormal | Fixed | Choice

#: Distribution name -> (required keys, optional keys) in a spec's inline table.
_KEYS: dict[str, tuple[set[str], set[str]]] = {
    "uniform": ({"low", "high"}, set()),
    "log-uniform": ({"low", "high"}, set()),
    "normal": ({"mean", "std"}, {"low", "high"}),
    "fixed": ({"value"}, set()),
    "choice": ({"values"}, {"probabilities"}),
}


def finite_number(where: str, key: str, value: Any) -> float:
    """``value`` as a float; ``ValueError`` ``"<where>: <key> = <value> is not a finite number"``
    for anything else (booleans, strings, NaN, inf)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{where}: {key} = {value!r} is not a finite number")
    return float(value)


def parse_distribution(where: str, table: Any, parameter: Parameter) -> Distribution:
    """Validate one dispersion table against its parameter and return the distribution.

    Parameters
    ----------
    where : str
        Location used in error messages (``"spec.toml: dispersions.J_hub"``).
    table : dict
        The inline table from the spec.
    parameter : Parameter
        The simulator parameter it disperses (range check, default truncation bounds).

    Raises
    ------
    ValueError
        Unknown distribution or key, missing key, non-numeric value, empty or inverted interval,
        non-positive std, probabilities that do not sum to 1, or any value outside the
        parameter's range ``[lower, upper]``.
    """
    if not isinstance(table, Mapping):
        raise ValueError(f'{where}: expected a table like {{ distribution = "uniform", ... }}')
    name = table.get("distribution")
    if name not in _KEYS:
        raise ValueError(
            f"{where}: unknown distribution {name!r}; use one of {', '.join(sorted(_KEYS))}"
        )
    required, optional = _KEYS[name]
    keys = set(table) - {"distribution"}
    missing = sorted(required - keys)
    if missing:
        raise ValueError(f"{where}: {name} distribution needs {', '.join(missing)}")
    unknown = sorted(keys - required - optional)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {', '.join(unknown)} for a {name} distribution")
    lo, hi = parameter.lower, parameter.upper
    unit = parameter.unit

    def in_range(key: str, value: float) -> float:
        clipped = parameter.clip(value)
        if clipped is None:
            raise ValueError(
                f"{where}: {key} = {value:g} {unit} outside the range of {parameter.name} "
                f"[{lo:g}, {hi:g}] {unit}"
            )
        return clipped

    if name == "fixed":
        return Fixed(in_range("value", finite_number(where, "value", table["value"])))
    if name == "choice":
        raw = table["values"]
        if not isinstance(raw, list) or not raw:
            raise ValueError(f"{where}: values must be a non-empty list")
        values = tuple(in_range("values", finite_number(where, "values", v)) for v in raw)
        if "probabilities" in table:
            praw = table["probabilities"]
            if not isinstance(praw, list) or len(praw) != len(values):
                raise ValueError(f"{where}: probabilities must be a list as long as values")
            probabilities = tuple(finite_number(where, "probabilities", p) for p in praw)
            if any(p < 0 for p in probabilities) or not math.isclose(
                sum(probabilities), 1.0, rel_tol=1e-9
            ):
                raise ValueError(
                    f"{where}: probabilities {list(probabilities)} must be >= 0 and sum to 1"
                )
        else:
            probabilities = tuple(1.0 / len(values) for _ in values)
        return Choice(values, probabilities)
    if name == "normal":
        mean = in_range("mean", finite_number(where, "mean", table["mean"]))
        std = finite_number(where, "std", table["std"])
        if std <= 0:
            raise ValueError(f"{where}: std = {std:g} {unit} must be positive")
        low = in_range("low", finite_number(where, "low", table.get("low", lo)))
        high = in_range("high", finite_number(where, "high", table.get("high", hi)))
        if not low < high:
            raise ValueError(f"{where}: low = {low:g} must be below high = {high:g} {unit}")
        return TruncatedNormal(mean, std, low, high)
    low = in_range("low", finite_number(where, "low", table["low"]))
    high = in_range("high", finite_number(where, "high", table["high"]))
    if not low < high:
        raise ValueError(f"{where}: low = {low:g} must be below high = {high:g} {unit}")
    if name == "log-uniform":
        if low <= 0:
            raise ValueError(f"{where}: log-uniform needs low > 0, got {low:g} {unit}")
        return LogUniform(low, high)
    return Uniform(low, high)
