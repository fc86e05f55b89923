"""Limit the BLAS thread pool of numpy/scipy's OpenBLAS (no extra dependency).

The mu kernels run many tiny batched factorizations (26 x 26); OpenBLAS threads make those
several times slower on a loaded machine, and sweep workers already run one per core.
"""

from __future__ import annotations

import ctypes
import glob
import os

_SYMBOLS = (
    "scipy_openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
    "openblas_set_num_threads64_",
    "openblas_set_num_threads",
)


def limit_blas_threads(n: int = 1) -> int:
    """Set the OpenBLAS thread count of numpy's and scipy's bundled libraries.

    Parameters
    ----------
    n : int
        Threads per BLAS call.

    Returns
    -------
    int
        Number of libraries whose thread count was set (0 if none was found).
    """
    import numpy
    import scipy

    count = 0
    dirs = [
        os.path.join(os.path.dirname(os.path.dirname(m.__file__)), f"{m.__name__}.libs")
        for m in (numpy, scipy)
    ]
    for path in sorted({p for d in dirs for p in glob.glob(os.path.join(d, "*openblas*.so*"))}):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _SYMBOLS:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(int(n))
                count += 1
                break
    return count
