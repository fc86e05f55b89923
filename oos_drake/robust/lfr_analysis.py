"""Shared pieces of the LFR analyses: block maps, the Delta-channel response, frequency grids.

For an LFR ``Fu(M, Delta)`` with state matrices ``A, Bw, Bu, Cz, ...`` the matrix seen by the
uncertainty at frequency ``omega`` is ``M11(j omega) = Dzw + Cz (j omega I - A)^{-1} Bw``
(``sum(q) x sum(p)``, MATLAB BLK order of :attr:`LFR.blk`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BlockMap:
    """Where each named LFR block sits in the mussv structure.

    Attributes
    ----------
    names : tuple of str
        Block names in channel order.
    kinds : tuple of str
        ``"ureal"``, ``"ucomplex"`` or ``"ultidyn"``.
    specs : tuple
        The block specs (with ``to_physical``).
    blk_rows : tuple of tuple of int
        Indices of the BLK rows of each block (one per block, several for repeated ultidyn).
    z_slices, w_slices : tuple of slice
        Rows of ``z`` / columns of ``w`` of each block.
    blk : numpy.ndarray
        BLK rows of all blocks.
    """

    names: tuple
    kinds: tuple
    specs: tuple
    blk_rows: tuple
    z_slices: tuple
    w_slices: tuple
    blk: np.ndarray

    def subset(self, names) -> tuple[BlockMap, np.ndarray, np.ndarray]:
        """Map restricted to ``names`` plus the z rows and w columns to keep."""
        unknown = [n for n in names if n not in self.names]
        if unknown:
            raise ValueError(f"unknown uncertain block(s) {unknown} (blocks: {list(self.names)})")
        keep = [i for i, n in enumerate(self.names) if n in set(names)]
        zrows, wcols, rows, zs, ws, blk = [], [], [], [], [], []
        z0 = w0 = 0
        for i in keep:
            zi = np.arange(self.z_slices[i].start, self.z_slices[i].stop)
            wi = np.arange(self.w_slices[i].start, self.w_slices[i].stop)
            zrows.append(zi)
            wcols.append(wi)
            zs.append(slice(z0, z0 + zi.size))
            ws.append(slice(w0, w0 + wi.size))
            z0 += zi.size
            w0 += wi.size
            rows.append(tuple(range(len(blk), len(blk) + len(self.blk_rows[i]))))
            blk.extend(self.blk[r] for r in self.blk_rows[i])
        sub = BlockMap(
            tuple(self.names[i] for i in keep),
            tuple(self.kinds[i] for i in keep),
            tuple(self.specs[i] for i in keep),
            tuple(rows),
            tuple(zs),
            tuple(ws),
            np.array(blk, dtype=int).reshape(-1, 2),
        )
        return sub, np.concatenate(zrows), np.concatenate(wcols)


def block_map(sys) -> BlockMap:
    """Block map of an LFR (see :class:`BlockMap`)."""
    names, kinds, specs, rows, zs, ws, blk = [], [], [], [], [], [], []
    slices = sys.channel_slices()
    for entry in sys.block_entries:
        spec = entry.spec
        names.append(spec.name)
        kinds.append(spec.kind)
        specs.append(spec)
        z, w = slices[spec.name]
        zs.append(z)
        ws.append(w)
        if spec.kind == "ureal":
            rows.append((len(blk),))
            blk.append([-entry.reps, 0])
        elif spec.kind == "ucomplex":
            rows.append((len(blk),))
            blk.append([entry.reps, 0])
        else:
            rows.append(tuple(range(len(blk), len(blk) + entry.reps)))
            blk.extend([list(spec.shape)] * entry.reps)
    if not names:
        raise ValueError("the LFR has no uncertain blocks to analyze")
    return BlockMap(
        tuple(names),
        tuple(kinds),
        tuple(specs),
        tuple(rows),
        tuple(zs),
        tuple(ws),
        np.array(blk, dtype=int).reshape(-1, 2),
    )


def model_matrices(sys, names=("A", "Bw", "Cz", "Dzw")) -> tuple[np.ndarray, ...]:
    """The state matrices ``names`` of an LFR model array, each as an ``(N, rows, columns)`` array.

    ``N`` is the number of models (1 for a single model). Raises ``ValueError`` for a batch
    shape of more than one dimension.
    """
    if len(sys.batch_shape) > 1:
        raise ValueError(f"expected a 1-D model array, got batch shape {sys.batch_shape}")
    n_models = sys.batch_shape[0] if sys.batch_shape else 1
    return tuple(
        np.asarray(x).reshape((n_models,) + np.shape(x)[-2:])
        for x in (getattr(sys, name) for name in names)
    )


def subset_parts(sys, subsets: dict) -> dict:
    """Subset name -> ``(z rows, w columns, BLK)`` of the Delta channels of ``sys``."""
    bmap = block_map(sys)
    parts = {}
    for name, members in subsets.items():
        sub, zrows, wcols = bmap.subset(list(members))
        parts[name] = (zrows, wcols, sub.blk)
    return parts


def delta_channel_response(A, Bw, Cz, Dzw, omega) -> np.ndarray:
    """``Dzw + Cz (j omega I - A)^{-1} Bw`` for batched matrices: ``batch + (F, nz, nw)``.

    Uses the eigen-decomposition of ``A`` when it is well conditioned (``O(F n nz nw)``), else
    batched solves. ``omega = inf`` gives ``Dzw`` (the well-posedness point of the loop).
    """
    A, Bw, Cz, Dzw = (np.asarray(x) for x in (A, Bw, Cz, Dzw))
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    batch = np.broadcast_shapes(A.shape[:-2], Bw.shape[:-2], Cz.shape[:-2], Dzw.shape[:-2])
    n = A.shape[-1]
    nz, nw = Dzw.shape[-2:]
    nb = int(np.prod(batch, dtype=int))  # explicit: -1 is ambiguous for a static model (n = 0)
    A = np.broadcast_to(A, batch + (n, n)).reshape(nb, n, n)
    Bw = np.broadcast_to(Bw, batch + (n, nw)).reshape(nb, n, nw)
    Cz = np.broadcast_to(Cz, batch + (nz, n)).reshape(nb, nz, n)
    Dzw = np.broadcast_to(Dzw, batch + (nz, nw)).reshape(nb, nz, nw)
    out = np.empty((nb, omega.size, nz, nw), dtype=complex)
    if n == 0:
        out[:] = Dzw[:, None]
        return out.reshape(batch + out.shape[1:])
    infinite = np.isinf(omega)
    s = 1j * np.where(infinite, 0.0, omega)
    for k in range(nb):
        lam, V = np.linalg.eig(A[k])
        cond = np.linalg.cond(V)
        if np.isfinite(cond) and cond < 1e8:
            CV = Cz[k] @ V
            VB = np.linalg.solve(V, Bw[k])
            inv = 1.0 / (s[:, None] - lam[None, :])  # (F, n)
            out[k] = Dzw[k] + np.einsum("in,fn,nj->fij", CV, inv, VB)
        else:
            eye = np.eye(n)
            X = np.linalg.solve(
                s[:, None, None] * eye - A[k], np.broadcast_to(Bw[k], (s.size, n, nw))
            )
            out[k] = Dzw[k] + Cz[k] @ X
    out[:, infinite] = Dzw[:, None]
    return out.reshape(batch + out.shape[1:])


def frequency_grid(
    A=None, *, points_per_decade: int = 40, omega_range=None, points: int | None = None
) -> np.ndarray:
    """Frequencies [rad/s] that resolve the dynamics of ``A`` (or several ``A``).

    The package's one frequency grid. A logarithmic grid from a decade below the slowest to a
    decade above the fastest non-zero pole (or over ``omega_range``), plus, around each lightly
    damped pole (damping ratio ``zeta < 0.3``), a local grid of spacing ``zeta * omega_n / 2``
    over ``+-6 zeta omega_n`` so that resonances of damping 0.01 are sampled at their peak.

    Parameters
    ----------
    A : array_like, shape (..., n, n), optional
        State matrices whose poles the grid resolves; None: a plain logarithmic grid over
        ``omega_range``.
    points_per_decade : int
        Density of the logarithmic grid.
    omega_range : (float, float), optional
        ``(lowest, highest)`` frequency [rad/s]; default: from the poles.
    points : int, optional
        Number of points of the logarithmic grid (instead of ``points_per_decade``).

    Examples
    --------
    >>> grid = frequency_grid(omega_range=(2 * np.pi * 0.01, 2 * np.pi * 100.0), points=400)
    >>> grid.size, round(grid[0] / (2 * np.pi), 6), round(grid[-1] / (2 * np.pi), 6)
    (400, 0.01, 100.0)
    """
    A = np.zeros((0, 0)) if A is None else np.asarray(A)
    poles = (
        np.linalg.eigvals(A.reshape((-1,) + A.shape[-2:])).ravel() if A.shape[-1] else np.array([])
    )
    mag = np.abs(poles)
    nz = mag[mag > 1e-9 * max(1.0, mag.max(initial=0.0))]
    if omega_range is None:
        if nz.size == 0:
            lo, hi = 1e-2, 1e2
        else:
            lo, hi = nz.min() / 10.0, nz.max() * 10.0
    else:
        lo, hi = omega_range
    decades = max(np.log10(hi / lo), 1.0)
    count = int(points_per_decade * decades) + 1 if points is None else int(points)
    grid = [np.logspace(np.log10(lo), np.log10(hi), count)]
    if nz.size:
        p = poles[mag > 1e-9 * max(1.0, mag.max())]
        wn = np.abs(p)
        zeta = -p.real / wn
        light = (zeta < 0.3) & (p.imag > 0)
        offsets = np.arange(-12, 13) / 2.0  # in units of zeta * wn, +-6 zeta wn
        for w0, z0 in zip(wn[light], np.maximum(zeta[light], 1e-4), strict=True):
            grid.append(w0 * (1.0 + z0 * offsets))
    grid = np.unique(np.concatenate(grid))
    return grid[(grid > 0) & (grid >= lo * 0.999) & (grid <= hi * 1.001)]


def worst_case_values(bmap: BlockMap, structure, delta: np.ndarray, omega: float) -> dict:
    """Map a normalized perturbation (mussv ``delta``) to named, PHYSICAL block values.

    ``ureal``: a float in the parameter's unit (bilinear/affine map of the block); ``ucomplex``:
    a complex value; ``ultidyn``: a ``control.StateSpace`` (stable, all-pass factors) whose
    response at ``omega`` [rad/s] equals the worst complex matrix, with H-infinity norm equal to
    its norm (scaled by the block's bound).
    """
    normalized = normalized_worst_case(bmap, structure, delta)
    values = {}
    for name, kind, spec in zip(bmap.names, bmap.kinds, bmap.specs, strict=True):
        if kind == "ureal":
            values[name] = float(spec.to_physical(normalized[name]))
        elif kind == "ucomplex":
            values[name] = complex(spec.to_physical(normalized[name]))
        else:
            values[name] = realize_complex_matrix(spec.bound * normalized[name], omega)
    return values


def normalized_worst_case(bmap: BlockMap, structure, delta: np.ndarray) -> dict:
    """Map a normalized perturbation (mussv ``delta``) to named NORMALIZED block values:
    ``ureal`` a float in [-1, 1], ``ucomplex`` a complex value, ``ultidyn`` its complex matrix."""
    values = {}
    for name, kind, rows in zip(bmap.names, bmap.kinds, bmap.blk_rows, strict=True):
        block = structure.blocks[rows[0]]
        sub = delta[block.r_slice, block.c_slice]
        values[name] = (
            float(sub[0, 0].real)
            if kind == "ureal"
            else complex(sub[0, 0])
            if kind == "ucomplex"
            else sub
        )
    return values


def realize_complex_matrix(value: np.ndarray, omega: float):
    """Stable real-rational ``Delta(s)``: ``Delta(j omega) = value``, ``||Delta||_inf = ||value||``.

    The rank-one form of the worst perturbation (``value = u v^*``, exact for the power
    iteration's full blocks; otherwise its dominant singular pair, which keeps the norm),
    realized with all-pass factors per entry by
    :func:`~oos_drake.robust.interpolant.lti_interpolant`. At ``omega = 0`` or ``inf`` the
    response of a real system is real: the real part of the rank-one value.
    """
    from oos_drake.robust.interpolant import lti_interpolant

    U, sv, Vh = np.linalg.svd(np.atleast_2d(np.asarray(value, dtype=complex)))
    rank_one = sv[0] * np.outer(U[:, 0], Vh[0, :])
    if omega <= 0 or np.isinf(omega):
        return lti_interpolant(rank_one.real, max(float(omega), 0.0))
    return lti_interpolant(rank_one, omega)
