r"""Robust stability margin of an uncertain LFR (MATLAB ``robstab`` semantics).

The stability margin is the factor by which the normalized uncertainty can grow before the loop
goes unstable: ``margin = 1 / max_omega mu(M11(j omega))``. A margin above 1 means the loop is
stable for the whole modeled uncertainty. The bounds:

* ``lower = 1 / max mu_upper``: with ``guaranteed=True`` (default) over the whole frequency
  axis (:mod:`oos_drake.robust.mu_intervals`: the D-G scalings of a few frequencies prove the
  bound on intervals computed exactly from a Hamiltonian, points are added until the intervals
  cover ``[0, inf)``; ``guarantee`` holds them); with ``guaranteed=False`` over the (refined)
  frequency grid only,
* ``upper = 1 / max mu_lower``: a perturbation of that size, returned in ``worst_case`` (named,
  physical values), puts a closed-loop pole on the imaginary axis at ``critical_frequency``;
  the mu sweep's power iteration is improved by the searches of
  :mod:`oos_drake.robust.worst_search` (box vertices, edges and a local search for real
  parameters, a phase search for complex scalar blocks).

Frequencies are chosen from the system's poles (log grid, dense clusters around lightly damped
poles, ``omega = 0``) and refined around the peaks of both bounds; the bounds come from the
package's one mu sweep (:func:`oos_drake.robust.sweep.sweep_models`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import (
    block_map,
    frequency_grid,
    normalized_worst_case,
    worst_case_values,
)
from oos_drake.robust.mu_intervals import SLACK, AxisCertificate
from oos_drake.robust.sweep import SweepOptions, sweep_models
from oos_drake.robust.tables import sweep_table
from oos_drake.robust.worst_search import improve_destabilizing


@dataclass(frozen=True)
class RobStabResult:
    """Robust stability margin bounds.

    Attributes
    ----------
    lower : float
        Guaranteed margin (``1 / peak mu_upper``; ``inf`` if mu = 0): on the whole frequency
        axis when ``covered``; else on the analyzed frequencies and the proved intervals of
        ``guarantee`` only (``reason`` says where the proof is missing and why).
    upper : float
        Margin of the destabilizing perturbation ``worst_case`` (``1 / peak mu_lower``).
    critical_frequency : float
        Frequency [rad/s] at which ``worst_case`` destabilizes (closed-loop pole ``j omega``).
    worst_case : dict
        Block name -> destabilizing value: physical value (float) for ``ureal``, complex for
        ``ucomplex``, a stable ``control.StateSpace`` for ``ultidyn`` (norm = bound * upper).
    worst_case_normalized : dict
        Block name -> normalized value (scalar or matrix at ``critical_frequency``).
    nominal_stable : bool
        False when the nominal closed loop is already unstable (margins 0).
    omega : numpy.ndarray
        Analyzed frequencies [rad/s] (sorted).
    mu_upper, mu_lower : numpy.ndarray
        Bounds of mu at ``omega``.
    guarantee : AxisCertificate or None
        The intervals that prove ``mu <= 1 / lower`` on ``[0, inf)`` (``guaranteed=True``):
        which points were solved (``added`` where the cover added them), at which level, on
        which interval; ``guarantee.check()`` proves it again.
    covered : bool
        True when ``lower`` holds on the whole frequency axis (the cover closed); False with
        ``guaranteed=False`` or when it did not close.
    reason : str
        Why ``lower`` is not proved on the whole axis (empty when ``covered``): not requested,
        or the frequencies the cover could not prove and why.
    worst_case_source : str
        Which search found ``worst_case``: ``"power iteration"`` (the mu sweep), or
        :func:`~oos_drake.robust.worst_search.improve_destabilizing`'s ``"vertex"``, ``"edge"``,
        ``"random"``, ``"start"``, ``"local"``, ``"phases"``.
    """

    lower: float
    upper: float
    critical_frequency: float
    worst_case: dict
    worst_case_normalized: dict = field(default_factory=dict)
    nominal_stable: bool = True
    omega: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    guarantee: AxisCertificate | None = None
    covered: bool = False
    reason: str = ""
    worst_case_source: str = "power iteration"

    def summary(self) -> str:
        """The bounds, the critical frequency and where the lower bound holds, one line."""
        if not self.nominal_stable:
            return "nominal closed loop unstable: stability margin 0"
        where = (
            "proved on the whole frequency axis"
            if self.covered
            else f"NOT proved on the whole frequency axis ({self.reason})"
        )
        return (
            f"stability margin in [{self.lower:.6g}, {self.upper:.6g}] (normalized units), "
            f"critical frequency {self.critical_frequency:.6g} rad/s; lower bound {where}"
        )

    def __str__(self) -> str:
        return self.summary()

    def table(self, subset: str = "total", time: float = float("nan")):
        """The analyzed frequencies as a mu sweep table (:func:`~.tables.sweep_table`).

        Parameters
        ----------
        subset : str
            Label of the analyzed blocks (``subset`` column).
        time : float
            Mission time [s] (or scheduling value) of the model.

        Returns
        -------
        pandas.DataFrame
            One row per analyzed frequency (model 0, ``tightened`` everywhere), plus
            :data:`~oos_drake.robust.tables.GUARANTEE_COLUMNS` when ``guarantee`` is set.
        """
        return sweep_table(
            subset=subset,
            model=0,
            time=time,
            omega=self.omega,
            upper=self.mu_upper,
            lower=self.mu_lower,
            guaranteed=None if self.guarantee is None else self.guarantee.upper,
            guarantee_points=None if self.guarantee is None else self.guarantee.omega.size,
            covered=self.covered,
            reason=self.reason,
        )


def robstab(
    sys,
    omega=None,
    *,
    blocks=None,
    points_per_decade: int = 40,
    refine_rounds: int = 2,
    mu_options: dict | None = None,
    guaranteed: bool = True,
    slack: float = SLACK,
) -> RobStabResult:
    """Robust stability margin of an uncertain LFR.

    Parameters
    ----------
    sys : LFR
        Closed-loop uncertain model (one model; use :func:`robust_sweep` for model arrays). Its
        inputs and outputs play no part.
    omega : array_like, optional
        Frequencies [rad/s]; default: chosen from the poles of the nominal model.
    blocks : sequence of str, optional
        Analyze only these uncertain blocks (the others stay at their nominal value).
    points_per_decade : int
        Density of the automatic logarithmic grid.
    refine_rounds : int
        Rounds of local refinement around the peaks of the bounds.
    mu_options : dict, optional
        Options passed to :func:`~oos_drake.robust.mussv`.
    guaranteed : bool
        Prove the upper bound of mu (so the margin ``lower``) on the whole frequency axis, not
        only on the grid (see :func:`~oos_drake.robust.mu_intervals.cover_axis`).
    slack : float
        Relative slack of the guaranteed bound above the bound found at each point
        (``lower`` is about ``1 / (1 + slack)`` times the exact D-G margin at best).

    Returns
    -------
    RobStabResult

    Raises
    ------
    ValueError
        If ``sys`` is a model array, has no uncertain blocks, or names unknown blocks. (A
        nominal pole within round-off of the imaginary axis is no error: the cover stays open
        there, ``covered`` is False and ``reason`` names the frequency.)

    Examples
    --------
    >>> import control
    >>> from oos_drake.lfr import ureal, feedback
    >>> k = ureal("k", 40.0, plusminus=10.0)                     # stable for -6 < k < 60
    >>> loop = feedback(k * control.tf(1, [1, 6, 11, 6]), 1)
    >>> res = robstab(loop)
    >>> round(res.upper, 3), round(res.worst_case["k"], 2), round(res.critical_frequency, 3)
    (2.0, 60.0, 3.317)
    """
    from oos_drake.lfr import as_lfr

    sys = as_lfr(sys)
    if sys.batch_shape:
        raise ValueError(f"robstab: sys is a model array {sys.batch_shape}; use robust_sweep")
    bmap = block_map(sys)
    A, Bw, Cz, Dzw = (np.asarray(x) for x in (sys.A, sys.Bw, sys.Cz, sys.Dzw))
    if blocks is not None:
        bmap, zrows, wcols = bmap.subset(list(blocks))
        Bw, Cz, Dzw = Bw[:, wcols], Cz[zrows, :], Dzw[np.ix_(zrows, wcols)]
    poles = np.linalg.eigvals(A) if A.size else np.zeros(0)
    if np.any(poles.real >= 0):
        # margin 0, exactly: nothing left to prove
        return RobStabResult(0.0, 0.0, float("nan"), {}, {}, nominal_stable=False, covered=True)
    if omega is None:
        omega = np.concatenate([[0.0], frequency_grid(A, points_per_decade=points_per_decade)])
    omega = np.asarray(omega, dtype=float)
    if omega.ndim != 1 or omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise ValueError("robstab: omega must be a non-empty 1-D array of frequencies >= 0 [rad/s]")
    # grid: mussv; 4 peaks of both bounds refined; long runs at the 4 highest upper bounds
    # (two rounds); real-axis crossings of the eigenvalues for real blocks; the axis cover
    options = SweepOptions(
        grid="cold",
        pole_points=0,
        mu_options=mu_options,
        refine_points=12,
        refine_peaks=4,
        refine_rounds=refine_rounds,
        refine_lower=True,
        refine_iterations=None,
        polish_points=4,
        polish_rounds=2,
        polish_iterations=600,
        polish_temperatures=(30.0, 300.0, 3000.0),
        crossings=True,
        slack=float(slack) if guaranteed else None,
        n_jobs=1,
    )
    everything = (slice(None), slice(None), bmap.blk)  # the channels of ``blocks``
    try:
        pts = sweep_models(
            A[None], Bw[None], Cz[None], Dzw[None], np.unique(omega), {"": everything}, options
        )[""]
    except ValueError as err:
        raise ValueError(f"robstab: {err}") from None
    omega, up, lo = pts.omega, pts.upper, pts.lower
    guarantee = pts.guarantees.get(0)
    covered = guarantee is not None and guarantee.covered
    if covered:
        peak_up, reason = guarantee.upper, ""
    elif guarantee is not None:  # never a silent margin of 0: the proved part, and why not all
        peak_up = max(float(up.max()), guarantee.upper_on_cover)
        reason = f"whole-axis cover open: {guarantee.reason}"
    else:
        peak_up, reason = float(up.max()), "guaranteed=False: analyzed frequencies only"
    peak_lo, wc, delta = pts.best[0]
    structure = parse_blk(bmap.blk)
    # searches beyond the power iteration (vertices, edges, local search; phases)
    better = improve_destabilizing(A, Bw, Cz, Dzw, structure, peak_lo, delta, omega, up)
    source = "power iteration"
    if better is not None:
        peak_lo, wc, delta, source = better.mu_lower, better.omega, better.delta, better.source
    lower = 1.0 / peak_up if peak_up > 0 else float("inf")
    upper = 1.0 / peak_lo if peak_lo > 0 else float("inf")
    worst, worst_norm = {}, {}
    if peak_lo > 0:
        worst = worst_case_values(bmap, structure, delta, wc)
        worst_norm = normalized_worst_case(bmap, structure, delta)
    else:
        wc = float("nan")
    return RobStabResult(
        lower,
        upper,
        wc,
        worst,
        worst_norm,
        True,
        omega,
        up,
        lo,
        guarantee,
        covered,
        reason,
        source,
    )
