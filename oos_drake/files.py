"""Result files written whole or not at all.

Every result file of the package goes through :func:`atomic_write_bytes`: the content is written
to a temporary file in the target's folder, flushed to disk, given the mode a new file gets
under the current umask, and renamed over the target, so that a crash or an error half-way
leaves the previous file (or none), never a truncated one.
"""

from __future__ import annotations

import os
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
