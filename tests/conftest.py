"""Shared pytest configuration: ``slow`` tests run only with ``--runslow`` or OOS_RUN_SLOW=1."""

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run tests marked slow")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """In CI (``CI`` set) a test skipped for a missing dependency fails: CI installs every test
    dependency, so such a skip would hide a broken install behind a green run."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and os.environ.get("CI") and isinstance(report.longrepr, tuple):
        reason = str(report.longrepr[2])
        if "could not import" in reason or "not installed" in reason:
            report.outcome = "failed"
            report.longrepr = f"missing test dependency in CI: {reason}"


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow") or os.environ.get("OOS_RUN_SLOW") == "1":
        return
    skip_slow = pytest.mark.skip(reason="slow: run with --runslow or OOS_RUN_SLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip_slow)


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory):
    """One ``oos run --quick`` from the command line, shared by the slow tests that read its
    results (CI time is tight: the run takes minutes).

    Returns
    -------
    types.SimpleNamespace
        ``out`` (the results folder), ``command`` (the argv) and ``result`` (the finished
        :class:`subprocess.CompletedProcess`, stdout and stderr captured).
    """
    out = tmp_path_factory.mktemp("quick-run") / "out"
    command = [sys.executable, "-m", "oos_drake.app.main", "run", "--out", str(out), "--quick"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=3000)
    return SimpleNamespace(out=out, command=command, result=result)


@pytest.fixture(scope="session")
def default_synthesis(tmp_path_factory):
    """``make run``'s controller stage on the paper (``oos synth``, default options: 200
    configurations), shared by the slow tests that read it (one such synthesis per session: CI
    time is tight).

    With ``OOS_HEADLINE_OUT=DIR`` (an existing ``make run`` output) its ``DIR/controller``.

    Returns
    -------
    pathlib.Path
        The folder holding ``controller.json``, ``closed_loop.npz``, ``models.parquet``, ...
    """
    from oos_drake.app.main import main

    existing = os.environ.get("OOS_HEADLINE_OUT")
    if existing:
        return Path(existing) / "controller"
    out = tmp_path_factory.mktemp("default-synthesis") / "controller"
    assert main(["synth", "--out", str(out)]) == 0
    return out


# Property tests draw new examples on every developer run; CI replays a fixed set (derandomized)
# so that a green CI means the same thing twice.
try:
    import hypothesis

    hypothesis.settings.register_profile("ci", derandomize=True, print_blob=True)
    if os.environ.get("CI"):
        hypothesis.settings.load_profile("ci")
except ImportError:  # pragma: no cover
    pass


@pytest.fixture(scope="session")
def paper_scenario():
    """The paper's scenario (``oos_drake/scenario/data/paper.toml``), passed explicitly: library
    functions take the scenario as a required argument (issue 34 item 3)."""
    from oos_drake.scenario.data import load_scenario

    return load_scenario("paper")
