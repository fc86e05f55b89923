"""Run numpy's OpenBLAS single-threaded inside the synthesis hot loops.

The gamma evaluation does thousands of small complex matrix products (one per model). With a
multi-threaded OpenBLAS on a shared machine, each of them pays thread wake-up and contention
costs that can exceed the arithmetic by 100x (measured: 0.21 s vs 0.0018 s for 4 products of
174x37 by 37x54). The batching over models and frequencies is the parallelism we want, so the
hot loops run with one BLAS thread. This does what ``threadpoolctl`` does, for the OpenBLAS
builds loaded in the process, without a new dependency.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools

_SETTERS = (
    "openblas_set_num_threads_local",  # returns the previous value, calling thread only
)
_GLOBAL = (
    ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
    ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
    ("openblas_set_num_threads", "openblas_get_num_threads"),
)


@functools.cache
def _libraries() -> tuple:
    paths = set()
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.split()[-1]
                if path.startswith("/") and "openblas" in path.lower():
                    paths.add(path)
    except OSError:
        return ()
    libs = []
    for path in sorted(paths):
        try:
            libs.append(ctypes.CDLL(path))
        except OSError:
            continue
    return tuple(libs)


@contextlib.contextmanager
def single_threaded_blas():
    """Context manager: one OpenBLAS thread inside, previous setting restored on exit."""
    restore = []
    for lib in _libraries():
        local = getattr(lib, _SETTERS[0], None)
        if local is not None:
            local.restype = ctypes.c_int
            local.argtypes = [ctypes.c_int]
            previous = local(1)
            restore.append((local, previous))
            continue
        for setter_name, getter_name in _GLOBAL:
            setter, getter = getattr(lib, setter_name, None), getattr(lib, getter_name, None)
            if setter is not None and getter is not None:
                getter.restype = ctypes.c_int
                previous = getter()
                setter.argtypes = [ctypes.c_int]
                setter(1)
                restore.append((setter, previous))
                break
    try:
        yield
    finally:
        for setter, previous in reversed(restore):
            setter(int(previous))


def with_single_threaded_blas(function):
    """Decorator form of :func:`single_threaded_blas`."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return function(*args, **kwargs)

    return wrapper
