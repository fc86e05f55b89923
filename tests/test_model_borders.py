"""Which model types cross a package border (issue 34, "one model type at package borders"):
the inventory of ``docs/DESIGN.md`` (*Model types at package borders*), checked against the
sources.

Every module is read with :mod:`ast` (lazy imports inside functions included). A model type
crosses a border when a package other than its own imports it by name; a raw-matrix function
(public, taking ``A, Bw, Cz, Dzw`` or ``A, B, C, D``) when a package other than its own imports
it. ``LFR`` is the border type and may go anywhere; any other crossing must be listed below (and
in the design page): a new one fails this test.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "oos_drake"

#: The package's model types and the package defining each.
MODEL_TYPES = {
    "LFR": "lfr",
    "BatchedStateSpace": "control",
    "PlantArray": "control",
    "ModelArray": "analysis",
    "Realization": "robust",
}

#: Model types other than LFR imported by another package: (type, importing package).
CROSSINGS = {
    ("Realization", "analysis"),  # the whole-axis cover's worker tasks (analysis.stability)
}

#: Raw-matrix functions imported by another package: (function, importing package). Kernels
#: only, called on the batched matrices a kernel or a worker task already holds.
RAW_CROSSINGS = {
    ("peak_gain", "control"),  # the synthesis' H-infinity norm (kernel)
    ("sweep_models", "analysis"),  # the mu sweep's batched kernel input
    ("real_destabilizing", "analysis"),
    ("delta_channel_response", "analysis"),
}


@functools.cache
def _modules() -> tuple[tuple[str, ast.Module], ...]:
    """``(package, parsed module)`` of every module of the package."""
    modules = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        parts = path.relative_to(PACKAGE_DIR).parts
        package = parts[0] if len(parts) > 1 else "(top)"
        modules.append((package, ast.parse(path.read_text(encoding="utf-8"))))
    return tuple(modules)


def _raw_functions() -> dict[str, str]:
    """Public module-level functions taking raw state-space matrices -> their package."""
    found = {}
    for package, tree in _modules():
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
                names = {a.arg for a in node.args.args + node.args.kwonlyargs}
                if {"A", "Bw", "Cz", "Dzw"} <= names or {"A", "B", "C", "D"} <= names:
                    found[node.name] = package
    return found


def _imported_by_other_packages(names: dict[str, str]) -> set[tuple[str, str]]:
    crossings = set()
    for package, tree in _modules():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("oos_drake"):
                home = (node.module.split(".") + [""])[1]
                for alias in node.names:
                    if names.get(alias.name) == home and home != package:
                        crossings.add((alias.name, package))
    return crossings


def test_the_types_are_where_the_inventory_says():
    defined = {}
    for package, tree in _modules():
        for node in tree.body:
            if isinstance(node, ast.ClassDef) and node.name in MODEL_TYPES:
                defined[node.name] = package
    assert defined == MODEL_TYPES


def test_only_the_listed_model_types_cross_a_package_border():
    crossings = _imported_by_other_packages(MODEL_TYPES)
    assert {c for c in crossings if c[0] != "LFR"} == CROSSINGS
    assert {package for name, package in crossings if name == "LFR"} >= {"titop", "scenario"}


def test_only_the_listed_raw_matrix_functions_cross_a_package_border():
    assert _imported_by_other_packages(_raw_functions()) == RAW_CROSSINGS


def test_the_design_page_lists_every_crossing():
    page = (PACKAGE_DIR.parent / "docs" / "DESIGN.md").read_text(encoding="utf-8")
    section = page.split("### Model types at package borders", 1)[1].split("\n### ", 1)[0]
    for name, package in CROSSINGS | RAW_CROSSINGS:
        assert re.search(rf"\b{name}\b", section) and package in section, (name, package)


def test_one_connect():
    # one interconnection routine by signal name: control.statespace.connect
    found = [
        package
        for package, tree in _modules()
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name == "connect"
    ]
    assert found == ["control"]
