"""One table convention (issue 34 item 5): every column name the library writes follows
:mod:`oos_drake.columns` (``name [unit]``, spaces not underscores, frequencies in Hz), and each
quantity has one spelling across tables.

The column names are read from the source (every string literal and f-string shaped like
``name [unit]`` outside docstrings, help texts, messages and figure labels; f-string fields
count as generated identifiers), so the check is fast and covers the writers of every stage.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

import oos_drake
from oos_drake.columns import RENAMED, column_problem, quantity_key

PACKAGE = Path(oos_drake.__file__).parent
_SHAPED = re.compile(r"[^\[\]\n|]+ \[[^\[\]\n]+\]")
#: Call arguments and keywords that are texts, not column names.
_TEXT_CALLS = {"set_xlabel", "set_ylabel", "set_title", "text", "annotate", "print", "warn", "log",
               "ValueError", "RuntimeError", "KeyError", "add_argument", "add_parser"}  # fmt: skip
_TEXT_KEYWORDS = {"help", "xlabel", "ylabel", "label", "title", "desc", "description"}


#: ``name [unit]`` strings that are no table column, and why.
NOT_COLUMNS = {
    "omega [rad/s]": "a key of the analysis' worst_perturbations.npz arrays (a function input)",
}


def _text(node) -> str | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "{}" for v in node.values)
    return None


def column_names(source: str, filename: str = "<string>") -> dict[str, list[int]]:
    """``column -> [line, ...]`` of every ``name [unit]``-shaped string of ``source``."""
    tree = ast.parse(source, filename)
    skip = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            skip.add(id(body[0].value))  # docstrings
        if isinstance(node, ast.keyword) and node.arg in _TEXT_KEYWORDS:
            skip.add(id(node.value))
        if isinstance(node, ast.Call):
            name = getattr(node.func, "attr", getattr(node.func, "id", None))
            if name in _TEXT_CALLS:
                skip.update(id(a) for a in node.args)
        if isinstance(node, ast.JoinedStr):
            skip.update(id(v) for v in node.values)
    found = defaultdict(list)
    for node in ast.walk(tree):
        text = None if id(node) in skip else _text(node)
        if text is not None and len(text) <= 60 and _SHAPED.fullmatch(text):
            found[text].append(node.lineno)
    return dict(found)


def library_columns() -> dict[str, list[str]]:
    """``column -> ["file:line", ...]`` over the library (the application floor prints, it
    writes no table of its own)."""
    columns = defaultdict(list)
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.startswith("app/") or relative == "columns.py":  # columns.py: old names
            continue
        for column, lines in column_names(path.read_text(), relative).items():
            columns[column] += [f"{relative}:{line}" for line in lines]
    return dict(columns)


@pytest.mark.parametrize(
    "bad",
    [
        "mu_upper [-]",  # underscore between words
        "wall_time [s]",
        "peak frequency [rad/s]",  # tables speak Hz
        "crossing frequency [rad/s]",
        "omega peak [rad/s]",
        "time[s]",  # no space before the unit
        "gain [dB] lower",  # unit not last
        "gap  [%]",
    ],
)
def test_the_rules_reject_a_bad_name(bad):
    assert column_problem(bad) is not None


@pytest.mark.parametrize(
    "good",
    ["mu upper [-]", "frequency [Hz]", "wc:Jxx_RH2 [kg m^2]", "w1_SA1 [rad/s]", "phi_x [rad]",
     "peak_torque [N m]", "wcgain:peak_torque upper [-]", "{} [{}]", "subset", "time [s]"],
)  # fmt: skip
def test_the_rules_accept_identifiers_and_labels(good):
    assert column_problem(good) is None


def test_the_scan_finds_columns_and_skips_texts():
    source = (
        '"""Doc [s]"""\n'
        'table = {"wall_time [s]": 1, f"{name} [{unit}]": 2}\n'
        'parser.add_argument("--x", help="lowest frequency [Hz]")\n'
        'raise ValueError("bad value [m]")\n'
    )
    assert set(column_names(source)) == {"wall_time [s]", "{} [{}]"}


def test_every_library_column_follows_the_convention():
    columns = library_columns()
    bad = [
        f"{column_problem(c)} at {', '.join(where[:3])}"
        for c, where in sorted(columns.items())
        if c not in NOT_COLUMNS and column_problem(c) is not None
    ]
    assert not bad, "column names against the table convention:\n" + "\n".join(bad)


def test_one_spelling_per_quantity():
    spellings = defaultdict(set)
    for column in library_columns():
        spellings[quantity_key(column)].add(column)
    twice = {k: sorted(v) for k, v in spellings.items() if len(v) > 1}
    assert not twice, f"one quantity spelled several ways: {twice}"


def test_renamed_columns_are_gone_and_their_new_names_follow_the_rules():
    columns = library_columns()
    assert not set(RENAMED) & set(columns), set(RENAMED) & set(columns)
    assert all(column_problem(new) is None for new in RENAMED.values())


def test_the_mu_sweep_schema_follows_the_convention():
    from oos_drake.robust.tables import GUARANTEE_COLUMNS, SWEEP_COLUMNS

    assert [c for c in SWEEP_COLUMNS + GUARANTEE_COLUMNS if column_problem(c)] == []


def test_simulator_signals_and_metrics_are_registered_identifiers():
    from oos_drake.campaign.attitude_sim import FlexibleAttitudeSimulator
    from oos_drake.columns import IDENTIFIERS

    simulator = FlexibleAttitudeSimulator(control_rate=5.0)
    names = set(simulator.signal_units()) | set(simulator.metric_units())
    assert names <= IDENTIFIERS, names - IDENTIFIERS
