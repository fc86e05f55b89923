r"""Structured singular value bounds: :func:`mussv` (MATLAB ``mussv`` semantics, Pythonic result).

.. math::

    \mu_\Delta(M) = \frac{1}{\min\{\bar\sigma(\Delta) : \Delta \in \mathbf{\Delta},\
        \det(I - M\Delta) = 0\}}

with ``mu = 0`` when no structured ``Delta`` makes ``I - M Delta`` singular.

Cost (paper-sized problem: 26 x 26, 16 blocks, one core, ``benchmarks/bench_mussv.py``): the
upper bound takes about 42-47 Hermitian eigenvalue problems per matrix (three smoothing
stages, per-matrix stopping) and lands within ~0.2 % (at most ~0.4 %) of the fully converged
D-G bound; with ``continuation=True`` (frequency responses) about 18-30. Matrices are optimized
eight at a time in SIMD lanes (:mod:`mu_lanes`, about 20 us per matrix and evaluation; a batch
of fewer than eight leaves lanes idle). The lower
bound runs two power-iteration starts per matrix and three more only where the gap still
exceeds 2 %, polishes the most promising start of each matrix, and certifies each ``delta``
with a residual vector (an SVD only when that is inconclusive). On small mixed structures (at
most three real blocks, ``sum(r) <= 12``; not the paper's) a search over the real parameters
(:func:`~oos_drake.robust.worst_search.mixed_real_search`, tens of ms per matrix) runs where the
gap exceeds 0.1 % and the complex blocks are a single block (all mixed structures of that
size with ``mixed_search=True``): the power iteration alone may return 0 there.

Example
-------
>>> import numpy as np
>>> from oos_drake.robust import mussv
>>> M = np.array([[1.0, 2.0], [0.0, 1.0]])
>>> res = mussv(M, [[1, 1], [1, 1]])          # two complex scalars
>>> bool(res.lower <= res.upper)
True
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from oos_drake.robust.blocks import REAL, BlockStructure, check_matrix, parse_blk
from oos_drake.robust.memory import joined
from oos_drake.robust.mu_lower import (
    CERTIFICATE_RTOL,
    LowerBoundResult,
    certificate_residual,
    mu_lower_bound,
)
from oos_drake.robust.mu_upper import (
    UpperBoundResult,
    _per_blk,
    lmi_residual,
    mu_upper_bound,
    power_of_two_scale,
)
from oos_drake.robust.worst_search import (
    MIXED_MAX_REAL,
    complex_phase_search,
    mixed_real_search,
)


@dataclass(frozen=True)
class MuResult:
    """Bounds of the structured singular value with their certificates.

    Attributes
    ----------
    upper : float or numpy.ndarray
        Upper bound of mu, shape ``batch`` (a float for a single matrix).
    lower : float or numpy.ndarray
        Certified lower bound of mu (``0 <= lower <= upper``).
    delta : numpy.ndarray
        ``(..., sum(r), sum(c))`` perturbation in the block structure with
        ``det(I - M delta) = 0`` and ``||delta||_2 = 1 / lower`` (all zeros where ``lower == 0``).
    D_left : numpy.ndarray
        ``(..., sum(c), sum(c))`` Hermitian positive definite scaling (output side of ``M``).
    D_right : numpy.ndarray
        ``(..., sum(r), sum(r))`` the same scalings on the input side of ``M``.
    G : numpy.ndarray
        ``(..., sum(r), sum(c))`` Hermitian scalings of the real blocks (zero elsewhere). The
        certificate is ``M^* D_l M + j (G M - M^* G^*) - upper^2 D_r <= 0``.
    structure : BlockStructure
        The parsed block structure.
    certificate_residual : numpy.ndarray
        ``sigma_min(I - M delta) / (1 + ||M delta||)`` of the returned ``delta`` (NaN if none).
    """

    upper: float | np.ndarray
    lower: float | np.ndarray
    delta: np.ndarray
    D_left: np.ndarray
    D_right: np.ndarray
    G: np.ndarray
    structure: BlockStructure
    certificate_residual: float | np.ndarray

    @property
    def blk(self) -> np.ndarray:
        """The BLK rows."""
        return self.structure.blk

    def check(self, M, *, rtol: float = 1e-6) -> dict:
        """Re-check both certificates against ``M`` independently of the algorithms.

        Returns
        -------
        dict
            ``lmi_max_eig`` (largest eigenvalue of the D-G LMI at ``upper * (1 + rtol)``, relative
            to the size of its terms; ``<= 0`` proves the upper bound, round-off level ~1e-14
            proves it up to round-off, as for bounds of zero reached by unbounded scalings),
            ``singularity`` (``sigma_min(I - M delta)``, relative; about round-off proves the
            lower bound) and ``delta_norm_error`` (``||delta|| * lower - 1``).
        """
        M = np.asarray(M, dtype=complex)
        up = np.asarray(self.upper, dtype=float)
        lmi = lmi_residual(M, up * (1 + rtol) + 1e-300, self.D_left, self.D_right, self.G)
        lo = np.asarray(self.lower, dtype=float)
        sing = np.where(lo > 0, certificate_residual(M, self.delta), np.nan)
        dn = np.linalg.norm(self.delta, ord=2, axis=(-2, -1))
        return {
            "lmi_max_eig": lmi,
            "singularity": sing,
            "delta_norm_error": np.where(lo > 0, dn * lo - 1.0, np.nan),
        }


#: Matrices per internal batch (memory: about 1 MB per 26 x 26 matrix in flight).
CHUNK = 2048


#: Upper bound settings of :func:`mussv`: three smoothing stages (temperatures relative to the
#: bound), an iteration cap and a per-matrix stopping tolerance. On the paper-sized benchmark
#: (``benchmarks/bench_mussv.py``) the bound lands within about 0.23 % (at most 0.4 %) of the
#: fully converged D-G bound in about 42-47 eigenvalue problems per matrix (the L-BFGS pairs
#: carry over from stage to stage); the former two stages ``(30, 300)`` at ``tol = 2e-4`` took
#: 53-57 for the same accuracy (the middle stage makes the last one short).
UPPER_TEMPERATURES = (30.0, 100.0, 300.0)
UPPER_ITERATIONS = 100
UPPER_TOL = 4e-4
#: Consecutive small decreases that stop a stage (2 stopped slow-but-steady descents early:
#: 5 % above the optimum on a badly scaled case, see tests/robust/test_mu_speed_paths.py;
#: 3 still passes it).
UPPER_PATIENCE = 3


#: Continuation (``mussv(..., continuation=True)``): each matrix also tries the previous one's
#: scalings and, where they start lower, runs one stage at :data:`CONTINUATION_TEMPERATURE` with
#: patience :data:`CONTINUATION_PATIENCE` from there.
CONTINUATION_TEMPERATURE = 300.0
CONTINUATION_PATIENCE = 2
#: Random restarts of the lower bound (besides the neighbours' vectors) with continuation.
CONTINUATION_LOWER_RESTARTS = 0
#: Power-iteration steps of those neighbour starts (they start near a fixed point).
CONTINUATION_LOWER_ITERATIONS = 60


#: Largest ``sum(r)`` of the structures that get :func:`mixed_real_search` in :func:`mussv`.
MIXED_MAX_SIZE = 12
#: Gap ``upper / lower`` above which :func:`mussv` runs that search (it is cheap on the small
#: structures it serves, and the power iteration may stop 2 % short where the gap is 2 %).
MIXED_GAP = 1.001
#: Length of that search's rays of real parameters, times ``1 / upper`` (capped at ``1 / lower``:
#: the minimizer has ``||y|| <= 1 / mu <= 1 / lower``).
MIXED_RADIUS = 2.0


_PARSED: dict = {}  # BLK (shape, dtype, bytes) -> its BlockStructure (single calls repeat it)


def _parsed(blk) -> BlockStructure:
    """:func:`~oos_drake.robust.blocks.parse_blk`, once per BLK (its ``blk`` array read-only)."""
    if isinstance(blk, BlockStructure):
        return blk
    arr = np.asarray(blk)
    key = (arr.shape, arr.dtype.str, arr.tobytes())
    if key not in _PARSED:
        structure = parse_blk(arr)
        structure.blk.flags.writeable = False
        if len(_PARSED) > 256:
            _PARSED.clear()
        _PARSED[key] = structure
    return _PARSED[key]


def _complex_scalars(structure) -> bool:
    """True if every block is a repeated complex scalar (:func:`mussv`'s phase search)."""
    return all(b.repeated and b.kind != REAL for b in structure.blocks)


def _small_mixed(structure, mixed_search) -> bool:
    """True for the structures :func:`mussv` hands to :func:`mixed_real_search` (argument
    ``mixed_search`` of :func:`mussv`)."""
    n_real = _per_blk("n_real", structure, lambda: sum(b.kind == REAL for b in structure.blocks))
    n_complex = len(structure.blocks) - n_real
    return (
        mixed_search is not False
        and 0 < n_real <= MIXED_MAX_REAL
        and 0 < n_complex <= (1 if mixed_search is None else n_complex)
        and structure.n_rows <= MIXED_MAX_SIZE
    )


def _upper_bound(part, structure, iterations, tol, *, continuation=False):
    """The D-G upper bound of :func:`mussv` (optionally with continuation along the batch)."""
    cold_options = dict(
        max_iter=iterations, tol=tol, temperatures=UPPER_TEMPERATURES, patience=UPPER_PATIENCE
    )
    if not continuation or part.shape[0] < 2:
        return mu_upper_bound(part, structure, **cold_options)
    return mu_upper_bound(  # chained matrix by matrix
        part,
        structure,
        **cold_options,
        chain=True,
        chain_temperatures=(CONTINUATION_TEMPERATURE,),
        chain_patience=CONTINUATION_PATIENCE,
    )


def _lower_bound(part, structure, up, *, restarts, iters, rng, restart_gap, continuation=False):
    """Power iteration from the upper bound's worst direction and one random start; the other
    random restarts only where the gap ``upper / lower`` still exceeds ``restart_gap``. With
    ``continuation`` they are replaced by starts from the neighbouring matrices' eigenvectors
    (plus :data:`CONTINUATION_LOWER_RESTARTS` random ones)."""
    first = mu_lower_bound(
        part,
        structure,
        start_inputs=up.worst_input,
        restarts=min(restarts, 1),
        iters=iters,
        rng=rng,
        polish_starts=1,
    )
    if restarts <= 1:
        return first
    redo = np.flatnonzero(up.upper > restart_gap * first.lower)
    if redo.size == 0:
        return first
    if continuation and part.shape[0] > 2:
        idx = np.arange(part.shape[0])
        nbr = np.stack([np.maximum(idx - 1, 0), np.minimum(idx + 1, idx.size - 1)], axis=1)
        more = mu_lower_bound(
            part[redo],
            structure,
            start_vectors=first.vector[nbr[redo]],
            restarts=min(restarts - 1, CONTINUATION_LOWER_RESTARTS),
            iters=min(iters, CONTINUATION_LOWER_ITERATIONS),
            rng=rng,
            polish_starts=1,
        )
    else:
        more = mu_lower_bound(
            part[redo], structure, restarts=restarts - 1, iters=iters, rng=rng, polish_starts=1
        )
    better = more.lower > first.lower[redo]
    if not better.any():  # (a lone matrix: no merging, the same values)
        return first
    rows = redo[better]
    merged = {}
    for f in fields(LowerBoundResult):
        a, b = getattr(first, f.name), getattr(more, f.name)
        if a is None or b is None:
            merged[f.name] = a
            continue
        a = a.copy()
        a[rows] = b[better]
        merged[f.name] = a
    return LowerBoundResult(**merged)


def mussv(
    M,
    blk,
    *,
    upper_iterations: int = UPPER_ITERATIONS,
    upper_tol: float = UPPER_TOL,
    lower_restarts: int = 4,
    lower_iterations: int = 60,
    restart_gap: float = 1.02,
    rng: np.random.Generator | None = None,
    continuation: bool = False,
    phase_search: bool = True,
    mixed_search: bool | None = None,
) -> MuResult:
    """Upper and lower bounds of the mixed structured singular value.

    Parameters
    ----------
    M : array_like
        ``(..., sum(c), sum(r))`` complex matrix or batch (e.g. a frequency response
        ``(models, frequencies, ny, nu)``), finite.
    blk : array_like of int, shape (k, 2)
        MATLAB BLK rows: ``[-r, 0]`` repeated real scalar, ``[r, 0]`` repeated complex scalar,
        ``[r, c]`` full complex ``r x c`` block.
    upper_iterations : int
        BFGS iterations of the D-G upper bound.
    upper_tol : float
        Relative decrease of the smoothed objective per iteration below which (four times in a
        row) a matrix stops its current smoothing stage.
    lower_restarts : int
        Random restarts of the power iteration (besides the start from the upper bound); all
        but the first run only where ``upper / lower > restart_gap`` after the first two starts.
    restart_gap : float
        Gap above which the remaining random restarts of the lower bound are run.
    lower_iterations : int
        Power-iteration steps per start.
    rng : numpy.random.Generator, optional
        Random starts of the lower bound (default: seeded, reproducible).
    continuation : bool
        Treat consecutive matrices of the batch (in C order: neighbouring frequencies of a frequency
        response along the last batch axis) as neighbours. The upper bound of each matrix also tries
        the scalings reached on the previous one and, where they start lower than balancing, runs
        one short smoothing stage from there; the lower bound's extra restarts start from the
        neighbours' eigenvectors instead of random vectors. Faster on smooth frequency responses,
        and as valid (each upper bound is the exact ``lambda_max`` at its own scalings, each lower
        bound has its own verified ``delta``); independent matrices should keep the default (False).
    phase_search : bool
        For structures of repeated complex scalar blocks only: where ``upper / lower >
        restart_gap``, also maximize ``rho(M Delta)`` over the blocks' phases
        (:func:`~oos_drake.robust.worst_search.complex_phase_search`; the power iteration alone
        may stop 10-15 % short there).
    mixed_search : bool or None
        For small mixed structures (real and complex blocks, at most
        :data:`~oos_drake.robust.worst_search.MIXED_MAX_REAL` real blocks and
        :data:`MIXED_MAX_SIZE` rows of ``Delta``) only: where ``upper / lower >`` :data:`MIXED_GAP`,
        also search the real parameters by rays and pattern searches, each point closed on the
        complex blocks (:func:`~oos_drake.robust.worst_search.mixed_real_search`; on two real
        and one complex scalar the power iteration alone may return 0 or stop 60 % short
        there). None (default): only where the complex blocks are a single block (closed form
        inside the search, tens of ms per matrix); True: also with several complex blocks (a
        power iteration at each point, about ten times slower); False: never.

    Returns
    -------
    MuResult

    Raises
    ------
    ValueError
        For a malformed BLK, an ``M`` whose shape does not match it, or a non-finite ``M``.
    """
    structure = _parsed(blk)
    M = check_matrix(M, structure)
    batch = M.shape[:-2]
    c, r = structure.m_shape
    flat = M.reshape((-1, c, r))
    scale = power_of_two_scale(flat)  # entries of order one: no overflow for huge or tiny M
    flat = flat / scale[:, None, None]
    rng = np.random.default_rng(0) if rng is None else rng
    ups, los = [], []
    for start in range(0, flat.shape[0], CHUNK):  # bounded memory for very large batches
        part = flat[start : start + CHUNK]
        ups.append(
            _upper_bound(part, structure, upper_iterations, upper_tol, continuation=continuation)
        )
        los.append(
            _lower_bound(
                part,
                structure,
                ups[-1],
                restarts=lower_restarts,
                iters=lower_iterations,
                rng=rng,
                restart_gap=restart_gap,
                continuation=continuation,
            )
        )
    up, lo = (
        (ups[0], los[0])
        if len(ups) == 1
        else (joined(UpperBoundResult, ups), joined(LowerBoundResult, los))
    )
    lower = lo.lower * scale
    # both bounds are certified; where they meet (full block, rank one) round-off may put the
    # lower one a few ulps above: raising a valid upper bound keeps it valid
    delta = lo.delta / scale[:, None, None]
    resid = lo.residual
    if phase_search and _per_blk("complex_scalars", structure, lambda: _complex_scalars(structure)):
        lower, delta, resid = lower.copy(), delta.copy(), np.array(resid, dtype=float)
        for i in np.flatnonzero(up.upper * scale > restart_gap * lower):
            value, d, res = complex_phase_search(
                flat[i] * scale[i], structure, start=delta[i], rng=rng
            )
            if res <= CERTIFICATE_RTOL and value > lower[i]:
                lower[i], delta[i], resid[i] = value, d, res
    if _small_mixed(structure, mixed_search):
        lower, delta, resid = lower.copy(), delta.copy(), np.array(resid, dtype=float)
        for i in np.flatnonzero(up.upper * scale > MIXED_GAP * lower):
            # on the scaled matrix (entries of order one); the residual is scale-invariant
            radius = MIXED_RADIUS / (up.upper[i] + 1e-300)
            if lower[i] > 0:
                radius = min(radius, scale[i] / lower[i])
            value, d, res = mixed_real_search(
                flat[i], structure, radius=radius, start=delta[i] * scale[i], rng=rng
            )
            if res <= CERTIFICATE_RTOL and value * scale[i] > lower[i]:
                lower[i], delta[i], resid[i] = value * scale[i], d / scale[i], res
    upper = np.maximum(up.upper * scale, lower)

    def shape(x, tail=()):
        x = x.reshape(batch + tail)
        return float(x) if (x.ndim == 0) else x

    return MuResult(
        upper=shape(upper),
        lower=shape(lower),
        delta=delta.reshape(batch + (r, c)),
        D_left=up.D_left.reshape(batch + (c, c)),
        D_right=up.D_right.reshape(batch + (r, r)),
        G=(up.G * scale[:, None, None]).reshape(batch + (r, c)),
        structure=structure,
        certificate_residual=shape(resid),
    )
