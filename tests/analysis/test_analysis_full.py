"""The full analysis (330 configurations, 2 x 300 docking stiffnesses): slow."""

import numpy as np
import pandas as pd
import pytest

from oos_drake.analysis.cli import _controller
from oos_drake.analysis.run import AnalysisOptions, run_analysis


@pytest.mark.slow
def test_full_analysis(tmp_path):
    summary = run_analysis(
        _controller(None), tmp_path, AnalysisOptions(progress=False), log=lambda *_: None
    )
    m = summary["mission"]
    assert m["configurations"] == 330 and m["nominal_stable_models"] == 330
    assert 0 < m["mu_peak_lower"] <= m["mu_peak_upper"]
    peaks = pd.read_parquet(tmp_path / "stability_peaks.parquet")
    assert np.all(peaks["mu_lower"] <= peaks["mu_upper"] * (1 + 1e-9))
    # every certified peak (mission subsets, docking phases): bounds within 5 %, no spike left
    for _, row in peaks.iterrows():
        assert row["gap [%]"] < 5.0, (row["study"], row["subset"], row["gap [%]"])
        assert row["spikes_left"] == 0, (row["study"], row["subset"])
    docking = pd.read_parquet(tmp_path / "docking_7.parquet")
    assert docking["model"].nunique() == 300
    assert summary["timings_s"]["total"] > 0
