"""Memory of the batched mu bounds: freed heap kept for reuse, big batches in chunks.

:func:`in_chunks` runs a bound on bounded chunks of a batch and :func:`joined` joins the
chunks' results (``mu_upper_bound``, ``mu_lower_bound``, ``mussv``, the sweeps).
:func:`reuse_freed_memory` keeps freed heap memory in the process (glibc only, else no-op).

The kernels allocate and free many temporaries of 1-20 MB per iteration (a batch of 26 x 26
complex matrices). With glibc's defaults, memory above the trim threshold (dynamically about
twice the largest freed mmap chunk) goes back to the kernel on every ``free`` and comes back
through page faults on the next allocation: measured 30 % of the time of one objective
evaluation of the D-G upper bound (176 -> 125 us per 26 x 26 matrix). Raising the trim
threshold and the top pad keeps those pages mapped.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from dataclasses import fields

import numpy as np

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3

#: Heap memory kept after ``free`` [bytes] (returned to the OS only above this).
TRIM_THRESHOLD = 512 * 2**20
#: Extra heap grown at each ``sbrk`` [bytes].
TOP_PAD = 64 * 2**20
#: Allocations above this go to ``mmap`` [bytes] (glibc's maximum on 64-bit systems).
MMAP_THRESHOLD = 32 * 2**20


@functools.cache
def reuse_freed_memory() -> bool:
    """Set glibc's malloc to keep freed memory for reuse (once per process).

    Returns
    -------
    bool
        True if the settings were applied (glibc found), False otherwise (no change).
    """
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    ok &= mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    ok &= mallopt(_M_TOP_PAD, TOP_PAD)
    return bool(ok)


def joined(result_type, parts):
    """One ``result_type`` (a dataclass) of the results of consecutive chunks of a batch.

    Array fields are concatenated along the batch axis (None if None in any part), ``int``
    fields take their largest value (e.g. iterations) and ``dict`` fields are merged.
    """
    values = {}
    for f in fields(result_type):
        got = [getattr(p, f.name) for p in parts]
        if any(v is None for v in got):
            values[f.name] = None
        elif all(isinstance(v, int) for v in got):
            values[f.name] = max(got)
        elif all(isinstance(v, dict) for v in got):
            values[f.name] = {k: v for d in got for k, v in d.items()}
        else:
            values[f.name] = np.concatenate(got, axis=0)
    return result_type(**values)


def in_chunks(function, M, size: int, result_type, per_matrix: dict, **options):
    """``function`` on chunks of at most ``size`` matrices of the batch ``M`` (bounded memory).

    ``per_matrix`` holds the arguments with one row per matrix (None: not given), sliced with
    ``M``; ``options`` go to every call unchanged. The results are :func:`joined`.
    """
    parts = [
        function(
            M[i : i + size],
            **{k: None if v is None else v[i : i + size] for k, v in per_matrix.items()},
            **options,
        )
        for i in range(0, M.shape[0], size)
    ]
    return joined(result_type, parts)
