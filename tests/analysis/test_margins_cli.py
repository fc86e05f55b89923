"""``oos margins`` and the shared ``--sampled`` / ``--delay`` options of analyze and synth."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from oos_drake.analysis.margins import LOOPS
from oos_drake.app.main import build_parser, main


def _options(parser, path):
    for action in parser._actions:
        if (
            hasattr(action, "choices")
            and isinstance(action.choices, dict)
            and path[0] in action.choices
        ):
            sub = action.choices[path[0]]
            return _options(sub, path[1:]) if len(path) > 1 else sub
    raise KeyError(path)


def test_analyze_and_synth_share_the_loop_options():
    parser = build_parser()
    for command in ("analyze", "synth"):
        sub = _options(parser, (command,))
        shown = {o for a in sub._actions for o in a.option_strings}
        assert {"--sampled", "--delay"} <= shown, command


def test_delay_without_sampled_is_refused(tmp_path, capsys):
    status = main(["analyze", "--out", str(tmp_path / "a"), "--delay", "0.05", "--quiet"])
    assert status == 2
    assert "--delay needs --sampled" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


def test_margins_command_writes_the_table_and_figure(tmp_path):
    out = tmp_path / "margins"
    assert main(["margins", "--out", str(out), "--configurations", "1", "--quiet"]) == 0
    table = pd.read_parquet(out / "margins.parquet")
    assert set(table["loop"]) == set(LOOPS)
    assert len(table) == 3 * len(LOOPS)
    assert all("[" in c for c in table.columns if c not in ("loop", "channel"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["loop"]["sample_rate_hz"] == 10.0
    assert (out / "margins.png").stat().st_size > 10_000
    # the 10 Hz hold costs phase: about omega_c T / 2 at the crossover (a few degrees here)
    cont = table[table["loop"] == "continuous"].set_index("channel")
    samp = table[table["loop"] == "sampled"].set_index("channel")
    lag = np.degrees(2 * np.pi * cont["gain crossover [Hz]"] * 0.1 / 2)
    np.testing.assert_allclose(
        cont["phase margin [deg]"] - samp["phase margin [deg]"], lag, rtol=0.15
    )
    # the rational hold model reproduces the exact sampled margins
    model = table[table["loop"] == "sampled model"].set_index("channel")
    np.testing.assert_allclose(model["phase margin [deg]"], samp["phase margin [deg]"], atol=0.1)
    np.testing.assert_allclose(model["disk margin [-]"], samp["disk margin [-]"], rtol=0.01)


def test_margins_refuses_a_missing_analysis(tmp_path, capsys):
    status = main(["margins", "--out", str(tmp_path / "m"), "--analysis", str(tmp_path), "--quiet"])
    assert status == 2
    assert "no summary.json" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


def test_margins_follow_the_scenario(tmp_path):
    """``--scenario``: the plants (and the baseline PD tuned on them) are the scenario's; the
    summary names it. The heavy target moves the margins of the same command."""
    tables = {}
    for name in ("paper", "heavy_target"):
        out = tmp_path / name
        argv = ["margins", "--out", str(out), "--configurations", "1", "--quiet"]
        assert main([*argv, "--scenario", name]) == 0
        summary = json.loads((out / "summary.json").read_text())
        assert summary["scenario"].endswith(f"{name}.toml")
        tables[name] = pd.read_parquet(out / "margins.parquet")
    paper, heavy = (tables[n].set_index(["loop", "channel"]) for n in ("paper", "heavy_target"))
    assert not np.allclose(paper["disk margin [-]"], heavy["disk margin [-]"], rtol=1e-3)
