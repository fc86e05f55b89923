"""Robust analysis: structured singular value, H-infinity norm, robust stability, worst-case gain.

``mussv`` and ``hinfnorm`` use numpy/scipy only; ``robstab``, ``wcgain`` and ``robust_sweep``
work on uncertain LFRs from :mod:`oos_drake.lfr`. No pydrake here.
"""

from oos_drake.robust.blocks import BlockStructure, parse_blk
from oos_drake.robust.hinf import HinfResult, hinfnorm
from oos_drake.robust.mu import MuResult, mussv
from oos_drake.robust.robstab import RobStabResult, robstab
from oos_drake.robust.sweep import robust_sweep
from oos_drake.robust.wcgain import WcGainResult, wcgain

__all__ = [
    "BlockStructure",
    "HinfResult",
    "MuResult",
    "RobStabResult",
    "WcGainResult",
    "hinfnorm",
    "mussv",
    "parse_blk",
    "robstab",
    "robust_sweep",
    "wcgain",
]
