"""Uncertain atoms ``ureal``, ``ucomplex``, ``ultidyn``: 1-occurrence LFRs with MATLAB semantics."""

from __future__ import annotations

from oos_drake.lfr.blocks import UComplex, ULTIDyn, make_ureal_spec
from oos_drake.lfr.core import LFR, BlockEntry


def ureal(name: str, nominal: float, *, percent=None, plusminus=None, range=None) -> LFR:  # noqa: A002
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
    >>> m = ureal("m", 2.0, percent=10)      # mass [kg], 1.8 .. 2.2
    >>> m.uncertainty["m"].range
    (1.8, 2.2)
    """
    spec = make_ureal_spec(name, nominal, percent=percent, plusminus=plusminus, range=range)
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))


def ucomplex(name: str, nominal: complex, radius: float) -> LFR:
    """Uncertain complex parameter ``nominal + radius * delta``, ``|delta| <= 1`` (``ucomplex``).

    Parameters
    ----------
    name : str
        Block name.
    nominal : complex
        Nominal value.
    radius : float
        Radius of the uncertainty disc (> 0).
    """
    spec = UComplex(name, complex(nominal), float(radius))
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))


def ultidyn(name: str, shape=(1, 1), bound: float = 1.0) -> LFR:
    """Unknown LTI dynamics with H-infinity norm <= ``bound`` (MATLAB ``ultidyn``, gain bounded).

    Parameters
    ----------
    name : str
        Block name.
    shape : int or (int, int)
        ``(p, q)``: ``p`` outputs and ``q`` inputs.
    bound : float
        Gain bound (> 0).

    Returns
    -------
    LFR
        ``p x q`` LFR ``bound * delta``.
    """
    spec = ULTIDyn(name, shape, float(bound))
    return LFR(spec.atom(), 0, (BlockEntry(spec, 1),))
