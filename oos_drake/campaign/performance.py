"""``oos confirm``'s performance table as the campaign layer reads it.

``performance_confirmation.parquet`` (written by :mod:`oos_drake.analysis.performance_twin`)
holds, per performance channel and uncertainty subset, the analysis' worst-case gain (its
certified interval) and the twin run with the worst perturbation and the worst input; every gain
is a ratio to the requirement the channel is weighted by (> 1 violates it). The campaign report,
``oos campaign falsify --confirm`` and ``oos report`` compare it with nonlinear runs through the
names below.
"""

from __future__ import annotations

import math

import pandas as pd

__all__ = [
    "PERFORMANCE_CONFIRMATION_FILE",
    "REQUIREMENT_METRICS",
    "REQUIREMENT_NAMES",
    "worst_twin_row",
    "worst_twin_where",
]

#: File of the performance confirmation in an ``oos confirm`` folder.
PERFORMANCE_CONFIRMATION_FILE = "performance_confirmation.parquet"
#: Performance channel -> the campaign metric whose requirement is its unit gain.
REQUIREMENT_METRICS = {"e_p": "ape", "e_u": "peak_torque"}
#: Performance channel -> the requirement its unit gain is, for a reader.
REQUIREMENT_NAMES = {"e_p": "APE requirement", "e_u": "torque limit"}
#: Column of the twin's ratio to the requirement.
TWIN_COLUMN = "gain twin [-]"


def worst_twin_row(table: pd.DataFrame | None) -> pd.Series | None:
    """The row of the largest finite twin ratio (``gain twin [-]``); None without a table or
    without a finished twin run."""
    if table is None or TWIN_COLUMN not in table.columns:
        return None
    ratios = pd.to_numeric(table[TWIN_COLUMN], errors="coerce")
    if not ratios.notna().any():
        return None
    return table.loc[ratios.idxmax()]


def worst_twin_where(row: pd.Series) -> str:
    """Which requirement, met or violated, where (channel, subset, time [s], frequency [Hz]) and
    the analysis' certified interval of that gain, e.g. ``"APE requirement violated: e_p total,
    t = 269.2 s, f = 0.0807 Hz; analysis [1.179, 1.199]"``."""
    channel = str(row.get("channel", "?"))
    requirement = REQUIREMENT_NAMES.get(channel, "requirement")
    verdict = "violated" if float(row[TWIN_COLUMN]) > 1 else "met"
    return (
        f"{requirement} {verdict}: {channel} {row.get('subset', '?')}, "
        f"t = {float(row.get('time [s]', math.nan)):.4g} s, "
        f"f = {float(row.get('frequency [Hz]', math.nan)):.4g} Hz; analysis "
        f"[{float(row.get('gain lower [-]', math.nan)):.4g}, "
        f"{float(row.get('gain upper [-]', math.nan)):.4g}]"
    )
