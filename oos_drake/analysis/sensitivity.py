r"""Which uncertain parameter moves the worst-case mu most (paper Fig. unc_sensitivity, extended).

At the critical configuration, for every block ``b`` of ``Delta_tot``, on the frequencies where
the peak lives:

* ``mu upper alone [-]``: mu with only ``b`` uncertain (what ``b`` can do by itself);
* ``mu upper without [-]``: mu with ``b`` held nominal (``drop [%]``: how much of the peak is due
  to ``b``);
* ``sensitivity [-]``: the mu-sensitivity ``(d mu / mu) / (d r_b / r_b)``, the relative change
  of the peak when the size ``r_b`` of ``b``'s uncertainty grows by 10 % (its Delta channels
  scaled by 1.1), a finite difference of the upper bound.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from oos_drake.analysis.subsets import block_group
from oos_drake.robust.lfr_analysis import block_map, delta_channel_response
from oos_drake.robust.sweep import SweepOptions, grid_bounds

#: Columns of the sensitivity table.
SENSITIVITY_COLUMNS = [
    "block",
    "group",
    "unit",
    "mu upper total [-]",
    "mu upper alone [-]",
    "mu upper without [-]",
    "drop [%]",
    "sensitivity [-]",
    "frequency [Hz]",
]


def mu_sensitivity(
    sys, model: int, omega, *, iterations: int = 300, step: float = 0.1
) -> pd.DataFrame:
    """Sensitivity of the peak of mu (total set) to each block, at one model.

    Parameters
    ----------
    sys : LFR
        Closed-loop model array or one model.
    model : int
        Index of the analyzed model.
    omega : array_like
        Frequencies [rad/s] around the peak (a dozen is plenty).
    iterations : int
        BFGS iterations of the upper bounds. The grown problem starts from the scalings of the
        total one (same structure), so the finite difference measures the perturbation, not
        the optimizer's noise.
    step : float
        Relative growth of a block's uncertainty for the finite difference.

    Returns
    -------
    pandas.DataFrame
        One row per block, columns :data:`SENSITIVITY_COLUMNS`, sorted by ``drop [%]``.
    """
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_upper import mu_upper_bound

    one = sys.model(model) if sys.batch_shape else sys
    bmap = block_map(one)
    omega = np.asarray(omega, dtype=float)
    M = delta_channel_response(
        np.asarray(one.A), np.asarray(one.Bw), np.asarray(one.Cz), np.asarray(one.Dzw), omega
    )
    structure = parse_blk(bmap.blk)
    base = mu_upper_bound(np.ascontiguousarray(M), structure, max_iter=iterations)
    total = base.upper
    peak = float(total.max())
    options = SweepOptions(upper_iterations=iterations)
    rows = []
    for i, name in enumerate(bmap.names):
        others = [n for n in bmap.names if n != name]
        sub, zr, wc = bmap.subset([name])
        alone, _ = grid_bounds(M[:, zr][:, :, wc], sub.blk, options)
        without = np.zeros_like(total)
        if others:
            sub_o, zr_o, wc_o = bmap.subset(others)
            without, _ = grid_bounds(M[:, zr_o][:, :, wc_o], sub_o.blk, options)
        scaled = M.copy()
        scaled[:, :, bmap.w_slices[i]] *= 1.0 + step
        grown = mu_upper_bound(
            scaled, structure, max_iter=max(iterations // 5, 10), x0=base.params
        ).upper
        rows.append(
            {
                "block": name,
                "group": block_group(one.uncertainty[name]),
                "unit": one.uncertainty[name].unit,
                "mu upper total [-]": peak,
                "mu upper alone [-]": float(alone.max()),
                "mu upper without [-]": float(without.max()),
                "drop [%]": 100.0 * (peak - float(without.max())) / peak if peak > 0 else 0.0,
                "sensitivity [-]": ((float(grown.max()) - peak) / peak / step) if peak > 0 else 0.0,
                "frequency [Hz]": float(omega[int(np.argmax(alone))] / (2 * np.pi)),
            }
        )
    table = pd.DataFrame(rows)[SENSITIVITY_COLUMNS]
    return table.sort_values("drop [%]", ascending=False, ignore_index=True)
