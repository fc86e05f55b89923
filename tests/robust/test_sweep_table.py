"""The one mu sweep table: schema and the names of tables written before it."""

import re

import numpy as np
import pandas as pd
import pytest

from oos_drake.robust.tables import (
    GUARANTEE_COLUMNS,
    LEGACY_COLUMNS,
    SWEEP_COLUMNS,
    sweep_table,
    upgrade_columns,
)


def test_every_column_follows_the_name_unit_convention():
    labels = {"subset", "model", "refined", "tightened", "guarantee points", "covered", "reason"}
    labels |= {  # the analysis tables' labels and counts (stability_peaks.parquet)
        "peak model",
        "lower source",
        "spike rounds",
        "spikes left",
        "spikes converged",
        "refinement points",
        "searched models",
        "spike stop",
        "budget exhausted",
        "guarantee solved points",
        "guarantee raised configurations",
        "guarantee failures",
        "guarantee fell back",
        "guarantee scope",
    }
    unit = re.compile(r"^[a-z][a-z ]*[a-z] \[[^\[\]]+\]$")
    for col in SWEEP_COLUMNS + GUARANTEE_COLUMNS:
        assert col in labels or unit.match(col), col
    for old, new in LEGACY_COLUMNS.items():
        assert (new in labels or unit.match(new)) and not unit.match(old), (old, new)
        assert "_" not in new, new


def test_sweep_table_builds_the_schema_and_converts_to_hz():
    t = sweep_table(
        subset="total",
        model=[1, 0, 0],
        time=12.0,
        omega=[2 * np.pi, 4 * np.pi, 2 * np.pi],
        upper=3.0,
        lower=[1, 2, 3],
    )
    assert list(t.columns) == SWEEP_COLUMNS
    assert t["frequency [Hz]"].tolist() == [1.0, 2.0, 1.0]  # sorted by model, then frequency
    assert t["model"].tolist() == [0, 0, 1]
    assert t["mu lower [-]"].tolist() == [3.0, 2.0, 1.0]
    g = sweep_table(
        subset="s",
        model=0,
        time=np.nan,
        omega=[1.0],
        upper=1.0,
        lower=0.5,
        guaranteed=1.1,
        guarantee_points=7,
    )
    assert list(g.columns) == SWEEP_COLUMNS + GUARANTEE_COLUMNS
    assert g["guarantee points"].iloc[0] == 7


def test_old_tables_are_renamed_and_mixed_ones_refused():
    old = pd.DataFrame({"model": [0], "time": [1.0], "frequency": [0.5], "mu_upper": [0.4]})
    new = upgrade_columns(old)
    assert list(new.columns) == ["model", "time [s]", "frequency [Hz]", "mu upper [-]"]
    assert upgrade_columns(new) is new
    with pytest.raises(ValueError, match="mu_upper"):
        upgrade_columns(old.assign(**{"mu upper [-]": [0.4]}))
