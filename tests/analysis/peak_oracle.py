"""A local certified mu peak of one model, for tests: an oracle independent of the analysis'
sweep and spike resolution (moved here from ``oos_drake.analysis.stability``: only tests use it)."""

import numpy as np

from oos_drake.analysis.stability import PeakCertificate, _analysis_model, _named_perturbation
from oos_drake.analysis.workers import CONVERGED_TEMPERATURES
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response
from oos_drake.robust.sweep import SweepOptions


def certify_peak(
    sys,
    subset: str,
    members,
    model: int,
    frequency_hz: float,
    *,
    time: float = float("nan"),
    span: float = 0.25,
    points: int = 41,
    upper_iterations: int = 300,
    search_band: float = 2.0,
) -> PeakCertificate:
    """Bounds of the mu peak of one model near ``frequency_hz``, with the worst perturbation.

    The upper bound is recomputed with ``upper_iterations`` BFGS iterations on a local grid;
    the lower bound is the best of the power iteration on that grid and of the direct search
    for a destabilizing perturbation
    (:func:`oos_drake.analysis.destabilizing.destabilizing_perturbation`),
    whose frequency may lie anywhere in ``frequency_hz * [1/search_band, search_band]``.

    Parameters
    ----------
    sys : LFR
        Closed-loop model array (or one model).
    subset : str
        Subset name (label).
    members : sequence of str
        Blocks of the subset.
    model : int
        Model index.
    frequency_hz : float
        Approximate peak frequency [Hz] (from the sweep).
    time : float
        Scheduling value of the model (label).
    span : float
        Relative half-width of the local grid around ``frequency_hz``.
    points : int
        Points of the local grid (log spaced).
    upper_iterations : int
        BFGS iterations of the local upper bounds.
    search_band : float
        Frequency band factor of the direct search.
    """
    from oos_drake.analysis.destabilizing import destabilizing_perturbation
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    A, Bw, Cz, Dzw, _, sub, _ = _analysis_model(sys, model, members)
    w0 = 2 * np.pi * frequency_hz
    omega = w0 * np.geomspace(1 - span, 1 + span, points)
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)
    opts = SweepOptions(upper_iterations=upper_iterations, lower_restarts=4, lower_iterations=60)
    structure = parse_blk(sub.blk)
    up_res = mu_upper_bound(
        np.ascontiguousarray(M),
        structure,
        max_iter=upper_iterations,
        temperatures=CONVERGED_TEMPERATURES,
    )
    up = up_res.upper
    lo_res = mu_lower_bound(
        M,
        structure,
        start_inputs=up_res.worst_input,
        restarts=opts.lower_restarts,
        iters=opts.lower_iterations,
    )
    k = int(np.argmax(lo_res.lower))
    lower, w_crit, delta = float(lo_res.lower[k]), float(omega[k]), lo_res.delta[k]
    direct = destabilizing_perturbation(
        A, Bw, Cz, Dzw, sub.blk, [w0 / search_band, w0 * search_band]
    )
    if direct.mu_lower > lower:
        lower, w_crit, delta = direct.mu_lower, direct.omega, direct.delta
    # the converged upper bound at the critical frequency (the certificate's other side)
    Mc = delta_channel_response(A, Bw, Cz, Dzw, [w_crit])
    up_crit = float(
        mu_upper_bound(
            Mc, structure, max_iter=max(1000, upper_iterations), temperatures=CONVERGED_TEMPERATURES
        ).upper[0]
    )
    up_crit = max(up_crit, lower)
    up = np.append(up, up_crit)
    peak_up = float(max(up.max(), lower))
    normalized, worst = {}, {}
    if lower > 0:
        worst, normalized = _named_perturbation(sub, delta, w_crit)
    return PeakCertificate(
        subset,
        int(model),
        float(time),
        float(w_crit / (2 * np.pi)),
        peak_up,
        lower,
        up_crit,
        delta,
        worst,
        normalized,
    )
