"""Size of the package: lines per folder and the longest functions (issue 34, "the house").

Reads the working tree, or any commit with ``--rev`` (``git show``, no checkout), so that the
before/after numbers come from one script::

    python benchmarks/code_size.py --rev d9bfc71   # before
    python benchmarks/code_size.py                 # after (the working tree)
    python benchmarks/code_size.py --before d9bfc71   # both, per folder with the change

Lines are physical lines of ``*.py`` files (blank lines and docstrings included). A function's
length is ``end_lineno - lineno + 1`` of its ``def`` (decorators excluded, nested functions
counted in their parent and on their own).
"""

from __future__ import annotations

import argparse
import ast
import subprocess
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "oos_drake"


def sources(rev: str | None) -> dict[str, str]:
    """``path -> text`` of every ``.py`` file of the package (working tree, or commit ``rev``)."""
    if rev is None:
        return {
            p.relative_to(ROOT).as_posix(): p.read_text()
            for p in sorted((ROOT / PACKAGE).rglob("*.py"))
        }
    names = subprocess.run(
        ["git", "ls-tree", "-r", "--name-only", rev, PACKAGE],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    return {
        name: subprocess.run(
            ["git", "show", f"{rev}:{name}"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout
        for name in names
        if name.endswith(".py")
    }


def folder_of(path: str) -> str:
    """``oos_drake/<pkg>/`` of a file, or ``oos_drake/`` for top-level modules."""
    parts = path.split("/")
    return "/".join(parts[:2]) + "/" if len(parts) > 2 else parts[0] + "/ (top)"


def lines_per_folder(files: dict[str, str]) -> Counter:
    """Physical lines per folder."""
    counts: Counter = Counter()
    for path, text in files.items():
        counts[folder_of(path)] += len(text.splitlines())
    return counts


def longest_functions(files: dict[str, str], count: int = 10) -> list[tuple[int, str]]:
    """The ``count`` longest functions: ``(lines, "path:line name")``, longest first."""
    found = []
    for path, text in files.items():
        for node in ast.walk(ast.parse(text, path)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = node.end_lineno - node.lineno + 1
                found.append((length, f"{path}:{node.lineno} {node.name}"))
    return sorted(found, key=lambda item: (-item[0], item[1]))[:count]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rev", default=None, help="a git commit (default: the working tree)")
    parser.add_argument(
        "--before", default=None, help="a git commit to compare with (columns before, after)"
    )
    parser.add_argument("--top", type=int, default=10, help="how many longest functions")
    args = parser.parse_args(argv)
    files = sources(args.rev)
    counts = lines_per_folder(files)
    after = args.rev or "working tree"
    if args.before is None:
        print(f"lines per folder ({after})")
        for folder, lines in sorted(counts.items()):
            print(f"  {folder:<28} {lines:>7}")
        print(f"  {'total':<28} {sum(counts.values()):>7}")
    else:
        old_files = sources(args.before)
        old = lines_per_folder(old_files)
        print(f"lines per folder: before ({args.before}), after ({after}), change")
        for folder in sorted(set(counts) | set(old)):
            a, b = old.get(folder, 0), counts.get(folder, 0)
            print(f"  {folder:<28} {a:>7} {b:>7} {b - a:>+7}")
        a, b = sum(old.values()), sum(counts.values())
        print(f"  {'total':<28} {a:>7} {b:>7} {b - a:>+7}")
        print(f"longest functions before ({args.top})")
        for lines, where in longest_functions(old_files, args.top):
            print(f"  {lines:>5}  {where}")
    print(f"longest functions ({after}, {args.top})")
    for lines, where in longest_functions(files, args.top):
        print(f"  {lines:>5}  {where}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
