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
    # single full block / independent complex scalars: bounds meet
    for subset in ("additive", "multiplicative"):
        row = peaks[(peaks["study"] == "mission") & (peaks["subset"] == subset)].iloc[0]
        assert row["gap [%]"] < 5.0, subset
    docking = pd.read_parquet(tmp_path / "docking_7.parquet")
    assert docking["model"].nunique() == 300
    assert summary["timings_s"]["total"] > 0
