"""Uncertain linear systems in linear fractional representation (LFR), MATLAB-RCT style.

An :class:`LFR` is the upper LFT ``Fu(M, blkdiag(I/s, Delta))`` of a continuous-time state-space
model and named uncertain blocks (see ``docs/DESIGN.md``). Quick tour::

    import control, numpy as np
    from oos_drake.lfr import ureal, feedback, usubs, usample

    m = ureal("m", 2.0, percent=10)              # mass [kg], MATLAB semantics
    k = ureal("k", 5.0, range=(4.0, 7.0))        # asymmetric range -> bilinear normalization
    s = control.tf("s")
    plant = feedback((1 / m) * (1 / s**2), k)   # 1 / (m s^2 + k), one occurrence each
    plant.blocks                                 # table: name, kind, repetitions, nominal, range
    models = usubs(plant, {"m": np.linspace(1.8, 2.2, 200)})   # model array, batch (200,)
    G = models.nominal.freqresp(np.logspace(-1, 1, 500))      # (200, 500, 1, 1)
    ss_one = usubs(plant, {"m": 2.1, "k": 6.0}).to_ss()       # control.StateSpace

Modules: :mod:`~oos_drake.lfr.blocks` (block specs and normalization),
:mod:`~oos_drake.lfr.core` (the LFR object, append/close primitives, operators),
:mod:`~oos_drake.lfr.interconnect` (feedback, lft, stacking, inversion; the one named-signal
``connect`` is :func:`oos_drake.control.statespace.connect`),
:mod:`~oos_drake.lfr.substitution` (usubs, usample, nominal),
:mod:`~oos_drake.lfr.frequency` (batched frequency response),
:mod:`~oos_drake.lfr.reduction` (structured minimal-occurrence reduction),
:mod:`~oos_drake.lfr.matfile` (MATLAB export).
"""

from oos_drake.lfr.blocks import UComplex, ULTIDyn, UReal
from oos_drake.lfr.core import LFR, BlockEntry, as_lfr
from oos_drake.lfr.frequency import freqresp
from oos_drake.lfr.interconnect import (
    append,
    feedback,
    hstack,
    inv,
    lft,
    vstack,
)
from oos_drake.lfr.matfile import load_lfr
from oos_drake.lfr.substitution import close_blocks, lftdata, nominal, usample, usubs
from oos_drake.lfr.uncertain import ucomplex, ultidyn, ureal

__all__ = [
    "LFR",
    "BlockEntry",
    "UComplex",
    "ULTIDyn",
    "UReal",
    "append",
    "as_lfr",
    "close_blocks",
    "feedback",
    "freqresp",
    "hstack",
    "inv",
    "lft",
    "lftdata",
    "load_lfr",
    "nominal",
    "ucomplex",
    "ultidyn",
    "ureal",
    "usample",
    "usubs",
    "vstack",
]
