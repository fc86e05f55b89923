"""Scratch arrays reused from chunk to chunk by the batched frequency-response routes.

Large temporaries freshly allocated for every chunk come from ``mmap`` and cost a page fault per
4 KiB on first touch, which on the model-array hot path doubled the time spent outside LAPACK and
BLAS. One :class:`Workspace` per worker thread keeps them alive between chunks.
"""

from __future__ import annotations

import numpy as np


class Workspace:
    """Named scratch arrays, grown on demand and reused (one instance per thread)."""

    def __init__(self):
        self._arrays = {}

    def get(self, name: str, shape, dtype=float) -> np.ndarray:
        """A C-contiguous array of ``shape`` and ``dtype`` (uninitialized), reused across calls.

        Parameters
        ----------
        name : str
            Key of the buffer; two live arrays must use different names.
        shape : tuple of int
            Shape of the returned view.
        dtype : numpy dtype, optional
            Element type (default float).

        Returns
        -------
        numpy.ndarray
            A view of the buffer (contents are whatever the last user left).
        """
        arr = self._arrays.get(name)
        size = int(np.prod(shape))
        if arr is None or arr.dtype != np.dtype(dtype) or arr.size < size:
            arr = np.empty(size, dtype=dtype)
            self._arrays[name] = arr
        return arr[:size].reshape(shape)
