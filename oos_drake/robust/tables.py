"""The mu sweep table: one schema for every sweep of the package, ``name [unit]`` columns.

:func:`~oos_drake.robust.sweep.robust_sweep`, the analysis's sweeps (``mu_mission.parquet``,
``docking_<phase>.parquet``), :meth:`RobStabResult.table
<oos_drake.robust.robstab.RobStabResult.table>` and ``oos robust robstab --out`` all build their
table with :func:`sweep_table`. Tables written before this convention (``time``, ``frequency``,
``mu_upper``, ...) are read back through :func:`upgrade_columns`.
"""

from __future__ import annotations

import numpy as np

from oos_drake.columns import CONVERTED, RENAMED

#: Columns of every mu sweep table of the package (see the module docstring): ``name [unit]``
#: for quantities, ``[-]`` when dimensionless; labels, indices and flags carry no unit.
#: Frequencies are in Hz (the scenario, the figures and the campaign regions speak Hz; function
#: arguments stay in rad/s, as in MATLAB).
SWEEP_COLUMNS = [
    "subset",
    "model",
    "time [s]",
    "frequency [Hz]",
    "mu lower [-]",
    "mu upper [-]",
    "refined",
    "tightened",
]
#: Extra columns when the peak over the whole frequency axis is proved (``guaranteed=True``),
#: the same values on every row of a model and subset: the bound (``inf`` where the cover did not
#: close), the frequencies solved for the proof, whether the cover closed and, if not, why.
GUARANTEE_COLUMNS = ["mu upper guaranteed [-]", "guarantee points", "covered", "reason"]
#: Names used by tables written before the ``name [unit]`` convention (words separated by
#: spaces, never underscores) -> current names: the sweep tables, the analysis' tables
#: (``stability_peaks.parquet`` and its siblings) and ``worst_cases.parquet`` of older result
#: folders (:func:`upgrade_columns` renames them when such a folder is read).
_SWEEP_LEGACY = {
    "time": "time [s]",
    "frequency": "frequency [Hz]",
    "mu_upper": "mu upper [-]",
    "mu_lower": "mu lower [-]",
    "mu_upper_guaranteed": "mu upper guaranteed [-]",
    "mu_upper_at_critical": "mu upper at critical [-]",
    "mu_upper_grid": "mu upper grid [-]",
    "guarantee_points": "guarantee points",
}
#: Every old name -> current name: the sweep's and :data:`oos_drake.columns.RENAMED` (the
#: analysis' and the campaign's tables), pure renames only.
LEGACY_COLUMNS = {
    **_SWEEP_LEGACY,
    **{old: new for old, new in RENAMED.items() if old not in CONVERTED},
}


def upgrade_columns(table, legacy: dict | None = None):
    """``table`` with the pre-``name [unit]`` column names of ``legacy`` renamed.

    Parameters
    ----------
    table : pandas.DataFrame
        A table read from a result folder, old or new.
    legacy : dict, optional
        Old name -> new name (default :data:`LEGACY_COLUMNS`).

    Returns
    -------
    pandas.DataFrame
        ``table`` itself when nothing needs a rename, else a renamed copy.

    Raises
    ------
    ValueError
        If a table holds both an old name and its new name (mixed schemas).
    """
    legacy = LEGACY_COLUMNS if legacy is None else legacy
    rename = {old: new for old, new in legacy.items() if old in table.columns}
    both = [old for old, new in rename.items() if new in table.columns]
    if both:
        raise ValueError(f"table has both old and new column names: {both}")
    return table.rename(columns=rename) if rename else table


def sweep_table(
    *,
    subset,
    model,
    time,
    omega,
    upper,
    lower,
    refined=False,
    tightened=True,
    guaranteed=None,
    guarantee_points=None,
    covered=True,
    reason="",
):
    """The mu sweep table (:data:`SWEEP_COLUMNS`) from per-point arrays, sorted.

    Parameters
    ----------
    subset : str or array_like of str
        Uncertainty subset of each point.
    model : int or array_like of int
        Index of the model in the model array.
    time : float or array_like
        Mission time [s] (or scheduling value) of each point's model; NaN when unknown.
    omega : array_like
        Frequencies [rad/s] (stored in Hz).
    upper, lower : array_like
        Bounds of mu [-] at each point.
    refined, tightened : bool or array_like of bool
        Peak-refinement point; full-accuracy bounds.
    guaranteed : float or array_like, optional
        Peak of mu proved on the whole frequency axis [-] (adds :data:`GUARANTEE_COLUMNS`).
    guarantee_points : int or array_like, optional
        Frequencies solved for that proof.
    covered : bool or array_like of bool
        The proof covers the whole axis (with ``guaranteed``).
    reason : str or array_like of str
        Why not, where ``covered`` is False (empty otherwise).

    Returns
    -------
    pandas.DataFrame
        Sorted by subset, model and frequency.
    """
    import pandas as pd

    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    n = omega.size

    def full(x, dtype=None):
        return np.broadcast_to(np.asarray(x, dtype=dtype), (n,)).copy()

    data = {
        "subset": full(subset, object),
        "model": full(model, int),
        "time [s]": full(time, float),
        "frequency [Hz]": omega / (2 * np.pi),
        "mu lower [-]": full(lower, float),
        "mu upper [-]": full(upper, float),
        "refined": full(refined, bool),
        "tightened": full(tightened, bool),
    }
    if guaranteed is not None:
        data["mu upper guaranteed [-]"] = full(guaranteed, float)
        data["guarantee points"] = full(0 if guarantee_points is None else guarantee_points, int)
        data["covered"] = full(covered, bool)
        data["reason"] = full(reason, object)
    table = pd.DataFrame(data)
    return table.sort_values(
        ["subset", "model", "frequency [Hz]"], ignore_index=True, kind="stable"
    )
