"""Uncertain linear systems in linear fractional representation (LFR), MATLAB-RCT style.

``from oos_drake.lfr import ureal, ucomplex, ultidyn, lft, feedback, usubs, usample`` gives the
blocks and the algebra; :class:`LFR` is the immutable model object (see ``docs/DESIGN.md``).
"""

from oos_drake.lfr.blocks import UComplex, ULTIDyn, UReal
from oos_drake.lfr.core import LFR, BlockEntry, as_lfr
from oos_drake.lfr.frequency import freqresp
from oos_drake.lfr.interconnect import (
    append,
    connect,
    feedback,
    hstack,
    inv,
    lft,
    sumblk,
    vstack,
)
from oos_drake.lfr.substitution import close_blocks, nominal, usample, usubs
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
    "connect",
    "feedback",
    "freqresp",
    "hstack",
    "inv",
    "lft",
    "nominal",
    "sumblk",
    "ucomplex",
    "ultidyn",
    "ureal",
    "usample",
    "usubs",
    "vstack",
]
