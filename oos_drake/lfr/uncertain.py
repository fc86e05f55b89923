"""Uncertain atoms ``ureal``, ``ucomplex``, ``ultidyn``: 1-occurrence LFRs with MATLAB semantics."""

from __future__ import annotations

from oos_drake.lfr.blocks import UComplex, ULTIDyn, make_ureal_spec
from oos_drake.lfr.core import LFR, BlockEntry


def ureal(
    name: str,
    nominal: float,
    *,
    percent=None,
    plusminus=None,
    range=None,  # noqa: A002
    unit: str = "",
    quantity: str = "",
) -> LFR:
    """Uncertain (or scheduled) real parameter, as MATLAB's ``ureal``.

    Parameters
    ----------
    name : str
        Block name; uses of the same name in a model are the same parameter.
    nominal : float
        Nominal value (physical unit of the parameter).
    percent : float or (float, float), optional
        Range ``nominal +/- |nominal| * percent / 100``; a pair ``[-a, b]`` gives the asymmetric
        range ``[nominal - |nominal| a/100, nominal + |nominal| b/100]``. Must be >= 0.
    plusminus : float or (float, float), optional
        Range ``nominal +/- plusminus``; a pair ``[-a, b]`` gives ``[nominal - a, nominal + b]``.
    range : (float, float), optional
        Range ``[lower, upper]``, must contain the nominal strictly.
    unit : str, optional
        Physical unit of the value (``"kg"``, ``"kg m^2"``, ``"rad/s"``, ``"-"``).
    quantity : str, optional
        What the parameter is: one of :data:`~oos_drake.lfr.blocks.QUANTITIES` (``"mass"``,
        ``"inertia"``, ``"modal frequency"``, ``"stiffness"``, ...). Unit and quantity travel with
        the block through the algebra (``.blocks``, ``lftdata``, ``to_mat``).

    With none of them, MATLAB's default ``plusminus=1`` applies. Ranges centred on the nominal are
    normalized affinely (``p = nominal + halfwidth * delta``); asymmetric ranges use MATLAB's
    bilinear map (see :mod:`oos_drake.lfr.blocks`). Either way the LFR has one occurrence.

    Returns
    -------
    LFR
        1x1 static LFR ``p(delta)``.

    Raises
    ------
    ValueError
        Nominal outside the range, negative percent/plusminus, bad name.

    Examples
    --------
    >>> m = ureal("m", 2.0, percent=10, unit="kg", quantity="mass")      # 1.8 .. 2.2 kg
    >>> m.uncertainty["m"].range, m.uncertainty["m"].unit
    ((1.8, 2.2), 'kg')
    """
    spec = make_ureal_spec(
        name,
        nominal,
        percent=percent,
        plusminus=plusminus,
        range=range,
        unit=unit,
        quantity=quantity,
    )
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))


def ucomplex(
    name: str, nominal: complex, radius: float, *, unit: str = "", quantity: str = ""
) -> LFR:
    """Uncertain complex parameter ``nominal + radius * delta``, ``|delta| <= 1`` (``ucomplex``).

    Parameters
    ----------
    name : str
        Block name.
    nominal : complex
        Nominal value.
    radius : float
        Radius of the uncertainty disc (> 0).
    unit, quantity : str, optional
        Physical unit and what the parameter is (see :func:`ureal`).
    """
    spec = UComplex(name, complex(nominal), float(radius), unit, quantity)
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))


def ultidyn(
    name: str, shape=(1, 1), bound: float = 1.0, *, unit: str = "", quantity: str = ""
) -> LFR:
    """Unknown LTI dynamics with H-infinity norm <= ``bound`` (MATLAB ``ultidyn``, gain bounded).

    Parameters
    ----------
    name : str
        Block name.
    shape : int or (int, int)
        ``(p, q)``: ``p`` outputs and ``q`` inputs.
    bound : float
        Gain bound (> 0).
    unit, quantity : str, optional
        Unit of the gain and what the block is (``"additive dynamics"``, ..., see :func:`ureal`).

    Returns
    -------
    LFR
        ``p x q`` LFR ``bound * delta``.
    """
    spec = ULTIDyn(name, shape, float(bound), unit, quantity)
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))
