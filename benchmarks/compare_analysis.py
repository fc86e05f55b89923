"""Are two ``oos analyze`` folders the same results? (issue 34: "make run results unchanged").

Every Parquet table is compared with :func:`pandas.testing.assert_frame_equal` (exact: same
columns, dtypes, order and values), every array of ``peak_perturbations.npz`` exactly, and
``summary.json`` as parsed JSON. Wall-clock quantities are left out (they are not results):
the columns and keys named in :data:`WALL_CLOCK`, ``timings_s``, and the scenario's ``file``
path (the same file read from two checkouts). The PNG figures are not compared (matplotlib
metadata); they are drawn from the compared tables.

Usage (``args.txt``: one reduced analysis, same controller, run on each checkout)::

    PYTHONPATH=/work/main python -m oos_drake.app.main analyze --out /tmp/a $(cat args.txt)
    PYTHONPATH=.          python -m oos_drake.app.main analyze --out /tmp/b $(cat args.txt)
    python benchmarks/compare_analysis.py /tmp/a /tmp/b

Exit status 0 when equal; 1 with the first difference of each file printed otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: Wall-clock columns / keys (seconds measured, not computed results).
WALL_CLOCK = ("spike time [s]", "guarantee time [s]", "timings_s", "wall time [s]")


def _strip(value):
    """``value`` without the wall-clock keys (recursively) and the scenario's file path."""
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if k not in WALL_CLOCK}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def compare(before: Path, after: Path) -> list[str]:
    """The differences between two analysis folders (empty: the same results)."""
    problems = []
    names = sorted(p.name for p in before.glob("*.parquet"))
    others = sorted(p.name for p in after.glob("*.parquet"))
    if names != others:
        problems.append(f"tables differ: {names} vs {others}")
    for name in names:
        if not (after / name).is_file():
            continue
        a, b = pd.read_parquet(before / name), pd.read_parquet(after / name)
        a = a.drop(columns=[c for c in WALL_CLOCK if c in a.columns])
        b = b.drop(columns=[c for c in WALL_CLOCK if c in b.columns])
        try:
            pd.testing.assert_frame_equal(a, b, check_exact=True)
        except AssertionError as error:
            problems.append(f"{name}: {str(error).splitlines()[0:4]}")
    if (before / "peak_perturbations.npz").is_file():
        a = np.load(before / "peak_perturbations.npz")
        b = np.load(after / "peak_perturbations.npz")
        if sorted(a.files) != sorted(b.files):
            problems.append("peak_perturbations.npz: keys differ")
        for key in a.files:
            if key in b.files and not np.array_equal(a[key], b[key]):
                problems.append(f"peak_perturbations.npz: {key} differs")
    sa = json.loads((before / "summary.json").read_text())
    sb = json.loads((after / "summary.json").read_text())
    for record in (sa, sb):
        record.get("scenario", {}).pop("file", None)
        record.get("options", {}).pop("progress", None)
    sa, sb = _strip(sa), _strip(sb)
    for key in sorted(set(sa) | set(sb)):
        if sa.get(key) != sb.get(key):
            problems.append(f"summary.json[{key!r}] differs: {sa.get(key)} vs {sb.get(key)}")
    return problems


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    args = parser.parse_args(argv)
    problems = compare(args.before, args.after)
    tables = len(list(args.before.glob("*.parquet")))
    if problems:
        print("\n".join(problems))
        return 1
    print(f"equal: {tables} tables (assert_frame_equal, exact), perturbations, summary.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
