"""The campaign result directory and its crash-safe writes.

Layout of a campaign directory::

    spec.toml              the resolved spec (every default filled in), the campaign's identity
    worst_cases.parquet    copy of the analysis regions (mu-guided campaigns only)
    environment.json       versions of Python and the numerical packages that ran the campaign
    plan.parquet           every planned run: run id, seed, region, weight, window, all values
    runs/run_000042.parquet   one finished run (one row), written when the run ends
    timeseries/run_000042.parquet   its retained time series (written before the run row)
    runs.parquet           consolidation of runs/ in run-id order (written at the end of run/resume)
    report/                figures and tables of ``oos campaign report``
    .lock                  held (``flock``) by the process that runs or resumes the campaign
    quarantine/            unreadable run files moved aside by ``resume`` (the runs are redone)

Every file is written to a temporary name in the same directory, flushed and ``fsync``-ed, then
renamed over its final name with :func:`os.replace` (atomic on POSIX): a reader (or a ``resume``
after ``kill -9``) sees either the whole file or none of it. A run is finished exactly when its
``runs/run_NNNNNN.parquet`` exists, and the time series is written before it, so a killed
campaign loses at most the runs that were in flight, and ``resume`` redoes exactly those.

Two processes never run one campaign: ``run`` and ``resume`` hold an exclusive ``flock`` on
``.lock`` (released by the kernel when the holder dies, even by ``kill -9``), and a second one is
refused with a one-line error. A run file that cannot be read (truncated by a crash of the disk
or a copy, never by our writes) is moved to ``quarantine/`` by ``resume``, which then redoes
that run.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from oos_drake.files import FILE_MODE, atomic_write_parquet

SPEC_FILE = "spec.toml"
PLAN_FILE = "plan.parquet"
ENVIRONMENT_FILE = "environment.json"
RUNS_FILE = "runs.parquet"
WORST_CASES_FILE = "worst_cases.parquet"
RUNS_DIR = "runs"
TIMESERIES_DIR = "timeseries"
REPORT_DIR = "report"
LOCK_FILE = ".lock"
QUARANTINE_DIR = "quarantine"


def read_table(path: Path, columns, label: str, *, legacy: bool = False) -> pd.DataFrame:
    """Read a Parquet table a user gave, with its required ``columns``.

    ``legacy``: rename the column names of tables written before the ``name [unit]``
    convention first (:func:`oos_drake.robust.tables.upgrade_columns`).

    Raises
    ------
    ValueError
        ``"<label>: cannot read Parquet: ..."`` or ``"<label>: missing column(s) ..."``.
    """
    try:
        table = pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 - any reader error is a bad file for the user
        raise ValueError(f"{label}: cannot read Parquet: {exc}") from exc
    if legacy:
        from oos_drake.robust.tables import upgrade_columns

        try:
            table = upgrade_columns(table)
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise ValueError(f"{label}: missing column(s) {', '.join(missing)}")
    return table


def environment() -> dict[str, str]:
    """Versions that determine the numbers (a rerun is bit-identical only on the same ones)."""
    import importlib.metadata
    import platform

    versions = {"python": platform.python_version(), "machine": platform.machine()}
    for package in ("oos_drake", "numpy", "scipy", "pandas", "pyarrow", "drake"):
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = "absent"
    return versions


def run_file(directory: Path, run_id: int) -> Path:
    """Path of one run's result row."""
    return Path(directory) / RUNS_DIR / f"run_{run_id:06d}.parquet"


def timeseries_file(directory: Path, run_id: int) -> Path:
    """Path of one run's retained time series."""
    return Path(directory) / TIMESERIES_DIR / f"run_{run_id:06d}.parquet"


def finished_run_ids(directory: Path) -> set[int]:
    """Ids of the runs whose result row exists (temporary leftovers are ignored)."""
    folder = Path(directory) / RUNS_DIR
    if not folder.is_dir():
        return set()
    return {int(p.stem.removeprefix("run_")) for p in folder.glob("run_*.parquet")}


def remove_temporaries(directory: Path) -> int:
    """Delete temporary files left by a killed writer; returns how many were removed."""
    count = 0
    for pattern in (f"{RUNS_DIR}/.*.tmp", f"{TIMESERIES_DIR}/.*.tmp", ".*.tmp"):
        for path in Path(directory).glob(pattern):
            path.unlink(missing_ok=True)
            count += 1
    return count


@contextlib.contextmanager
def campaign_lock(directory: Path) -> Iterator[None]:
    """Hold the campaign's exclusive lock for the ``with`` body; refuse if another process has it.

    Raises
    ------
    ValueError
        The campaign is being run or resumed by another process (its pid is named).
    """
    path = Path(directory) / LOCK_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = os.open(path, os.O_RDWR | os.O_CREAT, FILE_MODE)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(handle, 32, 0).decode(errors="replace").strip() or "?"
            raise ValueError(
                f"{directory} is in use by another campaign process (pid {holder}); "
                "wait for it to finish or stop it, then 'oos campaign resume'"
            ) from None
        os.ftruncate(handle, 0)
        os.pwrite(handle, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(handle)  # releases the lock


def _readable_parquet(path: Path) -> bool:
    import pyarrow.parquet as pq

    try:
        pq.read_metadata(path)
    except Exception:  # noqa: BLE001 - any reader error means the file is not usable
        return False
    return True


def quarantine_unreadable(directory: Path) -> list[Path]:
    """Move unreadable run rows and time series to ``quarantine/``; return their new paths.

    A run whose row or retained time series cannot be read is no longer finished: ``resume``
    redoes it. Nothing is deleted (the files are kept for inspection).
    """
    directory = Path(directory)
    moved = []
    for folder in (RUNS_DIR, TIMESERIES_DIR):
        source = directory / folder
        files = sorted(source.glob("run_*.parquet")) if source.is_dir() else []
        for path in files:
            if _readable_parquet(path):
                continue
            target = directory / QUARANTINE_DIR / folder / path.name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
            moved.append(target)
            row = run_file(directory, int(path.stem.removeprefix("run_")))
            if folder == TIMESERIES_DIR and row.is_file():  # redo the run to get its series
                aside = directory / QUARANTINE_DIR / RUNS_DIR / row.name
                aside.parent.mkdir(parents=True, exist_ok=True)
                os.replace(row, aside)
                moved.append(aside)
    return moved


def read_run_rows(directory: Path) -> pd.DataFrame:
    """Concatenate the finished run rows in run-id order (empty frame when none)."""
    folder = Path(directory) / RUNS_DIR
    files = sorted(folder.glob("run_*.parquet")) if folder.is_dir() else []
    if not files:
        return pd.DataFrame()
    frames = [pd.read_parquet(f) for f in files]
    return pd.concat(frames, ignore_index=True).sort_values("run_id").reset_index(drop=True)


def consolidate(directory: Path) -> Path:
    """Write ``runs.parquet`` from the per-run rows (atomically) and return its path."""
    table = read_run_rows(directory)
    return atomic_write_parquet(table, Path(directory) / RUNS_FILE)


def load_runs(directory: Path) -> pd.DataFrame:
    """The campaign's run table: ``runs.parquet`` if up to date, else the per-run rows."""
    directory = Path(directory)
    consolidated = directory / RUNS_FILE
    finished = finished_run_ids(directory)
    if consolidated.is_file():
        table = pd.read_parquet(consolidated)
        if "run_id" in table.columns and set(table["run_id"]) == finished:
            return table
    return read_run_rows(directory)
