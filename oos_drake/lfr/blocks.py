"""Uncertain block specifications and their MATLAB-compatible normalization.

A block spec describes one named uncertain (or scheduled) element independently of how often it
occurs in a model. Every block is normalized so that ``delta = 0`` is the nominal value and
``|delta| <= 1`` covers the declared range, exactly as MATLAB's Robust Control Toolbox does:

* ``ureal`` with a range ``[L, R]`` around the nominal ``N`` uses the bilinear (Moebius) map
  fixed by ``p(-1) = L``, ``p(0) = N``, ``p(1) = R``:

  .. math:: p(\\delta) = \\frac{N + \\alpha \\delta}{1 + \\beta \\delta}, \\qquad
            \\beta = \\frac{2N - L - R}{R - L}, \\quad \\alpha = R (1 + \\beta) - N .

  It is affine (``beta = 0``) when the range is centred on the nominal. Either way the parameter is
  one occurrence of ``delta`` per use.
* ``ucomplex``: ``p = N + radius * delta`` with ``|delta| <= 1`` complex.
* ``ultidyn``: ``Delta = bound * delta`` with ``||delta||_inf <= 1``.

Every spec also carries what it stands for, from where it is created: ``unit`` (the physical unit
of its value, ``"kg"``, ``"kg m^2"``, ``"rad/s"``, ``"-"``) and ``quantity`` (one of
:data:`QUANTITIES`: ``"mass"``, ``"inertia"``, ``"modal frequency"``, ...). Both are ``""`` when
not given; the algebra keeps them (merges, substitutions, ``lftdata``, ``.blocks``, ``to_mat``)
so that nothing downstream guesses them from a block's name.

The specs are frozen dataclasses; the algebra only keeps them in LFR block tables.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

#: Relative slack allowed when checking that a physical value lies in its block's range.
RANGE_RTOL = 1e-9

#: What an uncertain block may stand for (the ``quantity=`` of ``ureal``/``ucomplex``/``ultidyn``).
#: ``angle``: a scheduled angle (its value is ``tan(angle / 4)``); ``switch``: a connection switch
#: in [0, 1]; ``additive dynamics``/``multiplicative dynamics``: ``ultidyn`` blocks of the additive
#: plant and multiplicative input uncertainty; ``dynamics``: any other ``ultidyn``.
QUANTITIES = (
    "mass",
    "inertia",
    "length",
    "modal frequency",
    "stiffness",
    "damping",
    "angle",
    "switch",
    "gain",
    "dynamics",
    "additive dynamics",
    "multiplicative dynamics",
)


def _check_facts(spec) -> None:
    """Validate ``unit`` and ``quantity`` of a spec (``""``: not given)."""
    if not isinstance(spec.unit, str):
        raise ValueError(f"{spec.kind} {spec.name!r}: unit must be a string, got {spec.unit!r}")
    if spec.quantity not in QUANTITIES + ("",):
        raise ValueError(
            f"{spec.kind} {spec.name!r}: unknown quantity {spec.quantity!r}; use one of "
            f"{', '.join(QUANTITIES)}"
        )


def _facts(spec) -> str:
    facts = [f for f in (spec.quantity, f"[{spec.unit}]" if spec.unit else "") if f]
    return f" ({' '.join(facts)})" if facts else ""


def _check_name(name: object) -> str:
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"uncertain block name must be a non-empty string, got {name!r}")
    return name


def _fmt(value) -> str:
    arr = np.asarray(value)
    if arr.size == 1:
        return f"{arr.ravel()[0]:.6g}"
    flat = arr.ravel()
    text = ", ".join(f"{v:.6g}" for v in flat[:4])
    return f"[{text}{', ...' if flat.size > 4 else ''}]"


@dataclass(frozen=True)
class UReal:
    """Real parameter ``p`` in ``[lower, upper]`` around ``nominal`` (MATLAB ``ureal``).

    Parameters
    ----------
    name : str
        Block name (becomes a column name in campaign tables).
    nominal : float
        Nominal value, in the parameter's physical unit.
    lower, upper : float
        Range ``[lower, upper]`` with ``lower < nominal < upper``.
    mode : str
        How the user specified the range (``"plusminus"``, ``"percent"`` or ``"range"``);
        display only.
    unit : str
        Physical unit of the value (``"kg"``); ``""`` when not given.
    quantity : str
        What the parameter is, one of :data:`QUANTITIES`; ``""`` when not given.
    """

    name: str
    nominal: float
    lower: float
    upper: float
    mode: str = field(default="range", compare=False)
    unit: str = ""
    quantity: str = ""

    kind = "ureal"
    shape = (1, 1)  # (p, q) of one occurrence: w rows, z rows

    def __post_init__(self):
        _check_name(self.name)
        _check_facts(self)
        for label in ("nominal", "lower", "upper"):
            value = float(getattr(self, label))
            object.__setattr__(self, label, value)
            if not math.isfinite(value):
                raise ValueError(f"ureal {self.name!r}: {label} must be finite, got {value!r}")
        if not self.lower < self.upper:
            raise ValueError(
                f"ureal {self.name!r}: empty range [{self.lower:.6g}, {self.upper:.6g}]"
            )
        if not self.lower < self.nominal < self.upper:
            raise ValueError(
                f"ureal {self.name!r}: nominal {self.nominal:.6g} outside its range "
                f"[{self.lower:.6g}, {self.upper:.6g}] (must be strictly inside)"
            )

    # --- normalization -------------------------------------------------------------------
    @property
    def beta(self) -> float:
        """Denominator coefficient of the bilinear map (0 for a centred range)."""
        lo, hi, nom = self.lower, self.upper, self.nominal
        centred = math.isclose(nom - lo, hi - nom, rel_tol=1e-12, abs_tol=0.0)
        return 0.0 if centred else (2.0 * nom - lo - hi) / (hi - lo)

    @property
    def alpha(self) -> float:
        """Numerator coefficient of the bilinear map (the half-width for a centred range)."""
        beta = self.beta
        if beta == 0.0:
            return 0.5 * (self.upper - self.lower)
        return self.upper * (1.0 + beta) - self.nominal

    @property
    def is_affine(self) -> bool:
        """True when the range is centred on the nominal (affine normalization)."""
        return self.beta == 0.0

    def atom(self) -> np.ndarray:
        """2x2 matrix ``[[M11, M12], [M21, M22]]`` with ``p = Fu(M, delta)`` (one occurrence)."""
        beta, alpha, nom = self.beta, self.alpha, self.nominal
        gain = alpha - nom * beta  # = 2 (R - N)(N - L) / (R - L) > 0
        root = math.sqrt(gain)
        return np.array([[-beta, root], [root, nom]])

    def to_physical(self, delta):
        """Physical value(s) for normalized ``delta`` (array-like)."""
        delta = np.asarray(delta, dtype=float)
        return (self.nominal + self.alpha * delta) / (1.0 + self.beta * delta)

    def to_normalized(self, value, *, check: bool = True):
        """Normalized ``delta`` for physical value(s); raises ``ValueError`` outside the range."""
        value = np.asarray(value)
        if np.iscomplexobj(value):
            if np.any(value.imag != 0):
                raise ValueError(
                    f"ureal {self.name!r}: complex value {_fmt(value)} for a real block"
                )
            value = value.real
        value = value.astype(float)
        if not np.all(np.isfinite(value)):
            raise ValueError(f"ureal {self.name!r}: non-finite value {_fmt(value)}")
        if check:
            slack = RANGE_RTOL * max(1.0, abs(self.lower), abs(self.upper))
            bad = (value < self.lower - slack) | (value > self.upper + slack)
            if np.any(bad):
                raise ValueError(
                    f"ureal {self.name!r}: value {_fmt(value[bad])} outside its range "
                    f"[{self.lower:.6g}, {self.upper:.6g}]"
                )
        return (value - self.nominal) / (self.alpha - self.beta * value)

    def check_normalized(self, delta) -> np.ndarray:
        """Validate normalized values (real, finite); returns them as a float array."""
        delta = np.asarray(delta)
        if np.iscomplexobj(delta) and np.any(delta.imag != 0):
            raise ValueError(f"ureal {self.name!r}: complex delta {_fmt(delta)} for a real block")
        delta = np.real(delta).astype(float)
        if not np.all(np.isfinite(delta)):
            raise ValueError(f"ureal {self.name!r}: non-finite delta {_fmt(delta)}")
        if self.beta != 0.0 and np.any(np.isclose(1.0 + self.beta * delta, 0.0)):
            raise ValueError(f"ureal {self.name!r}: delta {_fmt(delta)} hits the bilinear pole")
        return delta

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """Physical values drawn uniformly in ``[lower, upper]``."""
        return rng.uniform(self.lower, self.upper, size)

    @property
    def range(self) -> tuple[float, float]:
        """``(lower, upper)`` physical range."""
        return (self.lower, self.upper)

    def describe(self) -> str:
        return (
            f"ureal {self.name}{_facts(self)}: nominal {self.nominal:.6g}, "
            f"range [{self.lower:.6g}, {self.upper:.6g}]"
        )


@dataclass(frozen=True)
class UComplex:
    """Complex parameter ``p = nominal + radius * delta``, ``|delta| <= 1`` (MATLAB ``ucomplex``).

    Parameters
    ----------
    name : str
        Block name.
    nominal : complex
        Nominal value (physical unit).
    radius : float
        Radius of the uncertainty disc around the nominal, > 0 (same unit).
    unit, quantity : str
        Physical unit and what the parameter is (:data:`QUANTITIES`); ``""`` when not given.
    """

    name: str
    nominal: complex
    radius: float
    unit: str = ""
    quantity: str = ""

    kind = "ucomplex"
    shape = (1, 1)
    range = None  # a disc, not an interval

    def __post_init__(self):
        _check_name(self.name)
        _check_facts(self)
        if not (np.isfinite(self.nominal) and math.isfinite(self.radius)):
            raise ValueError(
                f"ucomplex {self.name!r}: nominal {self.nominal!r} and radius {self.radius!r} "
                "must be finite"
            )
        if not self.radius > 0:
            raise ValueError(f"ucomplex {self.name!r}: radius must be > 0, got {self.radius!r}")

    def atom(self) -> np.ndarray:
        root = math.sqrt(self.radius)
        return np.array([[0.0, root], [root, self.nominal]], dtype=complex)

    def to_physical(self, delta):
        return self.nominal + self.radius * np.asarray(delta, dtype=complex)

    def to_normalized(self, value, *, check: bool = True):
        value = np.asarray(value, dtype=complex)
        if not np.all(np.isfinite(value)):
            raise ValueError(f"ucomplex {self.name!r}: non-finite value {_fmt(value)}")
        delta = (value - self.nominal) / self.radius
        if check:
            bad = np.abs(delta) > 1.0 + RANGE_RTOL
            if np.any(bad):
                raise ValueError(
                    f"ucomplex {self.name!r}: value {_fmt(value[bad])} outside the disc of radius "
                    f"{self.radius:.6g} around {self.nominal:.6g}"
                )
        return delta

    def check_normalized(self, delta) -> np.ndarray:
        delta = np.asarray(delta, dtype=complex)
        if not np.all(np.isfinite(delta)):
            raise ValueError(f"ucomplex {self.name!r}: non-finite delta {_fmt(delta)}")
        return delta

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """Physical values drawn uniformly in the disc."""
        radius = self.radius * np.sqrt(rng.uniform(0.0, 1.0, size))
        return self.nominal + radius * np.exp(2j * np.pi * rng.uniform(0.0, 1.0, size))

    def describe(self) -> str:
        return (
            f"ucomplex {self.name}{_facts(self)}: nominal {self.nominal:.6g}, "
            f"radius {self.radius:.6g}"
        )


@dataclass(frozen=True)
class ULTIDyn:
    """Unknown LTI dynamics ``Delta = bound * delta``, ``||delta||_inf <= 1`` (MATLAB ``ultidyn``).

    Parameters
    ----------
    name : str
        Block name.
    io_shape : tuple of int
        ``(p, q)``: ``Delta`` has ``p`` outputs (rows of ``w``) and ``q`` inputs (rows of ``z``).
    bound : float
        Gain bound (H-infinity norm bound), > 0.
    unit, quantity : str
        Unit of the gain (``"-"`` for a normalized perturbation) and what the block is
        (:data:`QUANTITIES`, e.g. ``"additive dynamics"``); ``""`` when not given.
    """

    name: str
    io_shape: tuple[int, int]
    bound: float = 1.0
    unit: str = ""
    quantity: str = ""

    kind = "ultidyn"

    def __post_init__(self):
        _check_name(self.name)
        _check_facts(self)
        shape = tuple(int(s) for s in np.atleast_1d(self.io_shape))
        if len(shape) == 1:
            shape = (shape[0], shape[0])
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(
                f"ultidyn {self.name!r}: shape must be (p, q) >= 1, got {self.io_shape!r}"
            )
        object.__setattr__(self, "io_shape", shape)
        if not (math.isfinite(self.bound) and self.bound > 0):
            raise ValueError(f"ultidyn {self.name!r}: bound must be > 0, got {self.bound!r}")

    nominal = 0.0
    range = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.io_shape

    def atom(self) -> np.ndarray:
        p, q = self.io_shape
        root = math.sqrt(self.bound)
        atom = np.zeros((q + p, p + q))
        atom[:q, p:] = root * np.eye(q)
        atom[q:, :p] = root * np.eye(p)
        return atom

    def to_physical(self, delta):
        return self.bound * np.asarray(delta)

    def to_normalized(self, value, *, check: bool = True):
        value = np.asarray(value)
        p, q = self.io_shape
        if value.shape[-2:] != (p, q):
            raise ValueError(
                f"ultidyn {self.name!r}: value of shape {value.shape} is not (..., {p}, {q})"
            )
        if not np.all(np.isfinite(value)):
            raise ValueError(f"ultidyn {self.name!r}: non-finite value")
        if check:
            norms = np.linalg.norm(value, ord=2, axis=(-2, -1))
            bad = norms > self.bound * (1.0 + RANGE_RTOL)
            if np.any(bad):
                raise ValueError(
                    f"ultidyn {self.name!r}: value with gain {_fmt(norms[bad])} exceeds bound "
                    f"{self.bound:.6g}"
                )
        return value / self.bound

    def check_normalized(self, delta) -> np.ndarray:
        delta = np.asarray(delta)
        if delta.shape[-2:] != self.io_shape:
            raise ValueError(
                f"ultidyn {self.name!r}: delta of shape {delta.shape} is not (..., "
                f"{self.io_shape[0]}, {self.io_shape[1]})"
            )
        return delta

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """Static real gains with spectral norm uniform in ``[0, bound]`` (dynamics not drawn)."""
        p, q = self.io_shape
        raw = rng.standard_normal((size, p, q))
        norms = np.linalg.norm(raw, ord=2, axis=(-2, -1))
        scale = self.bound * rng.uniform(0.0, 1.0, size) / np.where(norms > 0, norms, 1.0)
        return raw * scale[:, None, None]

    def describe(self) -> str:
        return (
            f"ultidyn {self.name}{_facts(self)}: {self.io_shape[0]}x{self.io_shape[1]}, "
            f"bound {self.bound:.6g}"
        )


Block = UReal | UComplex | ULTIDyn


def same_block(first: Block, second: Block) -> bool:
    """True when two specs describe the same block (same kind, name and normalization).

    ``unit`` and ``quantity`` must agree where both are given (``""`` matches anything).
    """
    if type(first) is not type(second) or first.name != second.name:
        return False
    for fact in ("unit", "quantity"):
        given = {getattr(first, fact), getattr(second, fact)} - {""}
        if len(given) > 1:
            return False
    if isinstance(first, UReal):
        return all(
            math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-300)
            for a, b in (
                (first.nominal, second.nominal),
                (first.lower, second.lower),
                (first.upper, second.upper),
            )
        )
    if isinstance(first, UComplex):
        return np.isclose(first.nominal, second.nominal, rtol=1e-12, atol=0) and math.isclose(
            first.radius, second.radius, rel_tol=1e-12
        )
    return first.io_shape == second.io_shape and math.isclose(
        first.bound, second.bound, rel_tol=1e-12
    )


def merge_facts(first: Block, second: Block) -> Block:
    """``first`` with the ``unit`` and ``quantity`` that only ``second`` gives (same block)."""
    missing = {
        fact: getattr(second, fact)
        for fact in ("unit", "quantity")
        if not getattr(first, fact) and getattr(second, fact)
    }
    return dataclasses.replace(first, **missing) if missing else first


def make_ureal_spec(
    name,
    nominal,
    *,
    percent=None,
    plusminus=None,
    range=None,  # noqa: A002
    unit: str = "",
    quantity: str = "",
) -> UReal:
    """Build a :class:`UReal` spec from MATLAB-style arguments (see :func:`oos_drake.lfr.ureal`)."""
    facts = {"unit": unit, "quantity": quantity}
    _check_name(name)
    try:
        nominal = float(nominal)
    except (TypeError, ValueError):
        raise ValueError(
            f"ureal {name!r}: nominal must be a real number, got {nominal!r}"
        ) from None
    given = [
        label
        for label, v in (("percent", percent), ("plusminus", plusminus), ("range", range))
        if v is not None
    ]
    if len(given) > 1:
        raise ValueError(
            f"ureal {name!r}: give only one of percent, plusminus, range (got {given})"
        )
    if not given:
        plusminus = 1.0  # MATLAB default: PlusMinus [-1, 1]

    def pair(value, label):
        arr = np.atleast_1d(np.asarray(value, dtype=float))
        if arr.size == 1:
            return -abs(arr[0]) if arr[0] >= 0 else arr[0], abs(arr[0]), arr[0]
        if arr.size != 2:
            raise ValueError(f"ureal {name!r}: {label} must be a scalar or a pair, got {value!r}")
        return arr[0], arr[1], None

    if percent is not None or plusminus is not None:
        label, value = ("percent", percent) if percent is not None else ("plusminus", plusminus)
        low, high, scalar = pair(value, label)
        if scalar is not None and scalar < 0:
            raise ValueError(f"ureal {name!r}: {label} must be >= 0, got {scalar:.6g}")
        if scalar is None and (low > 0 or high < 0):
            raise ValueError(
                f"ureal {name!r}: {label} pair must be [-a, b] with a, b >= 0, got {list(value)!r}"
            )
        scale = 1.0  # plusminus: absolute deviations
        if label == "percent":
            if nominal == 0.0:
                raise ValueError(
                    f"ureal {name!r}: percent uncertainty needs a nonzero nominal, got 0"
                )
            scale = abs(nominal) / 100.0
        return UReal(name, nominal, nominal + low * scale, nominal + high * scale, label, **facts)
    arr = np.asarray(range, dtype=float).ravel()
    if arr.size != 2:
        raise ValueError(f"ureal {name!r}: range must be a pair (lower, upper), got {range!r}")
    return UReal(name, nominal, float(arr[0]), float(arr[1]), "range", **facts)
