r"""Worst-case performance: gains of ``d -> e_p`` (APE) and ``d -> e_u`` (effort) per subset.

For each analyzed configuration, frequency and uncertainty subset, the worst-case gain
``max_{||Delta|| <= 1} sigma_max(F_u(M(j omega), Delta))`` of a performance channel is bounded by
the skewed-mu bisection of :func:`oos_drake.robust.wcgain.skewed_gain_bounds` (upper bound) and
the exact gain of the perturbation it finds (lower bound). Channels are the weighted errors of
the design: ``e_p = phi / W_p`` (the APE requirement is gain 1) and ``e_u = W_u u`` (the 2 N m
bound is gain 1), from the normalized disturbances ``d``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from oos_drake.blas import limit_blas_threads
from oos_drake.campaign.performance import REQUIREMENT_METRICS
from oos_drake.processes import make_executor
from oos_drake.robust.lfr_analysis import delta_channel_response, model_matrices, subset_parts

#: Performance channels: name -> rows of ``e``.
CHANNELS = {"e_p": (0, 1, 2), "e_u": (3, 4, 5)}
# REQUIREMENT_METRICS (imported above, defined once in oos_drake.campaign.performance): channel
# -> the campaign metric of the Drake mission whose requirement is its unit gain (``e_p``: the
# APE bound, ``e_u``: the 2 N m wheel command bound).

#: Columns of the performance table.
PERFORMANCE_COLUMNS = [
    "channel",
    "subset",
    "model",
    "time [s]",
    "frequency [Hz]",
    "gain nominal [-]",
    "gain lower [-]",
    "gain upper [-]",
]


def _channel_task(task):
    from oos_drake.robust.wcgain import skewed_gain_bounds

    (A, B, C, D, nz, nw, blk, omega, tol, iterations) = task
    nm = A.shape[0]
    M = delta_channel_response(A, B, C, D, omega)  # (nm, F, nz+ny, nw+nu)
    flat = M.reshape((-1,) + M.shape[2:])
    lo, up, delta, nom = skewed_gain_bounds(flat, nz, nw, blk, tol=tol, upper_iterations=iterations)
    F = omega.size
    return (
        lo.reshape(nm, F),
        up.reshape(nm, F),
        nom.reshape(nm, F),
        delta.reshape((nm, F) + delta.shape[1:]),
    )


def channel_matrices(sys, models, rows, blocks) -> tuple:
    """``(A, B, C, D, nz, nw, blk)`` of one channel and uncertainty subset of ``sys`` at
    ``models``: the subset's Delta channels and the channel's ``rows`` of ``e`` from ``d`` (the
    other blocks nominal), as the skewed-mu bisection takes them."""
    names = ("A", "Bw", "Bu", "Cz", "Cy", "Dzw", "Dzu", "Dyw", "Dyu")
    models = np.atleast_1d(np.asarray(models, dtype=int))
    A, Bw, Bu, Cz, Cy, Dzw, Dzu, Dyw, Dyu = (x[models] for x in model_matrices(sys, names))
    zr, wc, blk = subset_parts(sys, {"subset": list(blocks)})["subset"]
    rows = list(rows)
    B = np.concatenate([Bw[:, :, wc], Bu], axis=2)
    C = np.concatenate([Cz[:, zr, :], Cy[:, rows, :]], axis=1)
    D = np.concatenate(
        [
            np.concatenate([Dzw[:, zr][:, :, wc], Dzu[:, zr, :]], axis=2),
            np.concatenate([Dyw[:, rows][:, :, wc], Dyu[:, rows, :]], axis=2),
        ],
        axis=1,
    )
    return (A, B, C, D, zr.size, wc.size, blk)


def worst_case_gains(
    sys,
    models,
    omega,
    subsets: dict,
    *,
    times=None,
    tol: float = 0.02,
    upper_iterations: int = 40,
    n_jobs: int = 2,
    scheduler: str | None = None,
    progress: bool = True,
):
    """Worst-case gain bounds of ``e_p`` and ``e_u`` for chosen models, per subset.

    Parameters
    ----------
    sys : LFR
        Closed-loop model array ``d -> e`` (6 outputs ``[e_p; e_u]``).
    models : array_like of int
        Indices of the analyzed models.
    omega : array_like
        Frequencies [rad/s].
    subsets : dict
        Subset name -> block names.
    times : array_like, optional
        Scheduling value of every model of ``sys`` (stored in ``time [s]``).
    tol : float
        Relative accuracy of the bisection.
    upper_iterations : int
        BFGS iterations of each mu upper bound.
    n_jobs : int
        Worker processes.
    scheduler : str, optional
        Where they run (``--scheduler``, :func:`oos_drake.processes.make_executor`).
    progress : bool
        tqdm bar over (channel, subset) tasks.

    Returns
    -------
    table : pandas.DataFrame
        Columns :data:`PERFORMANCE_COLUMNS`.
    deltas : dict
        ``(channel, subset) -> (models, F, nw, nz)`` normalized worst perturbations (unit size).
    """
    from tqdm.auto import tqdm

    models = np.atleast_1d(np.asarray(models, dtype=int))
    omega = np.unique(np.asarray(omega, dtype=float))
    n_all = sys.batch_shape[0] if sys.batch_shape else 1
    times = np.full(n_all, np.nan) if times is None else np.asarray(times, dtype=float)
    tasks, keys = [], []
    for channel, rows in CHANNELS.items():
        for name, blocks in subsets.items():
            tasks.append(
                channel_matrices(sys, models, rows, blocks) + (omega, tol, upper_iterations)
            )
            keys.append((channel, name))
    bar = tqdm(total=len(tasks), desc="worst-case gains", unit="task", disable=not progress)
    results = []
    with make_executor(
        max(1, n_jobs), scheduler, initializer=limit_blas_threads, initargs=(1,)
    ) as executor:
        for future in [executor.submit(_channel_task, t) for t in tasks]:
            results.append(future.result())
            bar.update(1)
    bar.close()
    frames, deltas = [], {}
    hz = omega / (2 * np.pi)
    for (channel, name), (lo, up, nom, dl) in zip(keys, results, strict=True):
        deltas[(channel, name)] = dl
        for j, m in enumerate(models):
            frames.append(
                pd.DataFrame(
                    {
                        "channel": channel,
                        "subset": name,
                        "model": int(m),
                        "time [s]": times[m],
                        "frequency [Hz]": hz,
                        "gain nominal [-]": nom[j],
                        "gain lower [-]": lo[j],
                        "gain upper [-]": up[j],
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)[PERFORMANCE_COLUMNS], deltas


def peak_gains(table: pd.DataFrame, subset: str, model: int) -> dict:
    """Worst-case gains of one subset at one model, as campaign metric -> ``(lower, upper)``.

    The peak over the table's frequency grid of each channel's bounds: the lower one is the gain
    of a perturbation found (a true lower bound of the worst-case gain), the upper one the
    largest skewed-mu upper bound at the grid frequencies (not proved between them) [-].
    Channels without rows for ``(subset, model)`` are left out.
    """
    out = {}
    rows = table[(table["subset"] == subset) & (table["model"] == model)]
    for channel, metric in REQUIREMENT_METRICS.items():
        chosen = rows[rows["channel"] == channel]
        if len(chosen):
            out[metric] = (
                float(chosen["gain lower [-]"].max()),
                float(chosen["gain upper [-]"].max()),
            )
    return out
