"""Closed-form oracle of the TITOP appendage model (an independent reference for the tests).

``tests/`` is on ``sys.path`` (rootdir imports):
``from appendage_oracle import effective_mass_model``.
"""

from __future__ import annotations

import numpy as np

from oos_drake.titop.appendage import check_appendage_data
from oos_drake.titop.spatial import residual_mass


def effective_mass_model(s, rigid_inertia_P, participation, frequencies, damping) -> np.ndarray:
    """Evaluate ``M_P(s)`` by its closed form (numeric reference).

    Parameters
    ----------
    s : complex or array_like
        Laplace variable(s) [rad/s]; ``np.inf`` gives ``D_P0``.
    rigid_inertia_P, participation, frequencies, damping
        As in :func:`check_appendage_data` (participation: 6 x N, columns = modes).

    Returns
    -------
    numpy.ndarray, shape (..., 6, 6)
    """
    d_P, participation, w, xi = check_appendage_data(
        rigid_inertia_P, participation, frequencies, damping
    )
    s = np.asarray(s, dtype=complex)
    result = np.broadcast_to(residual_mass(d_P, participation), s.shape + (6, 6)).astype(complex)
    for i in range(w.size):
        li = participation[:, i]
        if np.all(np.isinf(s)):
            continue
        gain = (2 * xi[i] * w[i] * s + w[i] ** 2) / (s**2 + 2 * xi[i] * w[i] * s + w[i] ** 2)
        result = result + gain[..., None, None] * np.outer(li, li)
    return result
