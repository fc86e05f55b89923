"""Architecture contract.

- The math core never imports pydrake (fast to import, testable alone).
- Layers only point down. Every module's imports are read with :mod:`ast` (lazy imports inside
  functions included, and ``importlib.import_module("literal")`` calls), each module is mapped to
  a layer, and an import of a higher layer, or an import between two different packages of the
  same layer, fails the test. The package graph must also be free of cycles.

Layer order (low to high) and why:

``base`` (``oos_drake`` itself, ``blas``, ``resources``) < ``processes`` < ``lfr`` < ``titop`` <
``scenario`` < ``robust`` < ``control`` < ``multibody`` < ``campaign`` < ``analysis`` < ``report``
< ``app``.

- ``report``: reads the results folder every stage wrote (the top floor below the commands).

- ``robust`` below ``control``: the synthesis may reuse the mu and H-infinity machinery; the
  robustness analysis never needs a controller design.
- ``campaign`` below ``analysis``: the campaign is the generic Monte Carlo machinery (spec,
  samplers, runner, executors, tables, the ``worst_cases.parquet`` schema); the mission analysis
  writes its critical regions in that schema and may run its work on the campaign's executors.
- ``app``: ``oos_drake.app`` (the ``oos`` command modules and the ``oos run`` pipeline): the
  command line sits on top of everything, so a command module may use any layer
  (``app.synth`` builds Drake plants for ``oos synth --plant drake``).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

CORE_PACKAGES = ("oos_drake.lfr", "oos_drake.titop", "oos_drake.robust", "oos_drake.control")

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "oos_drake"

#: Layers from the bottom; a module may import its own package and lower layers only.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("oos_drake", "oos_drake.blas", "oos_drake.columns", "oos_drake.files", "oos_drake.resources"),
    ("oos_drake.processes",),
    ("oos_drake.lfr",),
    ("oos_drake.titop",),
    ("oos_drake.scenario",),
    ("oos_drake.robust",),
    ("oos_drake.control",),
    ("oos_drake.multibody",),
    ("oos_drake.campaign",),
    ("oos_drake.analysis",),
    ("oos_drake.report",),
    ("oos_drake.app",),
)


@pytest.mark.parametrize("package", CORE_PACKAGES)
def test_core_package_does_not_import_pydrake(package):
    code = (
        "import importlib, pkgutil, sys\n"
        f"pkg = importlib.import_module('{package}')\n"
        "for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
        "    importlib.import_module(info.name)\n"
        "print('pydrake' in sys.modules)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "False", f"{package} imports pydrake"


def test_cli_help_lists_commands():
    result = subprocess.run(
        [sys.executable, "-m", "oos_drake.app.main", "--help"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "usage: oos" in result.stdout


# --- layers ------------------------------------------------------------------------------------


def module_name(path: Path, package_dir: Path) -> str:
    """Dotted module name of ``path`` inside the package rooted at ``package_dir``."""
    parts = list(path.relative_to(package_dir.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_modules(path: Path, package_dir: Path) -> list[tuple[str, int]]:
    """``(module, line)`` of every ``oos_drake`` import in ``path``, lazy ones included.

    ``from pkg import name`` counts as an import of ``pkg.name`` when that is a module, else of
    ``pkg``; relative imports are resolved; ``importlib.import_module("oos_drake...")`` counts.
    """
    name = module_name(path, package_dir)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    root = package_dir.name
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                candidate = f"{target}.{alias.name}"
                if _module_path(candidate, package_dir) is not None:
                    found.append((candidate, node.lineno))
                else:
                    found.append((target, node.lineno))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.append((node.args[0].value, node.lineno))
    return sorted({(m, line) for m, line in found if m == root or m.startswith(root + ".")})


def _module_path(module: str, package_dir: Path) -> Path | None:
    relative = Path(*module.split(".")[1:])
    for candidate in (package_dir / relative / "__init__.py", package_dir / f"{relative}.py"):
        if candidate.is_file():
            return candidate
    return None


def unit_of(module: str) -> str:
    """The layered unit a module belongs to: its package, or a top-level module."""
    parts = module.split(".")
    if len(parts) == 1:
        return module
    return ".".join(parts[:2])


def layer_of(module: str, layers=LAYERS) -> int:
    """Index of the layer of ``module`` in ``layers``."""
    unit = unit_of(module)
    for index, members in enumerate(layers):
        if unit in members:
            return index
    raise AssertionError(f"module {module} is in no layer: add its package to LAYERS")


def import_graph(package_dir: Path) -> dict[str, list[tuple[str, str, int]]]:
    """``unit -> [(importing module, imported module, line)]`` over every module of the package."""
    graph: dict[str, list[tuple[str, str, int]]] = {}
    for path in sorted(package_dir.rglob("*.py")):
        source = module_name(path, package_dir)
        graph.setdefault(unit_of(source), [])
        for target, line in imported_modules(path, package_dir):
            graph[unit_of(source)].append((source, target, line))
    return graph


def layer_violations(package_dir: Path, layers=LAYERS) -> list[str]:
    """Every import that points up, or sideways between two packages of one layer."""
    bad = []
    for edges in import_graph(package_dir).values():
        for source, target, line in edges:
            if unit_of(source) == unit_of(target) or unit_of(target) == "oos_drake":
                continue
            low, high = layer_of(target, layers), layer_of(source, layers)
            if low > high or (low == high and high != len(layers) - 1):
                bad.append(f"{source} (line {line}, layer {high}) imports {target} (layer {low})")
    return bad


def package_cycles(package_dir: Path) -> list[list[str]]:
    """Cycles of the unit graph (a unit: a package, or a top-level module)."""
    graph = {
        unit: sorted({unit_of(t) for _, t, _ in edges} - {unit})
        for unit, edges in import_graph(package_dir).items()
    }
    cycles, state, stack = [], {}, []

    def visit(unit):
        state[unit] = "open"
        stack.append(unit)
        for nxt in graph.get(unit, ()):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[unit] = "done"

    for unit in sorted(graph):
        if unit not in state:
            visit(unit)
    return cycles


def test_every_module_is_in_a_layer():
    for path in PACKAGE_DIR.rglob("*.py"):
        layer_of(module_name(path, PACKAGE_DIR))


def test_imports_only_point_down():
    bad = layer_violations(PACKAGE_DIR)
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_the_library_imports_nothing_from_the_application_floor():
    """``oos_drake.app`` is the top floor: no module outside it imports it (lazily or not)."""
    bad = [
        f"{source} (line {line}) imports {target}"
        for edges in import_graph(PACKAGE_DIR).values()
        for source, target, line in edges
        if unit_of(target) == "oos_drake.app" and unit_of(source) != "oos_drake.app"
    ]
    assert LAYERS[-1] == ("oos_drake.app",)
    assert not bad, "library modules import the application floor:\n" + "\n".join(bad)


def test_no_import_cycle_between_packages():
    cycles = package_cycles(PACKAGE_DIR)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def _fake_package(tmp_path, files):
    package_dir = tmp_path / "oos_drake"
    for relative, text in files.items():
        path = package_dir / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return package_dir


def test_checker_sees_lazy_relative_and_dynamic_upward_imports(tmp_path):
    """The checker itself: each kind of upward import, hidden or not, is reported."""
    package_dir = _fake_package(
        tmp_path,
        {
            "__init__.py": "",
            "lfr/__init__.py": "",
            "lfr/core.py": "def f():\n    from oos_drake.robust import mu\n",
            "lfr/other.py": "from ..campaign import store\n",
            "lfr/third.py": "import importlib\nimportlib.import_module('oos_drake.analysis.run')\n",
            "lfr/fourth.py": "def main():\n    from oos_drake.app.robust import register\n",
            "robust/__init__.py": "",
            "robust/mu.py": "from oos_drake.lfr import core\n",
            "app/__init__.py": "",
            "app/robust.py": "from oos_drake.analysis import run\n",
            "campaign/__init__.py": "",
            "campaign/store.py": "",
            "analysis/__init__.py": "",
            "analysis/run.py": "import oos_drake.campaign.store\n",
        },
    )
    bad = layer_violations(package_dir)
    assert len(bad) == 4, bad
    assert any("oos_drake.lfr.core" in b and "oos_drake.robust.mu" in b for b in bad)
    assert any("oos_drake.lfr.other" in b and "oos_drake.campaign.store" in b for b in bad)
    assert any("oos_drake.lfr.third" in b and "oos_drake.analysis.run" in b for b in bad)
    assert any("oos_drake.lfr.fourth" in b and "oos_drake.app.robust" in b for b in bad)
    assert package_cycles(package_dir) == [["oos_drake.lfr", "oos_drake.robust", "oos_drake.lfr"]]
