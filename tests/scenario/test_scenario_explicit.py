"""The scenario is explicit (issue 34 item 3): no library function defaults to the paper's.

The paper's scenario is chosen once, where ``--scenario`` is parsed (the application floor
``oos_drake/app/``: the command modules and the pipeline); everywhere below, the scenario (or
an object built from it) is a required argument, and a scenario crosses process boundaries as
itself (it pickles).
"""

import ast
import pickle
from pathlib import Path

import numpy as np
import pytest

import oos_drake
from oos_drake.scenario.data import Scenario, load_scenario

PACKAGE = Path(oos_drake.__file__).parent
#: The application floor: where the paper's default may be chosen.
APPLICATION = PACKAGE / "app"
#: Documented exceptions, ``(file, function) -> why`` (none: a campaign spec of the Drake
#: mission names its scenario, the simulator requires it).
EXCEPTIONS: dict[tuple[str, str], str] = {}


def scenario_defaults(source: str, filename: str = "<string>") -> list[str]:
    """Where ``source`` lets a function fall back to the paper's scenario: a parameter
    ``scenario`` (or ``*_scenario``) defaulting to None, a call of ``load_scenario()`` without
    arguments, or of ``default_scenario``."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            arguments = node.args
            positional = arguments.posonlyargs + arguments.args
            pairs = list(zip(positional[len(positional) - len(arguments.defaults) :],
                             arguments.defaults, strict=True))  # fmt: skip
            pairs += [(a, d) for a, d in zip(arguments.kwonlyargs, arguments.kw_defaults,
                                             strict=True) if d is not None]  # fmt: skip
            for argument, default in pairs:
                if (
                    (argument.arg == "scenario" or argument.arg.endswith("_scenario"))
                    and isinstance(default, ast.Constant)
                    and default.value is None
                ):
                    found.append(f"{filename}:{node.lineno} {node.name}(scenario=None)")
        elif isinstance(node, ast.Call):
            name = getattr(node.func, "id", getattr(node.func, "attr", None))
            if name == "load_scenario" and not node.args and not node.keywords:
                found.append(f"{filename}:{node.lineno} load_scenario()")
            elif name == "default_scenario":
                found.append(f"{filename}:{node.lineno} default_scenario(...)")
    return found


def _allowed(path: Path, finding: str) -> bool:
    relative = path.relative_to(PACKAGE).as_posix()
    function = finding.split(" ", 1)[1].split("(")[0]
    return (relative, function) in EXCEPTIONS


def test_the_scan_catches_a_default_scenario():
    source = (
        "def f(x, scenario=None):\n    pass\n"
        "def g(*, scenario: Scenario | None = None):\n    pass\n"
        "def h(scenario):\n    return load_scenario()\n"
        "def k(scenario):\n    return default_scenario(scenario)\n"
        "def ok(scenario, path=None):\n    return load_scenario(path)\n"
    )
    found = scenario_defaults(source)
    assert [f.split(" ", 1)[1] for f in found] == [
        "f(scenario=None)", "g(scenario=None)", "load_scenario()", "default_scenario(...)"
    ]  # fmt: skip


def test_no_library_function_defaults_to_the_papers_scenario():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if APPLICATION in path.parents:
            continue
        found += [
            f for f in scenario_defaults(path.read_text(), str(path)) if not _allowed(path, f)
        ]
    assert not found, "library code falls back to the paper's scenario:\n" + "\n".join(found)


def _same(a, b, where="scenario"):
    """Deep equality of two scenario trees (arrays equal and read-only in both)."""
    import dataclasses

    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and not b.flags.writeable, where
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict | tuple | list) or hasattr(a, "items"):
        assert type(a) is type(b), where
        items = a.items() if hasattr(a, "items") else enumerate(a)
        other = dict(b.items()) if hasattr(b, "items") else dict(enumerate(b))
        assert len(other) == len(a), where
        for key, value in items:
            _same(value, other[key], f"{where}[{key!r}]")
    else:
        assert a == b, where


@pytest.mark.parametrize("overrides", [None, {"hubs.RH2.mass": 30.0}])
def test_a_scenario_pickles_as_itself(overrides):
    scenario = load_scenario("paper", overrides)
    copy = pickle.loads(pickle.dumps(scenario))
    assert isinstance(copy, Scenario) and copy is not scenario
    _same(scenario, copy)
    with pytest.raises(TypeError):
        copy.hubs["RH3"] = copy.hubs["RH2"]  # still a read-only mapping
    with pytest.raises(ValueError, match="read-only"):
        copy.hubs["RH2"].inertia[0, 0] = 1.0
    if overrides:
        assert copy.hubs["RH2"].mass == 30.0 and copy.overrides == (("hubs.RH2.mass", 30.0),)


def test_a_pickled_scenario_does_not_reread_its_file(tmp_path):
    """The data travel, not the file name: a worker gets the caller's scenario even when the
    file changed in between."""
    path = tmp_path / "mine.toml"
    text = load_scenario("paper").source.read_text()
    path.write_text(text)
    blob = pickle.dumps(load_scenario(path))
    path.write_text(text.replace("mass = 24.96", "mass = 30.0", 1))
    assert pickle.loads(blob).hubs["RH2"].mass == 24.96
