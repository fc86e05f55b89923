"""Architecture contract: the math core never imports pydrake (fast to import, testable alone)."""

import subprocess
import sys

import pytest

CORE_PACKAGES = ("oos_drake.lfr", "oos_drake.titop", "oos_drake.robust", "oos_drake.control")


@pytest.mark.parametrize("package", CORE_PACKAGES)
def test_core_package_does_not_import_pydrake(package):
    code = (
        "import importlib, pkgutil, sys\n"
        f"pkg = importlib.import_module('{package}')\n"
        "for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
        "    if not info.name.endswith('.cli'):\n"
        "        importlib.import_module(info.name)\n"
        "print('pydrake' in sys.modules)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "False", f"{package} imports pydrake"


def test_cli_help_lists_commands():
    result = subprocess.run(
        [sys.executable, "-m", "oos_drake.cli", "--help"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "usage: oos" in result.stdout
