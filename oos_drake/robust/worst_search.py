r"""Worst-case perturbations as good as a brute-force search: searches beyond the power iteration.

The power iteration of :mod:`oos_drake.robust.mu_lower` finds *a* destabilizing perturbation;
on real parameter boxes it may stop at a local crossing a few percent beyond the first
instability that a plain check of the box's vertices finds, and on complex scalar structures
it may stop short of ``mu``. This module searches further, and every result is certified the
same way (a perturbation ``delta`` with ``det(I - M11(j omega) delta) = 0``, re-checked by
:meth:`Destabilizing.check` without the search):

* **Real parameters** (:func:`real_destabilizing`). With ``x`` the normalized parameters and
  ``A_cl(x) = A + Bw X (I - Dzw X)^{-1} Cz`` (``X = diag(x_k I)``) the closed loop, the
  smallest destabilizing box is

  .. math:: s^* = \min \{ \|x\|_\infty : \alpha(A_{cl}(x)) = 0 \}

  with ``alpha`` the spectral abscissa. The search checks the box's vertices (all of them up
  to :data:`MAX_VERTICES`, else random ones), the edges next to the best vertices, the
  direction of the power iteration's perturbation and random directions at the current
  level ``s``; every direction unstable at ``s`` is bisected to its crossing. Then a local
  search: maximize ``alpha`` over the box ``s [-1, 1]^k`` (L-BFGS-B with the analytic
  eigenvalue gradient); a point with ``alpha > 0`` is bisected back along its ray to the axis,
  which gives a smaller ``s``; repeat until the maximum over the box stays at the axis.
  The crossing is then polished in frequency (the eigenvalue of ``M11(j omega) x`` made
  exactly real), so the certificate holds to round-off.
* **Small mixed structures** (:func:`mixed_real_search`): up to three real blocks, the
  complex ones closed in (their ``mu`` as a function of the real parameters), rays and pattern
  searches over the real parameters.
* **Complex scalar blocks** (:func:`complex_phase_search`). For ``Delta = diag(e^{j theta_k}
  I)``, ``mu(M) = max_theta rho(M Delta)`` (the spectral radius is subharmonic in each block,
  its maximum over the closed disks is on their boundary). The search maximizes
  ``rho`` over the phases by BFGS from the power iteration's phases and random starts.

References: Packard & Doyle, "The complex structured singular value", Automatica 29 (1993);
Young, Newlin & Doyle, "Practical computation of the mixed mu problem" (ACC 1992).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.optimize import minimize

from oos_drake.robust.blocks import REAL, BlockStructure, parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response
from oos_drake.robust.mu_lower import CERTIFICATE_RTOL, certificate_residual, mu_lower_bound

#: Largest number of vertices checked one by one (``2^12``); beyond, random vertices.
MAX_VERTICES = 4096


@dataclass(frozen=True)
class Destabilizing:
    """A certified destabilizing perturbation of an LFR ``Fu(M, delta)``.

    Attributes
    ----------
    mu_lower : float
        ``1 / max_k ||delta_k||`` [-]: the lower bound of mu it proves.
    omega : float
        Frequency [rad/s] at which ``I - M11(j omega) delta`` is singular (a closed-loop pole
        at ``j omega``).
    delta : numpy.ndarray
        ``(sum(r), sum(c))`` normalized perturbation in the mussv structure.
    residual : float
        ``sigma_min(I - M11 delta) / (1 + ||M11 delta||)`` at ``omega`` [-].
    source : str
        Which search found it (``"vertex"``, ``"random"``, ``"start"``, ``"local"``,
        ``"phases"``).
    """

    mu_lower: float
    omega: float
    delta: np.ndarray
    residual: float
    source: str

    def check(self, A, Bw, Cz, Dzw, structure: BlockStructure, rtol: float = CERTIFICATE_RTOL):
        """Prove the bound again, without the search.

        Checks that ``delta`` has the block structure (real blocks real, scalar blocks
        repeated), that its largest block norm is ``1 / mu_lower``, and that
        ``sigma_min(I - M11(j omega) delta)`` is below ``rtol`` relative.

        Returns
        -------
        bool
        """
        d = np.asarray(self.delta, dtype=complex)
        if d.shape != (structure.n_rows, structure.n_cols) or not np.all(np.isfinite(d)):
            return False
        scale = np.abs(d).max(initial=0.0) + 1e-300
        rebuilt = np.zeros_like(d)
        for b in structure.blocks:
            part = d[b.r_slice, b.c_slice]
            if b.repeated:
                value = part[0, 0]
                if b.kind == REAL and abs(value.imag) > 1e-12 * scale:
                    return False
                rebuilt[b.r_slice, b.c_slice] = value * np.eye(b.rows)
            else:
                rebuilt[b.r_slice, b.c_slice] = part
        if np.abs(rebuilt - d).max(initial=0.0) > 1e-12 * scale:
            return False
        norm = float(np.max(structure.block_norms(d[None])[0]))
        if not np.isclose(norm * self.mu_lower, 1.0, rtol=1e-9):
            return False
        M = delta_channel_response(A, Bw, Cz, Dzw, [self.omega])[0]
        return bool(certificate_residual(M, d) <= rtol)


def closed_loop(A, Bw, Cz, Dzw, delta):
    """``A + Bw delta (I - Dzw delta)^{-1} Cz`` for a batch of perturbations ``(N, nw, nz)``.

    Returns
    -------
    numpy.ndarray
        ``(N, n, n)``; rows of ill-posed loops (``I - Dzw delta`` singular) are ``nan``.
    """
    delta = np.asarray(delta)
    X = np.eye(Dzw.shape[0]) - Dzw @ delta
    ok = np.linalg.cond(X) < 1e12
    out = np.full((delta.shape[0],) + A.shape, np.nan, dtype=np.result_type(A, delta))
    if np.any(ok):
        out[ok] = A + Bw @ delta[ok] @ np.linalg.solve(
            X[ok], np.broadcast_to(Cz, X[ok].shape[:1] + Cz.shape)
        )
    return out


class _RealLoop:
    """The closed loop of an LFR as a function of its normalized real parameters ``x``."""

    def __init__(self, A, Bw, Cz, Dzw, structure):
        self.A, self.Bw, self.Cz, self.Dzw = (np.asarray(v, dtype=float) for v in (A, Bw, Cz, Dzw))
        self.structure = structure
        blocks = structure.blocks
        self.k = len(blocks)
        # parameter of each w channel (real structures: rows of delta)
        self.owner = np.concatenate([np.full(b.rows, i) for i, b in enumerate(blocks)])
        self.rows = np.concatenate([np.arange(b.rows) + b.row_offset for b in blocks])
        self.cols = np.concatenate([np.arange(b.cols) + b.col_offset for b in blocks])

    def delta(self, x):
        """``(N, k)`` parameters -> ``(N, nw, nz)`` perturbations."""
        x = np.atleast_2d(x)
        d = np.zeros((x.shape[0], self.structure.n_rows, self.structure.n_cols))
        d[:, self.rows, self.cols] = x[:, self.owner]
        return d

    def abscissa(self, x):
        """Spectral abscissa [rad/s] of the closed loop at each row of ``x`` (inf: ill-posed)."""
        Acl = closed_loop(self.A, self.Bw, self.Cz, self.Dzw, self.delta(x))
        bad = ~np.all(np.isfinite(Acl), axis=(1, 2))
        out = np.full(Acl.shape[0], np.inf)
        if np.any(~bad):
            out[~bad] = np.linalg.eigvals(Acl[~bad]).real.max(axis=1)
        return out

    def abscissa_gradient(self, x):
        """Spectral abscissa and its gradient in ``x`` (rightmost eigenvalue assumed simple)."""
        D = self.delta(x)[0]
        X = np.eye(self.Dzw.shape[0]) - self.Dzw @ D
        Y = np.eye(D.shape[0]) - D @ self.Dzw
        P = np.linalg.solve(X, self.Cz)  # (I - Dzw D)^{-1} Cz
        Acl = self.A + self.Bw @ D @ P
        lam, vl, vr = scipy.linalg.eig(Acl, left=True, right=True)
        i = int(np.argmax(lam.real))
        u, v = vl[:, i], vr[:, i]
        p = P @ v  # (nz,)
        q = np.linalg.solve(Y.T, self.Bw.T @ np.conj(u))  # (nw,): u^* Bw (I - D Dzw)^{-1}
        dl = (q[self.rows] * p[self.cols]) / (np.conj(u) @ v)
        grad = np.bincount(self.owner, weights=dl.real, minlength=self.k)
        return float(lam[i].real), grad

    def smallest_crossing(self, directions, level, steps=48):
        """The direction whose ray reaches the axis first, and that scale.

        Bisection on a common level: the directions unstable at the level stay candidates
        (each then has a crossing at or below it). Returns ``(index, scale)`` or
        ``(None, inf)`` when every ray is stable at ``level``.
        """
        alive = np.flatnonzero(self.abscissa(level * directions) >= 0)
        if alive.size == 0:
            return None, np.inf
        lo, hi = 0.0, float(level)
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            bad = self.abscissa(mid * directions[alive]) >= 0
            if np.any(bad):
                hi, alive = mid, alive[bad]
            else:
                lo = mid
        return int(alive[0]), hi

    def crossing(self, x, t_hi):
        """Scale ``t`` in ``(0, t_hi]`` where the rays ``t x`` reach the axis (first unstable
        point of a coarse scan, then bisection); ``inf`` where ``t_hi x`` is stable.

        ``x`` is ``(N, k)``, ``t_hi`` ``(N,)``; returns ``(N,)``.
        """
        x = np.atleast_2d(x)
        n = x.shape[0]
        t_hi = np.broadcast_to(np.asarray(t_hi, dtype=float), (n,)).copy()
        unstable = self.abscissa(t_hi[:, None] * x) >= 0
        out = np.full(n, np.inf)
        idx = np.flatnonzero(unstable)
        if idx.size == 0:
            return out
        hi = t_hi[idx].copy()
        for frac in np.linspace(0.1, 0.9, 9):  # the first crossing, not any crossing
            t = frac * t_hi[idx]
            bad = (self.abscissa(t[:, None] * x[idx]) >= 0) & (t < hi)
            hi = np.where(bad, t, hi)
        lo = np.where(hi > 0.1 * t_hi[idx] + 1e-300, hi - 0.1 * t_hi[idx], 0.0)
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            bad = self.abscissa(mid[:, None] * x[idx]) >= 0
            hi = np.where(bad, mid, hi)
            lo = np.where(bad, lo, mid)
        out[idx] = hi
        return out


def _box_directions(k, rng, n_random, max_vertices=MAX_VERTICES):
    """Vertices of ``[-1, 1]^k`` (all, or ``max_vertices`` random ones) and ``n_random``
    random directions scaled to ``||x||_inf = 1``."""
    if 2**k <= max_vertices:
        bits = (np.arange(2**k)[:, None] >> np.arange(k)[None, :]) & 1
        vertices = 2.0 * bits - 1.0
    else:
        vertices = rng.choice([-1.0, 1.0], size=(max_vertices, k))
    r = rng.uniform(-1.0, 1.0, size=(n_random, k))
    r /= np.abs(r).max(axis=1, keepdims=True)
    return vertices, r


def real_destabilizing(
    A,
    Bw,
    Cz,
    Dzw,
    structure: BlockStructure,
    *,
    start: np.ndarray | None = None,
    scale: float | None = None,
    random_directions: int = 200,
    local_starts: int = 3,
    rounds: int = 12,
    max_vertices: int = MAX_VERTICES,
    rng: np.random.Generator | None = None,
) -> Destabilizing | None:
    """Smallest destabilizing box of real parameters: vertex, edge, ray and local searches.

    Parameters
    ----------
    A, Bw, Cz, Dzw : numpy.ndarray
        State matrices of the LFR's Delta channel (real; the loop at ``x = 0`` must be stable).
    structure : BlockStructure
        Repeated real scalar blocks only.
    start : numpy.ndarray, optional
        ``(k,)`` normalized parameters of a known destabilizing perturbation (e.g. the power
        iteration's), searched first as a direction.
    scale : float, optional
        Upper end of the search (normalized size); default ``||start||_inf`` or 10.
    random_directions : int
        Random directions checked besides the vertices.
    local_starts : int
        Best points from which the local search runs.
    rounds : int
        Rounds of each local search (maximize the abscissa on the box, bisect back).
    max_vertices : int
        All vertices up to this many (``2^k``), else this many random vertices.
    rng : numpy.random.Generator, optional
        Random directions (default: seeded).

    Returns
    -------
    Destabilizing or None
        The certified perturbation (None: nothing unstable in ``scale`` times the box, or
        the crossing could not be certified).
    """
    if any(b.kind != REAL for b in structure.blocks):
        raise ValueError("real_destabilizing: the structure must have real blocks only")
    rng = np.random.default_rng(0) if rng is None else rng
    loop = _RealLoop(A, Bw, Cz, Dzw, structure)
    k = loop.k
    if scale is None:
        scale = float(np.abs(start).max()) if start is not None else 10.0
    vertices, randoms = _box_directions(k, rng, random_directions, max_vertices)
    sources = [("vertex", vertices), ("random", randoms)]
    if start is not None and np.abs(start).max() > 0:
        s = np.asarray(start, dtype=float)
        sources.insert(0, ("start", (s / np.abs(s).max())[None]))
    dirs = np.vstack([d for _, d in sources])
    labels = np.concatenate([[name] * len(d) for name, d in sources])
    i, best_t = loop.smallest_crossing(dirs, float(scale) * (1.0 + 1e-9))
    if i is None:
        return None
    best_x, best_src = dirs[i] * best_t, str(labels[i])
    # runners-up (most unstable just above the best level), then the edges next to them
    ranked = [(best_t, best_x, best_src)]
    alpha = loop.abscissa(1.03 * best_t * dirs) if local_starts > 1 else np.zeros(0)
    top = [j for j in np.argsort(-alpha)[: local_starts - 1] if alpha[j] >= 0]
    t = loop.crossing(dirs[top], np.full(len(top), 1.03 * best_t))
    ranked += [
        (float(t[m]), dirs[j] * t[m], str(labels[j]))
        for m, j in enumerate(top)
        if np.isfinite(t[m])
    ]
    ranked.sort(key=lambda item: item[0])
    edge_points = []
    for _, x, _ in ranked[:local_starts]:
        d = x / np.abs(x).max()
        for j in range(k):
            for value in np.linspace(-1.0, 1.0, 9)[1:-1]:
                e = d.copy()
                e[j] = value
                edge_points.append(e)
    j, t_edge = loop.smallest_crossing(np.array(edge_points), best_t * (1 - 1e-12))
    if j is not None:
        ranked.insert(0, (t_edge, edge_points[j] * t_edge, "edge"))
    best_t, best_x, best_src = ranked[0]
    for t0, x0, _ in ranked[:local_starts]:
        t_loc, x_loc = _local_search(loop, x0, t0, rounds)
        if t_loc < best_t * (1 - 1e-12):
            best_t, best_x, best_src = t_loc, x_loc, "local"
    return _certify_real(loop, best_x, best_src)


def _local_search(loop, x0, s0, rounds):
    """Shrink the destabilizing box from the crossing ``x0`` (``||x0||_inf = s0``): maximize
    the spectral abscissa on ``s [-1, 1]^k``; a point beyond the axis is bisected back."""
    s, x = s0, x0.copy()
    for _ in range(rounds):
        bounds = [(-s, s)] * loop.k

        def negative(y):
            value, grad = loop.abscissa_gradient(y)
            return -value, -grad

        try:
            out = minimize(negative, x, jac=True, method="L-BFGS-B", bounds=bounds,
                           options=dict(maxiter=60))  # fmt: skip
        except (np.linalg.LinAlgError, ValueError):
            break
        y = np.clip(out.x, -s, s)
        if loop.abscissa(y[None])[0] <= 0:
            break
        t = loop.crossing(y[None] / s, np.array([s]))[0]
        if not np.isfinite(t) or t >= s * (1 - 1e-10):
            break
        # the crossing lies on the ray through y: its box is t (the ray has ||.||_inf = 1)
        x = y / s * t
        s = t
    return s, x


def _certify_real(loop, x, source):
    """The exact crossing near the closed-loop pole of ``x`` on the axis: the eigenvalue of
    ``M11(j omega) X`` made real by a secant search in ``omega``; None if not certified."""
    D = loop.delta(x[None])[0]
    Acl = closed_loop(loop.A, loop.Bw, loop.Cz, loop.Dzw, D[None])[0]
    lam = np.linalg.eigvals(Acl)
    i = int(np.argmax(lam.real))
    omega = abs(float(lam[i].imag))

    def eig_near_one(w):
        M = delta_channel_response(loop.A, loop.Bw, loop.Cz, loop.Dzw, [w])[0]
        ev = np.linalg.eigvals(M @ D)
        return ev[np.argmin(np.abs(ev - 1.0))], M

    best = None
    candidates = [omega] if omega > 0 else [0.0]
    for w0 in candidates:
        w_prev, w = w0 * (1 + 1e-7) + 1e-12, w0
        mu_prev = eig_near_one(w_prev)[0]
        for _ in range(30):
            mu, M = eig_near_one(w)
            if abs(mu.imag) <= 1e-15 * abs(mu) or w == 0.0:
                break
            slope = (mu.imag - mu_prev.imag) / (w - w_prev) if w != w_prev else 0.0
            if slope == 0.0 or not np.isfinite(slope):
                break
            w_prev, mu_prev = w, mu
            w = max(w - mu.imag / slope, 0.0)
        mu, M = eig_near_one(w)
        if abs(mu.real) < 1e-300:
            continue
        delta = D / mu.real
        res = float(certificate_residual(M, delta))
        if res <= CERTIFICATE_RTOL:
            norm = float(np.abs(delta).max())
            cand = Destabilizing(1.0 / norm, float(w), delta.astype(complex), res, source)
            if best is None or cand.mu_lower > best.mu_lower:
                best = cand
    return best


def complex_phase_search(
    M: np.ndarray,
    structure: BlockStructure,
    *,
    start: np.ndarray | None = None,
    restarts: int = 8,
    rng: np.random.Generator | None = None,
):
    """Lower bound of mu for repeated complex scalar blocks: ``max_theta rho(M Delta(theta))``.

    Parameters
    ----------
    M : numpy.ndarray
        ``(sum(c), sum(r))`` complex matrix.
    structure : BlockStructure
        Repeated complex scalar blocks only.
    start : numpy.ndarray, optional
        ``(sum(r), sum(c))`` perturbation whose phases start the first search (e.g. the
        power iteration's).
    restarts : int
        Random phase starts besides ``start``.
    rng : numpy.random.Generator, optional
        Random starts (default: seeded).

    Returns
    -------
    tuple
        ``(mu_lower, delta, residual)``: ``delta = Delta(theta) / lambda`` with ``lambda`` the
        dominant eigenvalue of ``M Delta(theta)``, so ``det(I - M delta) = 0`` and
        ``||delta|| = 1 / mu_lower`` (``(0, zeros, nan)`` if ``M Delta`` is nilpotent).
    """
    if any(not b.repeated or b.kind == REAL for b in structure.blocks):
        raise ValueError("complex_phase_search: repeated complex scalar blocks only")
    rng = np.random.default_rng(0) if rng is None else rng
    M = np.asarray(M, dtype=complex)
    blocks = structure.blocks
    k = len(blocks)
    owner = np.concatenate([np.full(b.rows, i) for i, b in enumerate(blocks)])
    rows = np.concatenate([np.arange(b.rows) + b.row_offset for b in blocks])
    cols = np.concatenate([np.arange(b.cols) + b.col_offset for b in blocks])

    def Delta(theta):
        d = np.zeros((structure.n_rows, structure.n_cols), dtype=complex)
        d[rows, cols] = np.exp(1j * theta[owner])
        return d

    def negative_rho(phi):  # the first phase is absorbed by the eigenvalue's
        theta = np.concatenate([[0.0], phi])
        D = Delta(theta)
        lam, vl, vr = scipy.linalg.eig(M @ D, left=True, right=True)
        i = int(np.argmax(np.abs(lam)))
        u, v = vl[:, i], vr[:, i]
        # d lambda / d theta_m = u^* M (j E_m D) v / (u^* v)
        w = np.conj(u) @ M  # (r,)
        dv = D @ v  # (r,)
        dl = 1j * w[rows] * dv[rows] / (np.conj(u) @ v)
        dlam = np.bincount(owner, weights=dl.real, minlength=k) + 1j * np.bincount(
            owner, weights=dl.imag, minlength=k
        )
        mag = abs(lam[i]) + 1e-300
        grad = np.real(np.conj(lam[i]) * dlam) / mag
        return -mag, -grad[1:]

    starts = []
    if start is not None:
        phases = np.angle(np.asarray(start)[rows, cols])
        th = np.array([phases[owner == m][0] for m in range(k)])
        starts.append(th[1:] - th[0])
    starts += [rng.uniform(-np.pi, np.pi, k - 1) for _ in range(restarts)]
    if k == 1:
        starts = [np.zeros(0)]
    best = (-np.inf, None)
    for phi0 in starts:
        if k == 1:
            value, phi = negative_rho(phi0)[0], phi0
        else:
            out = minimize(negative_rho, phi0, jac=True, method="BFGS", options=dict(maxiter=200))
            value, phi = out.fun, out.x
        if -value > best[0]:
            best = (-value, phi)
    D = Delta(np.concatenate([[0.0], best[1]]))
    ev = np.linalg.eigvals(M @ D)
    lam = ev[np.argmax(np.abs(ev))]
    if abs(lam) <= 1e-13 * (np.linalg.norm(M) + 1e-300):
        return 0.0, np.zeros_like(D), float("nan")
    delta = D / lam
    return 1.0 / float(np.abs(delta).max()), delta, float(certificate_residual(M, delta))


#: Largest number of real blocks for which :func:`mixed_real_search` runs (its directions are
#: the ``MIXED_GRID_POINTS ** k - (MIXED_GRID_POINTS - 2) ** k`` grid points on the box's surface).
MIXED_MAX_REAL = 3
#: Grid points per real parameter of :func:`mixed_real_search` (odd: the grid holds 0).
MIXED_GRID_POINTS = 9
#: Grid points per real parameter of the grid of parameters in :func:`mixed_real_search`.
MIXED_POINT_GRID = 17
#: Best grid directions that start a pattern search in :func:`mixed_real_search`.
MIXED_STARTS = 3
#: Points of each ray's scan in :func:`mixed_real_search`, and bisection steps of its crossing.
MIXED_RAY_POINTS = 48
MIXED_BISECTIONS = 40
#: Scan points and bisection steps of the pattern search's trial rays (on ``[0, t]``, ``t`` the
#: best crossing so far), and the step of its directions below which it stops (coarse: the
#: search in parameter space polishes).
MIXED_TRIAL_POINTS = 8
MIXED_TRIAL_BISECTIONS = 20
MIXED_RAY_STEP_TOL = 1e-3
#: Step (relative to ``||y||_inf``) below which the search in parameter space stops.
MIXED_STEP_TOL = 1e-6
#: Largest number of rounds of one pattern search of :func:`mixed_real_search`.
MIXED_ROUNDS = 200


def _complex_substructure(structure: BlockStructure):
    """``(real_rows, real_cols, cplx_rows, cplx_cols, owner, sub)``: the ``Delta``-row and
    -column indices of the real and of the complex blocks, the real block of each real row, and
    the structure of the complex blocks alone (``None`` if there is none)."""
    real = [b for b in structure.blocks if b.kind == REAL]
    cplx = [b for b in structure.blocks if b.kind != REAL]

    def idx(blocks, attr, size):
        parts = [np.arange(getattr(b, size)) + getattr(b, attr) for b in blocks]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)

    owner = np.concatenate([np.full(b.rows, i) for i, b in enumerate(real)] or [[]]).astype(int)
    sub = parse_blk([[b.rows, 0 if b.repeated else b.cols] for b in cplx]) if cplx else None
    return (
        idx(real, "row_offset", "rows"),
        idx(real, "col_offset", "cols"),
        idx(cplx, "row_offset", "rows"),
        idx(cplx, "col_offset", "cols"),
        owner,
        sub,
    )


def mixed_real_search(
    M: np.ndarray,
    structure: BlockStructure,
    *,
    radius: float,
    start: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
):
    r"""Lower bound of mixed mu by a search over the real parameters' directions (few real blocks).

    With the real parameters ``y`` fixed (``Y = diag(y_k I)``), ``I - M Delta`` is singular
    exactly when ``I - M_C(y) Delta_C`` is, with ``M_C(y) = M_CC + M_CR Y (I - M_RR Y)^{-1}
    M_RC`` the loop closed on the real channels; the smallest such complex ``Delta_C`` has norm
    ``1 / mu_C(M_C(y))`` (exact for a single complex block: the spectral radius of a repeated
    scalar, the largest singular value of a full block; otherwise the power iteration's
    certified complex lower bound). Along a ray ``y = t u``
    (``||u||_inf = 1``) the first singular perturbation is at the smallest ``t`` with
    ``t mu_C(M_C(t u)) >= 1`` (or, for a real ``M_RR``, a sign change of ``det(I - M_RR Y)``:
    a pole of ``M_C``, ``Delta_C = 0``), and ``1 / mu = min_u t(u)``. Each ray is scanned on
    :data:`MIXED_RAY_POINTS` points of ``[0, radius]``, its first crossing bisected; the
    directions are the points of the box's surface on a grid (:data:`MIXED_GRID_POINTS` per
    parameter) and ``start``'s, then a pattern search (moves ``step * {-1, 0, 1}^k`` and random
    ones, the step halved when none improves) runs from the :data:`MIXED_STARTS` best. A ray
    that only touches the singular set may cross it between its scan points, so a second
    pattern search minimizes ``max(||y||_inf, 1 / mu_C(M_C(y)))`` in the parameters themselves,
    from the two best crossings, the :data:`MIXED_STARTS` best points of a grid of ``[-r, r]^k``
    (:data:`MIXED_POINT_GRID` per parameter, ``r`` the best crossing so far: the minimizer has
    ``||y||_inf <= 1 / mu <= r``) and ``start``'s parameters. The returned ``delta`` is checked
    like the power iteration's (``residual``); the caller keeps it only if that is at round-off.

    Cost: about 35 ms for 2 real scalars and a complex one (numpy, closed form inside); with
    several complex blocks each point runs a power iteration: about 300 ms on a 9 x 9 matrix
    with two real, a full and three complex scalar blocks.

    Parameters
    ----------
    M : numpy.ndarray
        ``(sum(c), sum(r))`` complex matrix.
    structure : BlockStructure
        At least one real and one complex block, at most :data:`MIXED_MAX_REAL` real blocks.
    radius : float
        Length of the rays (e.g. ``1 / lower``, or a few times ``1 / upper``).
    start : numpy.ndarray, optional
        ``(sum(r), sum(c))`` perturbation whose real parameters give one more direction (e.g.
        the power iteration's ``delta``).
    rng : numpy.random.Generator, optional
        Random directions of the pattern search (default: seeded).

    Returns
    -------
    tuple
        ``(mu_lower, delta, residual)``: ``det(I - M delta) = 0`` and ``||delta|| = 1 /
        mu_lower`` (``(0, zeros, nan)`` if no ray meets a singular perturbation).
    """
    real_rows, real_cols, c_rows, c_cols, owner, sub = _complex_substructure(structure)
    k = int(owner.max()) + 1 if owner.size else 0
    if k == 0 or sub is None or k > MIXED_MAX_REAL:
        raise ValueError(
            f"mixed_real_search: needs 1 to {MIXED_MAX_REAL} real blocks and a complex one"
        )
    rng = np.random.default_rng(0) if rng is None else rng
    M = np.asarray(M, dtype=complex)
    M_RR = M[np.ix_(real_cols, real_rows)]
    M_RC = M[np.ix_(real_cols, c_rows)]
    M_CR = M[np.ix_(c_cols, real_rows)]
    M_CC = M[np.ix_(c_cols, c_rows)]
    one_block = len(sub.blocks) == 1
    real_loop = not np.any(M_RR.imag)  # det(I - M_RR Y) real: its sign changes at poles
    eye = np.eye(real_rows.size)

    def close(y):
        """``(size, delta_C, mu_C, det)`` at the real parameters ``y`` ``(N, k)``:
        ``size = max(||y||_inf, 1 / mu_C(M_C(y)))`` (``||y||_inf`` where the real loop itself
        is singular) and ``det = det(I - M_RR Y)``."""
        Y = y[:, owner][:, :, None] * eye  # (N, nR, nR), Delta-rows x Delta-cols
        A = eye - M_RR @ Y
        with np.errstate(all="ignore"):
            X = np.linalg.solve(A, np.broadcast_to(M_RC, (y.shape[0],) + M_RC.shape))
            MC = M_CC + M_CR @ Y @ X
        ok = np.all(np.isfinite(MC), axis=(1, 2))
        MC = np.where(ok[:, None, None], MC, 0.0)
        if one_block:
            mu_c, dC = _single_block_mu(MC, sub.blocks[0])
        else:
            low = mu_lower_bound(MC, sub, restarts=2, rng=rng, polish_starts=1)
            mu_c, dC = low.lower, low.delta
        mu_c = np.where(ok, mu_c, np.inf)
        with np.errstate(divide="ignore"):
            size = np.maximum(np.max(np.abs(y), axis=1), 1.0 / mu_c)
        return size, dC, mu_c, np.linalg.det(A)

    def crossed(y):
        """``(hit, delta_C)``: a singular perturbation with real parameters ``y`` and
        ``||Delta_C|| <= ||y||_inf`` is known, or a pole of ``M_C`` was passed."""
        _, dC, mu_c, det = close(y)
        hit = np.max(np.abs(y), axis=1) * mu_c >= 1.0
        if real_loop:
            hit |= det.real <= 0.0  # det(I) = 1 at y = 0
        return hit, dC

    ts = np.linspace(0.0, radius, MIXED_RAY_POINTS + 1)[1:]

    def first_crossing(U, ts, bisections=MIXED_BISECTIONS):
        """``(t, delta_C)``: the first crossing along each ray ``t U[i]`` (inf if none before
        ``ts[-1]``), scanned at ``ts`` then bisected."""
        n = U.shape[0]
        hit, _ = crossed((ts[None, :, None] * U[:, None, :]).reshape(-1, k))
        hit = hit.reshape(n, ts.size)
        has = np.any(hit, axis=1)
        j = np.argmax(hit, axis=1)
        hi = np.where(has, ts[j], np.inf)
        lo = np.where(j > 0, ts[np.maximum(j - 1, 0)], 0.0)
        rows = np.flatnonzero(has)
        dC = np.zeros((n, sub.n_rows, sub.n_cols), dtype=complex)
        if rows.size == 0:
            return hi, dC
        lo_r, hi_r, U_r = lo[rows], hi[rows], U[rows]
        for _ in range(bisections):
            mid = 0.5 * (lo_r + hi_r)
            h, _ = crossed(mid[:, None] * U_r)
            hi_r, lo_r = np.where(h, mid, hi_r), np.where(h, lo_r, mid)
        _, dC[rows] = crossed(hi_r[:, None] * U_r)
        hi[rows] = hi_r
        return hi, dC

    def ray_value(U, t):
        # only a crossing before the current one is of use: scan [0, t] coarsely
        ts = t * np.linspace(0.0, 1.0, MIXED_TRIAL_POINTS + 1)[1:]
        return first_crossing(_unit(U), ts, MIXED_TRIAL_BISECTIONS)

    def point_value(y, t):
        size, dC, _, _ = close(y)
        return size, dC

    g = np.linspace(-1.0, 1.0, MIXED_GRID_POINTS)
    grid = np.stack([a.ravel() for a in np.meshgrid(*([g] * k), indexing="ij")], axis=1)
    dirs = grid[np.max(np.abs(grid), axis=1) == 1.0]
    y0 = None
    if start is not None:
        y0 = np.asarray(start)[real_rows, real_cols].real
        y0 = np.array([y0[owner == m][0] for m in range(k)])
        if np.any(y0):
            dirs = np.vstack([dirs, _unit(y0[None, :])])
    t, dC = first_crossing(dirs, ts)
    found = []  # (size, y, delta_C)
    for i in np.argsort(t, kind="stable")[:MIXED_STARTS]:
        if np.isfinite(t[i]):
            u, tu, du = _pattern_search(
                ray_value, dirs[i], t[i], dC[i], 0.25, MIXED_RAY_STEP_TOL, rng, _unit
            )
            found.append((tu, tu * u, du))
    # the rays' first crossings are local minima along the directions; polish the best ones
    # (and the power iteration's parameters) in the parameter space itself
    starts = sorted(found, key=lambda c: c[0])[: MIXED_STARTS - 1]
    # and the best points of a grid of [-r, r]^k with r the best crossing so far (the
    # minimizer has ||y||_inf <= 1 / mu <= r; a ray that only touches the singular set may
    # cross it between its scan points)
    g = np.linspace(-1.0, 1.0, MIXED_POINT_GRID)
    points = np.stack([a.ravel() for a in np.meshgrid(*([g] * k), indexing="ij")], axis=1)
    points *= min([radius] + [c[0] for c in found])
    size, dC_grid, _, _ = close(points)
    for i in np.argsort(size, kind="stable")[:MIXED_STARTS]:
        starts.append((size[i], points[i], dC_grid[i]))
    if y0 is not None:
        size0, d0, _, _ = close(y0[None, :])
        starts.append((size0[0], y0, d0[0]))
    for f0, y, d in starts:
        if np.isfinite(f0):
            step = 0.05 * max(np.max(np.abs(y)), 1e-3 * radius)
            y, f, d = _pattern_search(point_value, y, f0, d, step, MIXED_STEP_TOL, rng, None)
            found.append((f, y, d))
    f, y, dC = min(found, key=lambda c: c[0], default=(np.inf, None, None))
    delta = np.zeros((structure.n_rows, structure.n_cols), dtype=complex)
    if not np.isfinite(f):
        return 0.0, delta, float("nan")
    delta[real_rows, real_cols] = y[owner]
    delta[np.ix_(c_rows, c_cols)] = dC
    norm = float(np.max(structure.block_norms(delta)))
    return 1.0 / norm, delta, float(certificate_residual(M, delta))


def _single_block_mu(MC, block):
    """``(mu, delta)`` of a batch ``MC`` ``(N, c, r)`` for one complex block, exact: the
    spectral radius (repeated scalar, ``delta = I / lambda``) or the largest singular value
    (full, ``delta = v u^* / sigma``); ``delta`` is zero where ``mu`` is."""
    if block.repeated and block.rows == 1:  # one complex scalar: mu = |M_C|
        mu = np.abs(MC[:, 0, 0])
        with np.errstate(all="ignore"):
            return mu, np.where(mu > 0, 1.0 / MC[:, 0, 0], 0.0)[:, None, None]
    if block.repeated:
        ev = np.linalg.eigvals(MC)
        lam = ev[np.arange(ev.shape[0]), np.argmax(np.abs(ev), axis=1)]
        mu = np.abs(lam)
        with np.errstate(all="ignore"):
            inv = np.where(mu > 0, 1.0 / lam, 0.0)
        return mu, inv[:, None, None] * np.eye(block.rows)
    u, sv, vh = np.linalg.svd(MC)
    mu = sv[:, 0]
    with np.errstate(all="ignore"):
        inv = np.where(mu > 0, 1.0 / mu, 0.0)
    return mu, inv[:, None, None] * (
        np.conj(vh[:, 0, :])[:, :, None] * np.conj(u[:, :, 0])[:, None, :]
    )


def _unit(v):
    """Rows of ``v`` scaled to ``||.||_inf = 1``."""
    return v / np.maximum(np.max(np.abs(v), axis=-1, keepdims=True), 1e-300)


def _pattern_search(value, x, f, d, step, tol, rng, project):
    """Minimize ``value`` from ``x`` (value ``f``, attachment ``d``): each round tries the moves
    ``step * {-1, 0, 1}^k`` and ``2 k`` random ones at once (``value(X, f) -> (F, D)`` on the
    rows of ``X``, projected by ``project``), takes the best if it improves, else halves
    ``step``; stops below ``tol`` relative to ``||x||``. Returns ``(x, f, d)``."""
    k = x.size
    moves = np.stack([a.ravel() for a in np.meshgrid(*([[-1.0, 0.0, 1.0]] * k))], axis=1)
    moves = moves[np.any(moves != 0, axis=1)]
    scale = max(float(np.max(np.abs(x))), 1e-300)
    for _ in range(MIXED_ROUNDS):
        if step <= tol * scale:
            break
        rand = _unit(rng.standard_normal((2 * k, k)))
        trial = x + step * np.vstack([moves, rand])
        if project is not None:
            trial = project(trial)
        ft, dt = value(trial, f)
        j = int(np.argmin(ft))
        if ft[j] < f:
            x, f, d = trial[j], ft[j], dt[j]
        else:
            step /= 2.0
    return x, f, d


def improve_destabilizing(
    A,
    Bw,
    Cz,
    Dzw,
    structure: BlockStructure,
    lower: float,
    delta: np.ndarray | None,
    omega: np.ndarray,
    mu_upper: np.ndarray,
    *,
    frequencies: int = 4,
    restarts: int = 64,
    rng: np.random.Generator | None = None,
) -> Destabilizing | None:
    """A destabilizing perturbation better than the power iteration's, if the searches find one.

    Real structures: :func:`real_destabilizing` from ``delta``'s direction (whole box, all
    frequencies at once through the closed-loop poles). Repeated complex scalar structures:
    :func:`complex_phase_search` at the ``frequencies`` largest upper bounds and at the
    frequency of ``delta``. Other structures (mixed, full blocks): the power iteration of
    :func:`~oos_drake.robust.mu_lower.mu_lower_bound` from ``restarts`` random starts (longer
    runs) at those frequencies.

    Parameters
    ----------
    A, Bw, Cz, Dzw : numpy.ndarray
        State matrices of the Delta channel of a nominally stable LFR.
    structure : BlockStructure
    lower : float
        Best certified lower bound of mu so far [-] (0: none).
    delta : numpy.ndarray or None
        Its perturbation ``(sum(r), sum(c))``.
    omega, mu_upper : numpy.ndarray
        Analyzed frequencies [rad/s] and the upper bounds of mu there (where to search).
    frequencies : int
        Frequencies searched for complex and mixed structures.
    restarts : int
        Random starts of the power iteration for mixed structures.
    rng : numpy.random.Generator, optional

    Returns
    -------
    Destabilizing or None
        Only when certified and strictly better than ``lower``.
    """
    if np.shape(A)[0] == 0:  # a static LFR has no pole to move: nothing beyond the sweep
        return None
    rng = np.random.default_rng(0) if rng is None else rng
    kinds = {b.kind for b in structure.blocks}
    found = None
    if kinds == {REAL}:
        start = None
        if delta is not None and lower > 0:
            start = np.array([delta[b.row_offset, b.col_offset].real for b in structure.blocks])
        peak_up = float(np.max(mu_upper, initial=0.0))
        if lower > 0:
            scale = 1.0 / lower
        elif peak_up > 0:
            scale = 1.0 / peak_up * 4.0  # nothing found yet: search a box beyond the upper bound
        else:
            return None
        found = real_destabilizing(A, Bw, Cz, Dzw, structure, start=start, scale=scale, rng=rng)
    elif all(b.repeated and b.kind != REAL for b in structure.blocks):
        order = np.argsort(-np.asarray(mu_upper))[:frequencies]
        where = list(np.asarray(omega)[order])
        M = delta_channel_response(A, Bw, Cz, Dzw, where)
        for w, Mw in zip(where, M, strict=True):
            value, d, res = complex_phase_search(Mw, structure, start=delta, rng=rng)
            if value > 0 and res <= CERTIFICATE_RTOL and (found is None or value > found.mu_lower):
                found = Destabilizing(value, float(w), d, res, "phases")
    else:  # mixed or full blocks: the power iteration from many more starts
        order = np.argsort(-np.asarray(mu_upper))[:frequencies]
        where = list(np.asarray(omega)[order])
        M = delta_channel_response(A, Bw, Cz, Dzw, where)
        res = mu_lower_bound(M, structure, restarts=restarts, iters=200, polish_starts=8, rng=rng)
        j = int(np.argmax(res.lower))
        if res.lower[j] > 0 and res.residual[j] <= CERTIFICATE_RTOL:
            found = Destabilizing(
                float(res.lower[j]), float(where[j]), res.delta[j], float(res.residual[j]),
                "restarts",
            )  # fmt: skip
    if found is None or found.mu_lower <= lower * (1 + 1e-12):
        return None
    return found


@dataclass(frozen=True)
class WorstGain:
    """Parameters of a box that attain a peak gain (a certified lower bound of ``wcgain``).

    Attributes
    ----------
    gain : float
        H-infinity norm of the closed loop at ``x`` [-] (in the model's output/input units).
    omega : float
        Frequency of that peak [rad/s].
    x : numpy.ndarray
        ``(k,)`` normalized parameters in ``[-1, 1]`` (block order of the structure).
    source : str
        ``"vertex"``, ``"random"``, ``"local"``.
    evaluations : int
        Closed loops evaluated (frequency responses and H-infinity norms).
    """

    gain: float
    omega: float
    x: np.ndarray
    source: str
    evaluations: int

    def check(self, A, B, C, D, nz, nw, structure, rtol: float = 1e-6) -> bool:
        """Prove the gain again: ``x`` in the box, the closed loop at ``x`` stable, and its
        gain at ``omega`` at least ``gain (1 - rtol)``."""
        x = np.asarray(self.x, dtype=float)
        if x.shape != (len(structure.blocks),) or np.any(np.abs(x) > 1 + 1e-12):
            return False
        Acl, Bcl, Ccl, Dcl = _closed_loop_ss(A, B, C, D, nz, nw, structure, x[None])
        if not np.all(np.isfinite(Acl)) or np.linalg.eigvals(Acl[0]).real.max(initial=-1) >= 0:
            return False
        n = Acl.shape[-1]
        G = Dcl[0] + Ccl[0] @ np.linalg.solve(1j * self.omega * np.eye(n) - Acl[0], Bcl[0])
        return bool(np.linalg.norm(G, ord=2) >= self.gain * (1 - rtol))


def _diag_delta(structure, x):
    """``(N, k)`` real parameters -> ``(N, sum(r), sum(c))`` perturbations."""
    x = np.atleast_2d(x)
    d = np.zeros((x.shape[0], structure.n_rows, structure.n_cols))
    for i, b in enumerate(structure.blocks):
        idx = np.arange(b.rows)
        d[:, b.row_offset + idx, b.col_offset + idx] = x[:, i : i + 1]
    return d


def _closed_loop_ss(A, B, C, D, nz, nw, structure, x):
    """State space ``(A, B, C, D)`` of the loop closed by the parameters ``x`` (``(N, k)``),
    batched; ``B, C, D`` hold ``[w; u]`` / ``[z; y]`` partitions of the LFR."""
    Bw, Bu = B[:, :nw], B[:, nw:]
    Cz, Cy = C[:nz], C[nz:]
    Dzw, Dzu, Dyw, Dyu = D[:nz, :nw], D[:nz, nw:], D[nz:, :nw], D[nz:, nw:]
    delta = _diag_delta(structure, x)
    X = np.eye(nz) - Dzw @ delta
    S = delta @ np.linalg.solve(
        X, np.broadcast_to(np.hstack([Cz, Dzu]), X.shape[:1] + (nz, C.shape[1] + Bu.shape[1]))
    )
    n = A.shape[0]
    SC, SD = S[..., :n], S[..., n:]
    return A + Bw @ SC, Bu + Bw @ SD, Cy + Dyw @ SC, Dyu + Dyw @ SD


def real_worst_gain(
    A,
    B,
    C,
    D,
    nz: int,
    nw: int,
    structure: BlockStructure,
    omega,
    *,
    random_points: int = 1000,
    exact_points: int = 48,
    local_starts: int = 3,
    rng: np.random.Generator | None = None,
) -> WorstGain | None:
    """Worst-case peak gain over a box of real parameters: vertices, random points, local search.

    1. Every vertex (up to :data:`MAX_VERTICES`) and ``random_points`` random points of the
       box, screened by their gain at the frequencies ``omega`` (frequency responses).
    2. The ``exact_points`` best of them, and the center, evaluated exactly: H-infinity norm
       of the closed loop (peak over all frequencies; unstable loops dropped).
    3. A local ascent (L-BFGS-B on the box and the log-frequency) of the gain at a frequency
       from the ``local_starts`` best, each result evaluated exactly.

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        LFR state space with inputs ``[w; u]`` and outputs ``[z; y]`` (``nz``, ``nw``
        uncertainty channels first).
    nz, nw : int
    structure : BlockStructure
        Repeated real scalar blocks only.
    omega : array_like
        Frequencies [rad/s] where the gain may peak (e.g. the peaks of its bounds).
    random_points, exact_points, local_starts : int
        Effort of each stage.
    rng : numpy.random.Generator, optional

    Returns
    -------
    WorstGain or None
        None if no closed loop of the box evaluated is stable.
    """
    from oos_drake.robust.hinf import hinfnorm

    if any(b.kind != REAL for b in structure.blocks):
        raise ValueError("real_worst_gain: the structure must have real blocks only")
    rng = np.random.default_rng(0) if rng is None else rng
    A, B, C, D = (np.asarray(v, dtype=float) for v in (A, B, C, D))
    k = len(structure.blocks)
    omega = np.unique(np.asarray(omega, dtype=float))
    vertices, _ = _box_directions(k, rng, 0)
    randoms = rng.uniform(-1.0, 1.0, (random_points, k))
    points = np.vstack([np.zeros((1, k)), vertices, randoms])
    labels = np.array(["center"] + ["vertex"] * len(vertices) + ["random"] * random_points)
    M = delta_channel_response(A, B, C, D, omega)  # (F, nz + ny, nw + nu)

    def freq_gain(P, Mw):
        delta = _diag_delta(structure, P)
        M11, M12, M21, M22 = Mw[:nz, :nw], Mw[:nz, nw:], Mw[nz:, :nw], Mw[nz:, nw:]
        X = np.eye(nz) - M11 @ delta
        G = M22 + M21 @ delta @ np.linalg.solve(X, np.broadcast_to(M12, X.shape[:1] + M12.shape))
        return np.linalg.norm(G, ord=2, axis=(-2, -1))

    screen = np.max([freq_gain(points, Mw) for Mw in M], axis=0)
    evaluations = points.shape[0] * omega.size
    top = np.argsort(-screen)[:exact_points]
    top = np.union1d(top, [0])

    def exact(P):
        Acl, Bcl, Ccl, Dcl = _closed_loop_ss(A, B, C, D, nz, nw, structure, P)
        ok = np.all(np.isfinite(Acl), axis=(1, 2))
        ok[ok] = np.linalg.eigvals(Acl[ok]).real.max(axis=1) < 0
        gain, peak = np.full(len(P), -np.inf), np.full(len(P), np.nan)
        if np.any(ok):
            res = hinfnorm((Acl[ok], Bcl[ok], Ccl[ok], Dcl[ok]))
            gain[ok] = np.atleast_1d(res.norm)
            peak[ok] = np.atleast_1d(res.peak_frequency)
        return gain, peak

    g, w = exact(points[top])
    evaluations += top.size
    if not np.any(np.isfinite(g)):
        return None
    order = np.argsort(-g)
    best = int(order[0])
    result = (float(g[best]), float(w[best]), points[top[best]], str(labels[top[best]]))
    for j in order[:local_starts]:
        if not np.isfinite(g[j]):
            continue
        w0 = max(float(w[j]), 1e-6)

        def negative(z):
            Mw = delta_channel_response(A, B, C, D, [np.exp(z[-1])])[0]
            return -freq_gain(z[None, :-1], Mw)[0]

        z0 = np.concatenate([points[top[j]], [np.log(w0)]])
        bounds = [(-1.0, 1.0)] * k + [(np.log(w0) - 1.0, np.log(w0) + 1.0)]
        out = minimize(negative, z0, method="L-BFGS-B", bounds=bounds, options=dict(maxiter=80))
        evaluations += int(out.nfev)
        x = np.clip(out.x[:-1], -1.0, 1.0)
        gx, wx = exact(x[None])
        evaluations += 1
        if gx[0] > result[0]:
            result = (float(gx[0]), float(wx[0]), x, "local")
    return WorstGain(
        result[0], result[1], np.asarray(result[2], dtype=float), result[3], evaluations
    )
