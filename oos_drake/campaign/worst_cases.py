"""The ``worst_cases.parquet`` file: where the mu analysis says the danger is.

The robust analysis writes it (``oos analyze``); the ``mu-guided`` campaign sampler draws around
its regions, and every sampler takes from it the frequencies at which a simulator realizes its
LTI perturbation blocks (:func:`oos_drake.campaign.samplers.make_plan`). One row per critical
*region* (a configuration / time of the mission at which a worst case was found). No worst-case
file of the Drake mission ships with the package: it must come from our own analysis.

Schema
------

=========================  =======  ==========================================================
column                     dtype    meaning
=========================  =======  ==========================================================
``region``                 int64    region id, unique (>= 0)
``configuration``          string   configuration label (``"capture"``, ``"docked-2"``, ...)
``time [s]``               float64  critical mission time [s] (>= 0)
``frequency [Hz]``         float64  critical frequency of the mu peak [Hz] (>= 0)
``mu upper [-]``           float64  upper bound of mu at the peak [-]
``mu lower [-]``           float64  lower bound of mu at the peak [-] (<= ``mu upper [-]``)
``subset``                 string   the uncertain blocks analyzed, comma-separated
``wc:<block> [<unit>]``    float64  worst-case value of the named block, PHYSICAL units
``wcgain:<metric> lower``  float64  optional: worst-case gain of the performance channel whose
``[-]`` / ``upper [-]``             unit gain is the requirement on campaign metric
                                    ``<metric>``, over the region's subset at its
                                    configuration (lower: gain of a perturbation found; upper:
                                    largest upper bound over the analysis' frequency grid)
=========================  =======  ==========================================================

A ``wc:`` column may be NaN in a row whose subset does not contain the block (the sampler then
leaves that block at its nominal dispersion for that region). ``<block>`` must be a parameter of the
campaign's simulator and ``<unit>`` its unit (checked by :func:`read_worst_cases`). For an LTI
block (``Delta_add``, ``Delta_mul``) the value is the scalar that scales the stable realization of
the worst-case perturbation (the simulator parameter of kind ``lti``).

Example::

    region configuration time [s] frequency [Hz] mu upper [-] mu lower [-] subset  wc:J_hub [kg m^2]
    0      capture       100.0    0.21           1.31         1.27         J_hub,k_dock 262.0

Files written before the ``name [unit]`` convention (``mu_upper``, ``mu_lower``) are read with
their columns renamed (:data:`oos_drake.robust.tables.LEGACY_COLUMNS`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.campaign.simulator import Parameter

#: Fixed columns and their pandas dtype kinds ("i" integer, "f" float, "O"/"U" string).
BASE_COLUMNS: dict[str, str] = {
    "region": "int64",
    "configuration": "string",
    "time [s]": "float64",
    "frequency [Hz]": "float64",
    "mu upper [-]": "float64",
    "mu lower [-]": "float64",
    "subset": "string",
}

_WC_COLUMN = re.compile(r"^wc:(?P<name>[^\s\[\]]+) \[(?P<unit>[^\]]*)\]$")
_GAIN_COLUMN = re.compile(r"^wcgain:(?P<metric>[^\s\[\]]+) (?P<bound>lower|upper) \[-\]$")


def gain_column(metric: str, bound: str) -> str:
    """Column of a worst-case gain bound, e.g. ``"wcgain:ape upper [-]"``."""
    return f"wcgain:{metric} {bound} [-]"


@dataclass(frozen=True)
class WorstCaseRegion:
    """One critical region of the analysis.

    Attributes
    ----------
    region : int
        Region id.
    configuration : str
        Configuration label.
    time : float
        Critical mission time [s].
    frequency : float
        Critical frequency [Hz].
    mu_upper, mu_lower : float
        Bounds of mu at the peak [-].
    subset : str
        Blocks analyzed (comma-separated).
    perturbation : Mapping[str, float]
        Worst-case block values in physical units (only the blocks given for this region).
    gains : Mapping[str, tuple of float]
        Campaign metric -> ``(lower, upper)`` worst-case gain of the performance channel that
        bounds it, normalized so that 1 is the requirement [-] (empty when not computed).
    """

    region: int
    configuration: str
    time: float
    frequency: float
    mu_upper: float
    mu_lower: float
    subset: str
    perturbation: Mapping[str, float]
    gains: Mapping[str, tuple[float, float]] = field(default_factory=dict)


def worst_case_column(parameter: Parameter) -> str:
    """Column name of a parameter's worst-case value, e.g. ``"wc:J_hub [kg m^2]"``."""
    return f"wc:{parameter.name} [{parameter.unit}]"


def worst_cases_table(
    regions: Sequence[WorstCaseRegion], parameters: Sequence[Parameter]
) -> pd.DataFrame:
    """The regions as a table in the schema above (one row per region).

    Raises
    ------
    ValueError
        A region's perturbation names a block that is not in ``parameters``.
    """
    by_name = {p.name: p for p in parameters}
    names = sorted({n for r in regions for n in r.perturbation})
    for name in names:
        if name not in by_name:
            raise ValueError(f"worst cases: unknown block {name!r}")
    table = pd.DataFrame(
        {
            "region": pd.array([r.region for r in regions], dtype="int64"),
            "configuration": pd.array([r.configuration for r in regions], dtype="string"),
            "time [s]": [float(r.time) for r in regions],
            "frequency [Hz]": [float(r.frequency) for r in regions],
            "mu upper [-]": [float(r.mu_upper) for r in regions],
            "mu lower [-]": [float(r.mu_lower) for r in regions],
            "subset": pd.array([r.subset for r in regions], dtype="string"),
        }
    )
    for name in names:
        table[worst_case_column(by_name[name])] = [
            float(r.perturbation.get(name, np.nan)) for r in regions
        ]
    for metric in sorted({m for r in regions for m in r.gains}):
        for index, bound in enumerate(("lower", "upper")):
            table[gain_column(metric, bound)] = [
                float(r.gains[metric][index]) if metric in r.gains else np.nan for r in regions
            ]
    return table


def write_worst_cases(
    regions: Sequence[WorstCaseRegion], parameters: Sequence[Parameter], path: str | Path
) -> Path:
    """Write :func:`worst_cases_table` of the regions to ``path`` (atomically: temp file +
    rename)."""
    from oos_drake.files import atomic_write_parquet

    return atomic_write_parquet(worst_cases_table(regions, parameters), Path(path))


def read_worst_cases(
    path: str | Path, parameters: Sequence[Parameter]
) -> tuple[WorstCaseRegion, ...]:
    """Read and validate a ``worst_cases.parquet`` against the simulator's parameters.

    Raises
    ------
    ValueError
        Missing file, missing column, unknown block or unit mismatch, duplicated region ids,
        ``mu_lower > mu_upper``, negative time, or a worst-case value outside the block's range.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"worst cases file {path} not found (written by oos analyze)")
    from oos_drake.campaign.store import read_table

    table = read_table(path, BASE_COLUMNS, f"worst cases file {path}", legacy=True)
    if table.empty:
        raise ValueError(f"worst cases file {path}: no region")
    by_name = {p.name: p for p in parameters}
    blocks: dict[str, str] = {}
    gain_columns: dict[str, tuple[str, str]] = {}
    for column in table.columns:
        if column in BASE_COLUMNS:
            continue
        gain = _GAIN_COLUMN.match(column)
        if gain:
            gain_columns[gain["metric"]] = (
                gain_column(gain["metric"], "lower"),
                gain_column(gain["metric"], "upper"),
            )
            continue
        match = _WC_COLUMN.match(column)
        if not match:
            raise ValueError(
                f"worst cases file {path}: unexpected column {column!r} "
                "(perturbations are 'wc:<block> [<unit>]', gains 'wcgain:<metric> "
                "lower|upper [-]')"
            )
        name, unit = match["name"], match["unit"]
        if name not in by_name:
            raise ValueError(
                f"worst cases file {path}: unknown block {name!r} in {column!r}; "
                f"known: {', '.join(by_name)}"
            )
        if unit != by_name[name].unit:
            raise ValueError(
                f"worst cases file {path}: {column!r} has unit {unit!r}, "
                f"block {name} is in {by_name[name].unit!r}"
            )
        blocks[name] = column
    if table["region"].duplicated().any():
        raise ValueError(f"worst cases file {path}: duplicated region ids")
    if (table["region"] < 0).any():
        raise ValueError(
            f"worst cases file {path}: region ids must be >= 0 (-1 marks nominal runs)"
        )
    regions = []
    for row in table.itertuples(index=False):
        record = dict(zip(table.columns, row, strict=True))
        region = int(record["region"])
        where = f"worst cases file {path}: region {region}"
        mu_upper, mu_lower = float(record["mu upper [-]"]), float(record["mu lower [-]"])
        if not (np.isfinite(mu_upper) and np.isfinite(mu_lower)) or mu_lower > mu_upper * (
            1 + 1e-9
        ):
            raise ValueError(f"{where}: mu_lower {mu_lower} must be <= mu_upper {mu_upper}")
        time = float(record["time [s]"])
        if not (np.isfinite(time) and time >= 0):
            raise ValueError(f"{where}: time {time} s must be finite and >= 0")
        perturbation = {}
        for name, column in blocks.items():
            value = float(record[column])
            if np.isnan(value):
                continue
            parameter = by_name[name]
            # a vertex of the uncertainty box may miss its bound by round-off (Parameter.clip)
            clipped = parameter.clip(value)
            if clipped is None:
                raise ValueError(
                    f"{where}: {column} = {value:g} outside the range of {name} "
                    f"[{parameter.lower:g}, {parameter.upper:g}]"
                )
            perturbation[name] = clipped
        gains = {}
        for metric, (low_column, high_column) in gain_columns.items():
            if low_column not in table.columns or high_column not in table.columns:
                raise ValueError(
                    f"worst cases file {path}: {metric} needs both {low_column!r} and "
                    f"{high_column!r}"
                )
            low, high = float(record[low_column]), float(record[high_column])
            if np.isnan(low) and np.isnan(high):
                continue
            if not low <= high * (1 + 1e-9):
                raise ValueError(f"{where}: {low_column} {low} exceeds {high_column} {high}")
            gains[metric] = (low, high)
        regions.append(
            WorstCaseRegion(
                region=region,
                configuration=str(record["configuration"]),
                time=time,
                frequency=float(record["frequency [Hz]"]),
                mu_upper=mu_upper,
                mu_lower=mu_lower,
                subset=str(record["subset"]),
                perturbation=perturbation,
                gains=gains,
            )
        )
    return tuple(regions)
