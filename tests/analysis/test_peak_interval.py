"""One interval per peak: [best certified lower bound, whole-axis guaranteed upper bound].

A reduced analysis input (a real gain in a third-order loop, four configurations, a coarse
grid), whose mu peak is known in closed form, goes through the analysis's certified sweep with
the whole-axis guarantee, the peak table and the printed summary.
"""

import control
import numpy as np

from oos_drake.analysis.models import ModelArray
from oos_drake.analysis.run import _certify
from oos_drake.analysis.stability import SweepOptions, certified_sweep
from oos_drake.app.analyze import peak_lines
from oos_drake.lfr import feedback, ureal, usubs

GAINS = np.array([0.8, 1.0, 1.2, 1.4])


def _array():
    """``k a / ((s+1)(s+2)(s+3))`` in unit feedback, ``k = 40 +- 10``: unstable from
    ``k a = 60`` (Routh), so ``mu = 10 / (60 / a - 40)`` per configuration (closed form)."""
    k = ureal("k", 40.0, plusminus=10.0)
    a = ureal("a", 1.0, range=(0.1, 2.0))
    loop = usubs(feedback(k * a * control.tf(1, [1, 6, 11, 6]), 1), {"a": GAINS})
    return ModelArray(loop, GAINS, "gain [-]", "mission")


def test_peak_interval_is_best_lower_and_guaranteed_upper():
    array = _array()
    omega = 2 * np.pi * np.geomspace(0.05, 5.0, 9)  # coarse: the grid misses sqrt(11) rad/s
    options = SweepOptions(n_jobs=1, converge_passes=1, converge_iterations=60)
    res = certified_sweep(
        array.system, omega, {"k": ["k"]}, times=GAINS, options=options, progress=False,
        guarantee=True,
    )  # fmt: skip
    rows, _, _ = _certify(array, res, {"k": ["k"]}, configuration_label=str)
    row = rows.iloc[0]
    exact = float(np.max(10.0 / (60.0 / GAINS - 40.0)))
    guaranteed = res.guarantees["k"].mu_upper
    # the interval: the guarantee's level (whole axis), never the grid's upper bound
    assert row["mu upper scope"] == "whole axis"
    np.testing.assert_allclose(row["mu upper [-]"], guaranteed, rtol=1e-12)
    assert row["mu lower [-]"] <= exact * (1 + 1e-9) <= row["mu upper [-]"] * (1 + 1e-9)
    np.testing.assert_allclose(row["mu lower [-]"], exact, rtol=5e-3)  # the best lower bound
    up, lo = row["mu upper [-]"], row["mu lower [-]"]
    np.testing.assert_allclose(row["gap [%]"], 100 * (up - lo) / up, rtol=1e-9)
    np.testing.assert_allclose(row["margin [-]"], 1.0 / guaranteed, rtol=1e-12)
    # the analyzed points' largest upper bound is kept beside it (here the grid alone, which
    # misses the crossing frequency, gives mu <= 0 on every point: a real parameter)
    assert row["mu upper grid [-]"] >= res.table["mu upper [-]"].max()
    # the printed line shows the same interval
    record = rows.drop(columns=["study"]).to_dict(orient="records")[0]
    summary = {
        "mission": {
            "mu_peak_upper": up,
            "mu_peak_upper_scope": row["mu upper scope"],
            "mu_peak_upper_grid": row["mu upper grid [-]"],
            "mu_peak_lower": lo,
            "gap_percent": row["gap [%]"],
            "peak_time_s": row["gain [-]"],
            "peak_frequency_hz": row["frequency [Hz]"],
            "upper_peak_time_s": row["peak gain [-]"],
            "upper_peak_frequency_hz": row["peak frequency [Hz]"],
            "stability_margin": row["margin [-]"],
        },
        "subsets": [{**record, "time [s]": record["gain [-]"]}],
        "docking": {},
    }
    lines = peak_lines(summary)
    assert f"<= {guaranteed:.4g} on the whole frequency axis" in lines[0]
    assert f"mu in [{lo:.4g}, {guaranteed:.4g}]" in lines[2]
    if not np.isclose(row["mu upper grid [-]"], guaranteed, rtol=1e-3):
        assert f"mu in [{lo:.4g}, {row['mu upper grid [-]']:.4g}]" not in lines[2]


def test_a_fallback_cover_is_named_in_the_printed_peaks():
    """A whole-axis bound proved by a fallback cover (its tight level did not close) says so on
    the mission's, the subset's and the docking phase's lines, and only where it happened."""
    from oos_drake.app.analyze import FELL_BACK

    peak = {"gap [%]": 1.0, "spikes left": 0, "spike stop": "resolved", "budget exhausted": False}
    subset = {
        **peak, "subset": "total", "time [s]": 10.0, "frequency [Hz]": 0.5, "mu lower [-]": 0.3,
        "mu upper [-]": 0.31, "mu upper scope": "whole axis", "mu upper grid [-]": 0.305,
    }  # fmt: skip
    docking = {
        **peak, "stiffness": 1e3, "frequency [Hz]": 0.2, "mu_lower": 0.2, "mu_upper": 0.21,
        "mu_upper_scope": "whole axis", "mu_upper_grid": 0.205,
    }  # fmt: skip
    mission = {
        "mu_peak_upper": 0.31, "mu_peak_upper_scope": "whole axis", "mu_peak_upper_grid": 0.305,
        "mu_peak_lower": 0.3, "gap_percent": 1.0, "peak_time_s": 10.0, "peak_frequency_hz": 0.5,
        "upper_peak_time_s": 10.0, "upper_peak_frequency_hz": 0.5, "stability_margin": 3.2,
    }  # fmt: skip

    def lines(fell_back: bool) -> list[str]:
        summary = {
            "mission": {**mission, "guarantee_fell_back": fell_back},
            "subsets": [{**subset, "guarantee fell back": fell_back}],
            "docking": {"7": {**docking, "guarantee_fell_back": fell_back}},
        }
        return peak_lines(summary)

    fell = lines(True)
    assert FELL_BACK in fell[0] and FELL_BACK in fell[2] and FELL_BACK in fell[3]
    assert not any(FELL_BACK in line for line in lines(False))
    # a summary written before the key existed reads as no fallback
    old = {"mission": mission, "subsets": [subset], "docking": {"7": docking}}
    assert not any(FELL_BACK in line for line in peak_lines(old))
