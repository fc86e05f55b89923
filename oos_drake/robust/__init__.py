"""Robust analysis: structured singular value, H-infinity norm, robust stability, worst-case gain.

``mussv`` and ``hinfnorm`` use numpy/scipy only; ``robstab``, ``wcgain``, ``robust_sweep`` and
``mu_sweep`` work on uncertain LFRs from :mod:`oos_drake.lfr` (the mu sweeps are one function,
:func:`oos_drake.robust.sweep.sweep_models`). No pydrake here.
"""

from oos_drake.robust.blocks import BlockStructure, parse_blk
from oos_drake.robust.hinf import HinfResult, hinfnorm
from oos_drake.robust.mu import MuResult, mussv
from oos_drake.robust.robstab import RobStabResult, robstab
from oos_drake.robust.sweep import SweepOptions, mu_sweep, robust_sweep
from oos_drake.robust.wcgain import WcGainResult, wcgain

__all__ = [
    "BlockStructure",
    "HinfResult",
    "MuResult",
    "RobStabResult",
    "SweepOptions",
    "WcGainResult",
    "hinfnorm",
    "mu_sweep",
    "mussv",
    "parse_blk",
    "robstab",
    "robust_sweep",
    "wcgain",
]
