"""Project conventions of docs/DESIGN.md and README.md that cut across packages.

- D3: ``oos --help`` lists every command and every command sets ``func``.
- D6: no global RNG in ``oos_drake/`` (AST scan).
- D43 / R36: only ``oos_drake/multibody/`` imports pydrake (AST scan), and the command-line
  modules of ``control`` and ``robust`` and the whole ``oos`` parser load without pydrake.
- D12: scheduled parameters (``tau_*``, ``delta_C*``) are substituted, not analyzed.
- R32: the README's Python snippet runs and leaves exactly ``Delta_real`` uncertain.
"""

import argparse
import ast
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import oos_drake

PACKAGE = Path(oos_drake.__file__).resolve().parent
README = PACKAGE.parent / "README.md"

#: The real uncertain parameters of the paper (Delta_real), written out by hand.
DELTA_REAL = {"m_RH2", "Jxx_RH2", "Jyy_RH2", "Jzz_RH2", "w1_SA1", "w1_SA2", "w1_SA3", "w1_SA4"}
SCHEDULED = re.compile(r"^(tau_|delta_C)")


def _sources():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 20, "source scan found too few files"
    return [(path, path.relative_to(PACKAGE).as_posix()) for path in files]


# ---------------------------------------------------------------- D3: the oos parser
COMMANDS = {
    "run", "model", "sdf", "validate", "synth", "analyze", "confirm", "robust", "campaign",
    "ulinearize", "margins", "study", "tree", "report",
}  # fmt: skip
#: Every command line that runs something (README's `oos` table).
RUNNABLE = {
    "run",
    "validate",
    "synth",
    "analyze",
    "margins",
    "confirm",
    "study",
    "model info",
    "model figures",
    "sdf generate",
    "sdf check",
    "robust mussv",
    "robust hinfnorm",
    "robust robstab",
    "robust sweep",
    "ulinearize",
    "tree check",
    "tree sdf",
    "tree convert",
    "tree solve",
    "campaign run",
    "campaign resume",
    "campaign rerun",
    "campaign report",
    "campaign replay",
    "campaign falsify",
    "report",
}


def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return None


def _walk(parser, path=()):
    """Yield ``(path, parser, subparsers_action)`` for every parser below ``parser``."""
    action = _subparsers(parser)
    yield path, parser, action
    if action is not None:
        for name, sub in action.choices.items():
            yield from _walk(sub, path + (name,))


def test_oos_help_lists_every_command():
    from oos_drake.app.main import build_parser

    parser = build_parser()
    assert set(_subparsers(parser).choices) == COMMANDS
    text = parser.format_help()
    for command in COMMANDS:
        assert re.search(rf"^\s+{command}\s", text, re.MULTILINE), f"{command} not in oos --help"


def test_every_runnable_command_sets_func():
    from oos_drake.app.main import build_parser

    leaves = [(path, p) for path, p, action in _walk(build_parser()) if action is None]
    assert {" ".join(path) for path, _ in leaves} == RUNNABLE
    for path, parser in leaves:
        func = parser.get_default("func")
        assert callable(func), f"oos {' '.join(path)} sets no func"


def test_every_command_with_actions_sets_func_or_requires_an_action():
    from oos_drake.app.main import build_parser

    for path, parser, action in _walk(build_parser()):
        if path and action is not None:
            assert action.required or callable(parser.get_default("func")), (
                f"oos {' '.join(path)}: no func and the action is optional"
            )


# ---------------------------------------------------------------- D6: no global RNG
RNG_ALLOWED = {
    "default_rng",
    "Generator",
    "SeedSequence",
    "BitGenerator",
    "PCG64",
    "PCG64DXSM",
    "Philox",
    "SFC64",
}


def global_rng_uses(source: str, filename: str = "<string>") -> list[str]:
    """Uses of numpy's legacy global-RNG API or of the stdlib ``random`` module in ``source``."""
    tree = ast.parse(source, filename)
    numpy_names, random_modules, found = set(), set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                bound = alias.asname or alias.name.split(".")[0]
                if alias.name == "random" or alias.name.startswith("random."):
                    found.append(f"{filename}:{node.lineno}: import {alias.name}")
                elif alias.name == "numpy.random" and alias.asname:
                    random_modules.add(alias.asname)
                elif alias.name.split(".")[0] == "numpy":
                    numpy_names.add(bound)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "random" or node.module.startswith("random."):
                found.append(f"{filename}:{node.lineno}: from {node.module} import ...")
            elif node.module == "numpy":
                for alias in node.names:
                    if alias.name == "random":
                        random_modules.add(alias.asname or "random")
            elif node.module == "numpy.random":
                for alias in node.names:
                    if alias.name not in RNG_ALLOWED:
                        found.append(f"{filename}:{node.lineno}: numpy.random.{alias.name}")
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        base = node.value
        on_random = (isinstance(base, ast.Name) and base.id in random_modules) or (
            isinstance(base, ast.Attribute)
            and base.attr == "random"
            and isinstance(base.value, ast.Name)
            and base.value.id in numpy_names
        )
        if on_random and node.attr not in RNG_ALLOWED:
            found.append(f"{filename}:{node.lineno}: numpy.random.{node.attr}")
    return found


def test_the_rng_scan_catches_the_global_rng():
    bad = (
        "import numpy as np\nimport numpy.random as npr\nimport random\n"
        "from numpy import random as nr\nfrom numpy.random import rand\n"
        "def f():\n"
        "    np.random.seed(0)\n    npr.normal()\n    nr.shuffle([1])\n"
        "    random.random()\n    return np.random.default_rng(1)\n"
    )
    found = global_rng_uses(bad)
    assert len(found) == 5, found
    assert not any("default_rng" in item for item in found)
    good = (
        "import numpy as np\n"
        "def f(rng: np.random.Generator):\n"
        "    seq = np.random.SeedSequence(3)\n"
        "    return np.random.default_rng(seq).random(3) + rng.random()\n"
    )
    assert global_rng_uses(good) == []


def test_no_global_rng_in_the_package():
    found, explicit = [], 0
    for path, name in _sources():
        source = path.read_text()
        found += global_rng_uses(source, name)
        explicit += source.count("default_rng")
    assert found == []
    assert explicit > 0  # the scan sees the package's explicit generators


# ---------------------------------------------------------------- D43 / R36: pydrake in multibody
def pydrake_imports(source: str, filename: str = "<string>") -> list[str]:
    """Every import of pydrake in ``source``: module level, inside functions, or by name."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Call) and node.args:
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            first = node.args[0]
            if called in ("import_module", "__import__") and isinstance(first, ast.Constant):
                names = [str(first.value)]
        if any(n == "pydrake" or n.startswith("pydrake.") for n in names):
            found.append(f"{filename}:{node.lineno}")
    return found


def test_the_pydrake_scan_catches_lazy_imports():
    source = (
        "import importlib\nfrom pydrake.all import MultibodyPlant\n"
        "def f():\n    import pydrake.systems\n    return importlib.import_module('pydrake.math')\n"
        "import pydrake_like\n"
    )
    assert pydrake_imports(source) == ["<string>:2", "<string>:4", "<string>:5"]


def test_only_multibody_imports_pydrake():
    inside, outside = [], []
    for path, name in _sources():
        found = pydrake_imports(path.read_text(), name)
        (inside if name.startswith("multibody/") else outside).extend(found)
    assert outside == []
    assert inside  # the scan does see multibody's imports


def test_control_and_robust_cli_and_the_oos_parser_do_not_load_pydrake():
    code = (
        "import sys\n"
        "import oos_drake.app.synth, oos_drake.app.robust\n"
        "first = 'pydrake' in sys.modules\n"
        "from oos_drake.app.main import build_parser\n"
        "build_parser().format_help()\n"
        "print(first, 'pydrake' in sys.modules)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["False", "False"]


# ---------------------------------------------------------------- D12: scheduled, not analyzed
@pytest.fixture(scope="module")
def controller(paper_scenario):
    from oos_drake.analysis.controller import scenario_controller

    return scenario_controller(None, paper_scenario)


def _remaining(system) -> set[str]:
    return set(system.uncertainty)


def test_mission_closed_loop_keeps_no_scheduled_block(controller, paper_scenario):
    from oos_drake.analysis.models import mission_closed_loop
    from oos_drake.scenario.model import build_mission_model

    open_loop = set(build_mission_model(paper_scenario).uncertainty)
    assert {n for n in open_loop if SCHEDULED.match(n)}  # the model does schedule them
    loop = mission_closed_loop(controller, [0.0, 700.0], paper_scenario)
    names = _remaining(loop.system)
    assert loop.system.batch_shape == (2,)
    assert not {n for n in names if SCHEDULED.match(n)}
    assert DELTA_REAL <= names  # the analyzed real parameters stay uncertain
    assert "Delta_add" in names


@pytest.mark.parametrize("phase", ["7", "8"])
def test_docking_closed_loops_keep_no_scheduled_or_swept_block(controller, phase, paper_scenario):
    from oos_drake.analysis.models import docking_closed_loop
    from oos_drake.scenario.model import build_docking_model

    open_loop = set(build_docking_model(phase, paper_scenario).uncertainty)
    assert {n for n in open_loop if SCHEDULED.match(n)}
    loop = docking_closed_loop(controller, phase, [1.0, 1e3], scenario=paper_scenario)
    names = _remaining(loop.system)
    assert loop.system.batch_shape == (2,)
    assert not {n for n in names if SCHEDULED.match(n)}
    assert not {n for n in names if n.endswith(("_SM1", "_SM2"))}  # swept spring-dampers
    assert DELTA_REAL <= names


# ---------------------------------------------------------------- R32: the README snippet
def _readme_python_block() -> str:
    """The README's mission snippet (the servicer's ulinearize snippet is tested with it)."""
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    blocks = [b for b in blocks if "mission_values" in b]
    assert len(blocks) == 1, f"README has {len(blocks)} python blocks with the mission snippet"
    return blocks[0]


def test_readme_snippet_substitutes_the_schedule_and_keeps_delta_real(capsys):
    from oos_drake.lfr import usubs
    from oos_drake.scenario.model import mission_values

    namespace = {}
    exec(compile(_readme_python_block(), str(README), "exec"), namespace)
    printed = capsys.readouterr().out
    assert "Jxx_RH2" in printed and "tau_alpha1" in printed  # the block table was printed
    array, model, times = namespace["array"], namespace["model"], namespace["times"]
    assert array.batch_shape == (330,)
    assert set(array.uncertainty) == DELTA_REAL
    assert {spec.kind for spec in array.uncertainty.values()} == {"ureal"}
    assert array.occurrences == {n: model.occurrences[n] for n in DELTA_REAL}
    # one model of the vectorized call is the model substituted alone at its time
    for k in (0, 217, 329):
        alone = usubs(model, mission_values(times[k : k + 1], namespace["scenario"])).model(0)
        np.testing.assert_allclose(array.model(k).M, alone.M, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------- benchmarks stay runnable
BENCHMARKS = sorted((PACKAGE.parent / "benchmarks").glob("bench_*.py"))


def _package_imports(tree):
    """``(module, name)`` of every ``from oos_drake... import name`` in a parsed file, except
    fallbacks in ``except ImportError:`` handlers (imports of older checkouts, for comparisons)."""
    fallbacks = {
        id(node)
        for handler in ast.walk(tree)
        if isinstance(handler, ast.ExceptHandler)
        for node in ast.walk(handler)
    }
    return [
        (node.module, alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        and (node.module or "").startswith("oos_drake")
        and id(node) not in fallbacks
        for alias in node.names
    ]


def test_the_benchmark_scan_catches_a_missing_name():
    tree = ast.parse("from oos_drake.robust.mu import no_such_function\n")
    missing = [
        (m, n) for m, n in _package_imports(tree) if not hasattr(__import__(m, fromlist=[n]), n)
    ]
    assert missing == [("oos_drake.robust.mu", "no_such_function")]


@pytest.mark.parametrize("path", BENCHMARKS, ids=lambda p: p.name)
def test_benchmarks_compile_and_import_names_that_exist(path):
    """CI does not run ``benchmarks/`` (timing scripts); this keeps them valid Python of the
    supported version and their package imports pointing at names that exist."""
    source = path.read_text()
    tree = ast.parse(source, filename=str(path))  # a SyntaxError names the file and line
    compile(source, str(path), "exec")
    for module, name in _package_imports(tree):
        mod = __import__(module, fromlist=[name])
        assert hasattr(mod, name) or (module + "." + name) in sys.modules, (
            f"{path.name}: {module} has no {name}"
        )
