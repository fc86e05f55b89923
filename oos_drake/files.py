"""Result files and folders written whole or not at all.

Every result file of the package goes through :func:`atomic_write_bytes`: the content is written
to a temporary file in the target's folder, flushed to disk, given the mode a new file gets
under the current umask, and renamed over the target, so that a crash or an error half-way
leaves the previous file (or none), never a truncated one. Result folders (``oos analyze``,
``oos margins``, ``oos confirm``, ``oos study``, the stages of ``oos run``) go through
:func:`atomic_folder` likewise.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def _file_mode() -> int:
    """Mode of a newly created file under the current umask (mkstemp would give 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


#: Mode of the files written by :func:`atomic_write_bytes` (and of the campaign's lock file).
FILE_MODE = _file_mode()


def atomic_write_bytes(path: Path, write) -> Path:
    """Call ``write(binary_stream)`` into a temporary file, then rename it to ``path``.

    Parameters
    ----------
    path : path-like
        The file to write (its folder is created if needed).
    write : callable
        ``write(stream)`` writes the whole content into the binary stream.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as stream:
            write(stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(temporary, FILE_MODE)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def atomic_write_parquet(table, path: Path) -> Path:
    """Write the :class:`pandas.DataFrame` ``table`` to ``path`` as Parquet, atomically."""
    return atomic_write_bytes(path, lambda stream: table.to_parquet(stream, index=False))


def atomic_write_text(text: str, path: Path) -> Path:
    """Write ``text`` (UTF-8) to ``path``, atomically."""
    return atomic_write_bytes(path, lambda stream: stream.write(text.encode("utf-8")))


def atomic_folder(path, work, *, marker: str | None = None, what: str = "a result"):
    """Run ``work(tmp)`` in a new sibling folder ``tmp`` that replaces ``path`` only when it
    returns: a failed or interrupted run leaves the previous folder (or none), never a
    half-written one.

    Parameters
    ----------
    path : path-like
        The result folder.
    work : callable
        ``work(tmp)`` writes the results into the (created, empty) folder ``tmp``.
    marker : str, optional
        File that marks a previous result: an existing non-empty ``path`` without it is refused
        (``what`` names the result in the error). None: any ``path`` is replaced.

    Returns
    -------
    object
        What ``work`` returns.
    """
    path = Path(path).resolve()
    if marker and path.exists() and any(path.iterdir()) and not (path / marker).is_file():
        raise ValueError(f"--out {path} exists and holds something other than {what}")
    tmp = path.with_name(f".{path.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir(parents=True)
        result = work(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(path, ignore_errors=True)
    tmp.rename(path)
    return result
