"""Package data: every data file of the package is shipped and found without the repository."""

from __future__ import annotations

import fnmatch
import os
import subprocess
import sys
import tomllib
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "oos_drake"
#: Files that are build products, not data (compiled numba kernels, bytecode).
NOT_DATA = ("*.py", "*.pyc", "*.nbi", "*.nbc")


def test_every_data_file_matches_a_package_data_pattern():
    pyproject = tomllib.loads((PACKAGE_DIR.parent / "pyproject.toml").read_text())
    patterns = pyproject["tool"]["setuptools"]["package-data"]["oos_drake"]
    suffixes = [p.removeprefix("**/") for p in patterns]
    data = [
        p
        for p in PACKAGE_DIR.rglob("*")
        if p.is_file()
        and "__pycache__" not in p.parts
        and not any(fnmatch.fnmatch(p.name, n) for n in NOT_DATA)
    ]
    assert data, "no data file found"
    unshipped = [str(p) for p in data if not any(fnmatch.fnmatch(p.name, s) for s in suffixes)]
    assert not unshipped, f"not in [tool.setuptools.package-data]: {unshipped}"


def test_data_is_found_from_another_directory(tmp_path):
    """The scenario, the SDF folder and the shipped specs, with the working directory elsewhere."""
    code = (
        "from oos_drake.scenario.data import DEFAULT_SCENARIO_PATH\n"
        "from oos_drake.multibody.scenario_sdf import SDF_DIRECTORY, ASSEMBLY_FILE\n"
        "from oos_drake.campaign.spec import load_spec, packaged_spec_names\n"
        "assert DEFAULT_SCENARIO_PATH.is_file()\n"
        "assert (SDF_DIRECTORY / ASSEMBLY_FILE).is_file()\n"
        "print(packaged_spec_names(), load_spec('demo').name)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(PACKAGE_DIR.parent))
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split("]")[-1].strip() == "demo"
    assert "'paper'" in result.stdout
