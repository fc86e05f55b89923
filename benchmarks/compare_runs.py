"""Are two ``oos run`` folders the same results? (issue 34 must-show: "``make run`` results
unchanged to six digits, stage times unchanged within noise").

Every Parquet and CSV table of every stage folder is compared column by column (numbers to
``--rtol``, relative to the column's largest magnitude; anything else exactly), every ``.npz``
array likewise, and every ``.json`` file (``controller.json``, ``summary.json``, ...) number
by number. Wall-clock quantities are not results and are left out: columns and keys whose name
says time of the run (:data:`WALL_CLOCK`). Stage folders are matched by name, a campaign folder
(``campaign-<key>``, the key hashes the code) by its prefix. The stage times of
``timings.json`` are printed side by side with their ratio.

Usage::

    python benchmarks/compare_runs.py BEFORE AFTER [--rtol 1e-6]

Exit status 0 when every compared number agrees to ``--rtol``; 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: Column / key fragments of wall-clock measurements (not results).
WALL_CLOCK = ("wall", "time_s", "timings", "cpu", "elapsed", "spike time", "guarantee time")
#: Keys that name a place, not a result.
PLACES = ("file", "path", "out", "folder", "directory", "created", "version", "key")


def _is_clock(name: str) -> bool:
    """A wall-clock measurement or the worker process that ran a task (not results)."""
    name = name.lower()
    return any(w in name for w in WALL_CLOCK) or name in ("worker", "host", "pid")


def _folder(root: Path, name: str) -> Path | None:
    if (root / name).is_dir():
        return root / name
    prefix = name.split("-", 1)[0] + "-"
    found = sorted(p for p in root.iterdir() if p.is_dir() and p.name.startswith(prefix))
    return found[0] if len(found) == 1 else None


def _compare_tables(a: pd.DataFrame, b: pd.DataFrame, rtol: float) -> tuple[bool, float, str]:
    """``(equal, largest relative difference, message)`` of two tables."""
    if list(a.columns) != list(b.columns) or len(a) != len(b):
        return False, math.inf, f"shape/columns {a.shape} vs {b.shape}"
    worst, identical = 0.0, True
    for col in a.columns:
        if _is_clock(str(col)):
            continue
        x, y = a[col], b[col]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
            u, v = x.to_numpy(dtype=float), y.to_numpy(dtype=float)
            same_nan = np.isnan(u) == np.isnan(v)
            if not same_nan.all():
                return False, math.inf, f"{col}: NaN pattern differs"
            ok = ~np.isnan(u)
            if not np.array_equal(u[ok], v[ok]):
                identical = False
            inf = np.isinf(u[ok]) | np.isinf(v[ok])
            if not np.array_equal(u[ok][inf], v[ok][inf]):
                return False, math.inf, f"{col}: infinities differ"
            fin_u, fin_v = u[ok][~inf], v[ok][~inf]
            if fin_u.size:
                scale = max(np.abs(fin_u).max(), np.abs(fin_v).max(), 1e-300)
                rel = float(np.abs(fin_u - fin_v).max() / scale)
                worst = max(worst, rel)
                if rel > rtol:
                    return False, rel, f"{col}: relative difference {rel:.3g}"
        else:
            if not x.astype(str).equals(y.astype(str)):
                return False, math.inf, f"{col}: values differ"
    return True, worst, "identical" if identical else f"max relative difference {worst:.2g}"


def _numbers(value, prefix=""):
    """Flatten a parsed JSON into ``key path -> number or string`` (clock and places left out)."""
    out = {}
    if isinstance(value, dict):
        for k, v in value.items():
            if _is_clock(str(k)) or str(k).lower() in PLACES:
                continue
            out.update(_numbers(v, f"{prefix}/{k}"))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out.update(_numbers(v, f"{prefix}[{i}]"))
    else:
        out[prefix] = value
    return out


def _compare_json(a, b, rtol: float) -> tuple[bool, float, str]:
    x, y = _numbers(a), _numbers(b)
    if set(x) != set(y):
        return False, math.inf, f"keys differ: {sorted(set(x) ^ set(y))[:5]}"
    worst, identical = 0.0, True
    for key in x:
        u, v = x[key], y[key]
        if isinstance(u, bool) or not isinstance(u, (int, float)):
            if u != v:
                return False, math.inf, f"{key}: {u!r} vs {v!r}"
            continue
        if u != v and not (isinstance(v, float) and math.isnan(u) and math.isnan(v)):
            identical = False
            if not (isinstance(v, (int, float)) and math.isfinite(u) and math.isfinite(v)):
                return False, math.inf, f"{key}: {u!r} vs {v!r}"
            rel = abs(u - v) / max(abs(u), abs(v), 1e-300)
            worst = max(worst, rel)
            if rel > rtol:
                return False, rel, f"{key}: {u!r} vs {v!r}"
    return True, worst, "identical" if identical else f"max relative difference {worst:.2g}"


def _compare_arrays(a, b, rtol: float) -> tuple[bool, float, str]:
    if set(a.files) != set(b.files):
        return False, math.inf, f"arrays differ: {sorted(set(a.files) ^ set(b.files))}"
    worst, identical = 0.0, True
    for name in a.files:
        x, y = a[name], b[name]
        if x.shape != y.shape:
            return False, math.inf, f"{name}: shape {x.shape} vs {y.shape}"
        if np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"):
            continue
        identical = False
        if x.dtype.kind not in "fc":
            return False, math.inf, f"{name}: values differ"
        scale = max(np.nanmax(np.abs(x)), np.nanmax(np.abs(y)), 1e-300)
        rel = float(np.nanmax(np.abs(x - y)) / scale)
        worst = max(worst, rel)
        if rel > rtol:
            return False, rel, f"{name}: relative difference {rel:.3g}"
    return True, worst, "identical" if identical else f"max relative difference {worst:.2g}"


def compare(before: Path, after: Path, rtol: float) -> bool:
    """Print the comparison of every stage folder's tables and JSON files; True when equal."""
    ok = True
    for stage in sorted(p for p in before.iterdir() if p.is_dir()):
        other = _folder(after, stage.name)
        if other is None:
            print(f"{stage.name}: missing in {after}")
            ok = False
            continue
        for path in sorted(stage.rglob("*")):
            rel = path.relative_to(stage)
            target = other / rel
            if (
                path.suffix not in (".parquet", ".csv", ".json", ".npz")
                or path.name == "stage.json"
            ):
                continue
            if not target.is_file():
                print(f"{stage.name}/{rel}: missing after")
                ok = False
                continue
            if path.suffix == ".npz":
                equal, _, message = _compare_arrays(np.load(path), np.load(target), rtol)
            elif path.suffix == ".json":
                equal, _, message = _compare_json(
                    json.loads(path.read_text()), json.loads(target.read_text()), rtol
                )
            else:
                read = pd.read_parquet if path.suffix == ".parquet" else pd.read_csv
                equal, _, message = _compare_tables(read(path), read(target), rtol)
            ok &= equal
            print(f"{'ok  ' if equal else 'DIFF'} {stage.name}/{rel}: {message}")
    return ok


def timings(before: Path, after: Path) -> None:
    """Stage times of ``timings.json`` side by side."""
    files = [before / "timings.json", after / "timings.json"]
    if not all(f.is_file() for f in files):
        print("timings.json missing in", [str(f) for f in files if not f.is_file()])
        return
    a, b = (json.loads(f.read_text()) for f in files)
    a, b = a.get("stages_s", a), b.get("stages_s", b)
    print(f"{'stage':<16} {'before [s]':>11} {'after [s]':>11} {'after/before':>13}")
    for stage in a:
        x, y = a[stage], b.get(stage)
        if isinstance(x, dict):
            x, y = (
                x.get("wall_s", x.get("seconds")),
                (y or {}).get("wall_s", (y or {}).get("seconds")),
            )
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) and x:
            print(f"{stage:<16} {x:11.1f} {y:11.1f} {y / x:13.2f}")
        else:
            print(f"{stage:<16} {x!s:>11} {y!s:>11}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance [-]")
    args = parser.parse_args(argv)
    ok = compare(args.before, args.after, args.rtol)
    timings(args.before, args.after)
    print("same results" if ok else "RESULTS DIFFER")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
