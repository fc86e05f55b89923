"""Reading the worst-case gains of an analysis folder (``oos confirm``'s performance cases).

A folder written before the ``name [unit]`` column convention (``gain_lower [-]``) must give
the same cases as today's names; a table without a needed column is refused in one line
naming the file and the column (it used to stop ``oos confirm`` with a bare ``gain lower [-]``).
"""

import math

import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.performance_twin import read_gain_cases


def _table(names: dict[str, str]) -> pd.DataFrame:
    table = pd.DataFrame(
        {
            "channel": ["e_p", "e_p", "e_u", "e_p"],
            "subset": ["total", "total", "total", "real"],
            "model": [0, 1, 0, 0],
            "time [s]": [10.0, 20.0, 10.0, 30.0],
            "frequency [Hz]": [0.1, 0.2, 0.3, 0.4],
            "gain nominal [-]": [0.5, 0.6, 0.2, 0.3],
            "gain lower [-]": [0.9, 1.2, 0.4, np.inf],
            "gain upper [-]": [0.95, 1.25, 0.41, np.inf],
        }
    )
    return table.rename(columns=names)


OLD = {
    "gain nominal [-]": "gain_nominal [-]",
    "gain lower [-]": "gain_lower [-]",
    "gain upper [-]": "gain_upper [-]",
}


def test_an_old_folder_gives_the_same_cases_as_todays(tmp_path):
    (tmp_path / "old").mkdir()
    (tmp_path / "new").mkdir()
    _table(OLD).to_parquet(tmp_path / "old" / "performance.parquet")
    _table({}).to_parquet(tmp_path / "new" / "performance.parquet")
    old = read_gain_cases(tmp_path / "old")
    assert old == read_gain_cases(tmp_path / "new")
    # the largest finite lower bound per channel and subset; the infinite one is a stability case
    assert [(c.channel, c.subset, c.time, c.lower) for c in old] == [
        ("e_p", "total", 20.0, 1.2),
        ("e_u", "total", 10.0, 0.4),
    ]
    assert math.isclose(old[0].omega, 2 * math.pi * 0.2)


def test_a_table_without_a_needed_column_is_refused_naming_it(tmp_path):
    _table({}).drop(columns="gain upper [-]").to_parquet(tmp_path / "performance.parquet")
    with pytest.raises(ValueError, match=r"performance\.parquet: missing column\(s\) gain upper"):
        read_gain_cases(tmp_path)


def test_no_performance_table_no_cases(tmp_path):
    assert read_gain_cases(tmp_path) == []
