"""The main job's stage mechanics: skipped when up to date, atomic on failure, timed."""

import json
import subprocess
import sys

import pytest

from oos_drake.pipeline import STAMP, run_stage, source_key


def _writer(text, calls):
    def work(folder):
        calls.append(folder)
        (folder / "result.txt").write_text(text)

    return work


def test_stage_runs_once_per_key_and_records_its_time(tmp_path):
    calls, timings = [], {}
    folder = tmp_path / "stage"
    assert run_stage("demo", folder, "key-1", _writer("a", calls), timings)
    assert (folder / "result.txt").read_text() == "a"
    assert json.loads((folder / STAMP).read_text())["key"] == "key-1"
    assert timings["demo"] >= 0.0

    assert not run_stage("demo", folder, "key-1", _writer("b", calls), timings)
    assert len(calls) == 1 and timings["demo"] is None
    assert (folder / "result.txt").read_text() == "a"

    assert run_stage("demo", folder, "key-2", _writer("c", calls), timings)
    assert (folder / "result.txt").read_text() == "c"


def test_failed_stage_keeps_the_previous_result(tmp_path):
    folder = tmp_path / "stage"
    run_stage("demo", folder, "key-1", _writer("good", []))

    def crash(tmp):
        (tmp / "result.txt").write_text("half")
        raise RuntimeError("killed")

    with pytest.raises(RuntimeError):
        run_stage("demo", folder, "key-2", crash)
    assert (folder / "result.txt").read_text() == "good"
    assert json.loads((folder / STAMP).read_text())["key"] == "key-1"


def test_source_key_depends_on_the_packages():
    assert source_key("lfr") == source_key("lfr")
    assert source_key("lfr") != source_key("lfr", "titop")


def test_missing_campaign_spec_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "oos_drake.cli", "run", "--out", str(out), "--campaign", "no.toml"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2
    assert "no.toml" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()
