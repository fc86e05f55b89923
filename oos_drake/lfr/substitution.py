"""Substituting values for uncertain blocks: ``usubs``, ``nominal``, ``usample``.

Closing the Delta channels of a set ``s`` of blocks with ``w_s = Delta_s z_s`` gives

.. math:: M' = M_{kk} + M_{ks} W, \\qquad (I - \\Delta_s M_{ss}) W = \\Delta_s M_{sk},

for all models of a model array at once. For scalar blocks (``ureal``, ``ucomplex``) ``Delta_s`` is
diagonal and the solve exploits the sparsity of ``M_ss``: its strongly connected components are
ordered topologically once per LFR (cached), and ``W`` is then computed level by level, so an LFR
whose occurrences do not form algebraic loops costs matrix products only. Full blocks
(``ultidyn``) are closed afterwards with a dense batched solve.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from oos_drake.lfr.core import LFR
from oos_drake.processes import make_executor

#: Work-array size (entries) per chunk of models in the batched substitution.
SUBS_CHUNK_ENTRIES = 1_000_000


def nominal(sys: LFR) -> LFR:
    """The nominal model of ``sys``: every block at ``delta = 0`` (an LFR without blocks)."""
    if sys.is_certain:
        return sys
    _, _, rows, cols = _split(sys, sys.uncertainty)
    return sys._replace(sys.M[..., rows[:, None], cols[None, :]], blocks=())


def _ureal_table(sys: LFR):
    """Cached arrays (name -> row, nominal, lower, upper, alpha, beta) of the ureal blocks."""
    table = sys._cache.get("ureal_table")
    if table is None:
        specs = [e.spec for e in sys.block_entries if e.spec.kind == "ureal"]
        table = {
            "row": {spec.name: i for i, spec in enumerate(specs)},
            "params": np.array(
                [[sp.nominal, sp.lower, sp.upper, sp.alpha, sp.beta] for sp in specs]
            ).reshape(-1, 5),
        }
        sys._cache["ureal_table"] = table
    return table


def _known(sys: LFR, names, caller: str) -> dict:
    """``sys.uncertainty``, once every one of ``names`` is checked to be among its blocks."""
    specs = sys.uncertainty
    for name in names:
        if name not in specs:
            known = ", ".join(specs) or "none"
            raise ValueError(f"{caller}: unknown block name {name!r} (blocks: {known})")
    return specs


def _normalized_values(sys: LFR, values: Mapping, normalized: bool):
    if not isinstance(values, Mapping):
        raise ValueError(
            f"usubs: values must be a mapping name -> value, got {type(values).__name__}"
        )
    specs = _known(sys, values, "usubs")
    out = {}
    fast = []
    for name, value in values.items():
        spec = specs[name]
        if normalized:
            out[name] = spec.check_normalized(value)
        elif spec.kind == "ureal":
            fast.append(name)
        else:
            out[name] = spec.to_normalized(value)
    if fast:
        out.update(_normalize_ureals(sys, specs, values, fast))
    return out


def _normalize_ureals(sys, specs, values, names):
    """Vectorized physical -> normalized map of many ureal blocks (one numpy pass)."""
    try:
        arrays = np.broadcast_arrays(*(np.asarray(values[k]) for k in names))
        if any(a.dtype.kind not in "biuf" for a in arrays):
            raise TypeError("complex or non-numeric values: use the per-block path")
        stacked = np.stack(arrays).astype(float)
    except (ValueError, TypeError):
        return {k: specs[k].to_normalized(values[k]) for k in names}
    table = _ureal_table(sys)
    rows = np.array([table["row"][k] for k in names])
    nom, lo, hi, alpha, beta = (
        col.reshape((-1,) + (1,) * (stacked.ndim - 1)) for col in table["params"][rows].T
    )
    from oos_drake.lfr.blocks import RANGE_RTOL

    slack = RANGE_RTOL * np.maximum(1.0, np.maximum(np.abs(lo), np.abs(hi)))
    bad = ~np.isfinite(stacked) | (stacked < lo - slack) | (stacked > hi + slack)
    if np.any(bad):
        first = int(np.flatnonzero(bad.reshape(len(names), -1).any(axis=1))[0])
        specs[names[first]].to_normalized(values[names[first]])  # raises with the message
    delta = (stacked - nom) / (alpha - beta * stacked)
    return {k: delta[i] for i, k in enumerate(names)}


def usubs(sys: LFR, values: Mapping, *, normalized: bool = False, workers: int = 1) -> LFR:
    """Substitute values for some or all uncertain blocks.

    Parameters
    ----------
    sys : LFR
        The uncertain model.
    values : mapping str -> scalar or array
        Block name -> PHYSICAL value (same unit as the block's nominal). ``ureal``/``ucomplex``:
        a scalar or an array of shape ``batch`` (e.g. ``(N,)``); ``ultidyn``: a static matrix
        ``(p, q)``, an array ``batch + (p, q)``, or an LTI system (LFR, ``control.StateSpace`` or
        ``TransferFunction``; its gain is not checked against the bound). Arrays of all blocks
        broadcast against each other and against ``sys.batch_shape``; the result is a model array
        with that batch shape.
    normalized : bool
        If True the values are normalized ``delta`` (no range check), e.g. worst-case deltas from a
        mu analysis.
    workers : int
        Threads closing chunks of a model array in parallel (1: single-threaded). Results do
        not depend on it (numpy releases the GIL in its array loops and BLAS calls); each
        worker runs its BLAS calls single-threaded.

    Returns
    -------
    LFR
        The remaining blocks only (no blocks when all were substituted; convert one model with
        ``.to_ss()``).

    Raises
    ------
    ValueError
        Unknown block name, or a physical value outside its block's range (the message names the
        block and the value).

    Examples
    --------
    >>> import numpy as np
    >>> from oos_drake.lfr import ureal, usubs
    >>> k = ureal("k", 10.0, percent=20)
    >>> usubs(3 * k, {"k": np.array([9.0, 11.0])}).M[:, 0, 0]
    array([27., 33.])
    """
    if isinstance(values, Mapping):
        dynamic = {k: v for k, v in values.items() if _is_system(v)}
        if dynamic:
            static = {k: v for k, v in values.items() if k not in dynamic}
            return _substitute_systems(
                usubs(sys, static, normalized=normalized, workers=workers), dynamic, normalized
            )
    deltas = _normalized_values(sys, values, normalized)
    if not deltas:
        return sys
    return close_blocks(sys, deltas, workers=workers)


def _is_system(value) -> bool:
    import control

    return isinstance(value, LFR | control.StateSpace | control.TransferFunction)


def _substitute_systems(sys: LFR, systems: Mapping, normalized: bool) -> LFR:
    """Close ``ultidyn`` blocks with LTI systems (not checked against the bound) via ``lftdata``."""
    from oos_drake.lfr.core import append_systems, as_lfr
    from oos_drake.lfr.interconnect import lft

    specs = _known(sys, systems, "usubs")
    for name in systems:
        if specs[name].kind != "ultidyn":
            raise ValueError(
                f"usubs: block {name!r} is a {specs[name].kind}; only ultidyn blocks "
                "can be replaced by a system"
            )
    names = sorted(systems)
    M, _ = lftdata(sys, names)
    pieces = []
    for entry in sys.block_entries:
        if entry.spec.name not in systems:
            continue
        value = as_lfr(systems[entry.spec.name])
        if value.shape != entry.spec.shape:
            raise ValueError(
                f"usubs: system for ultidyn {entry.spec.name!r} has shape "
                f"{value.shape}, expected {entry.spec.shape}"
            )
        scaled = value if normalized else value * (1.0 / entry.spec.bound)
        pieces.extend([scaled] * entry.reps)
    # Delta's outputs (w) drive M's first inputs, M's first outputs (z) drive Delta's inputs
    n_w = M.ninputs - sys.ninputs
    n_z = M.noutputs - sys.noutputs
    return lft(append_systems(pieces), M, nu=n_w, ny=n_z)


def close_blocks(sys: LFR, deltas: Mapping, *, workers: int = 1) -> LFR:
    """Close the named blocks with NORMALIZED values ``deltas`` (see :func:`usubs`, also for
    ``workers``)."""
    specs = sys.uncertainty
    unknown = [k for k in deltas if k not in specs]
    if unknown:
        raise ValueError(f"close_blocks: unknown block name {unknown[0]!r}")
    scalar = {k: v for k, v in deltas.items() if specs[k].kind != "ultidyn"}
    full = {k: v for k, v in deltas.items() if specs[k].kind == "ultidyn"}
    if scalar:
        sys = _close_scalar(sys, scalar, workers)
    if full:
        sys = _close_full(sys, full)
    return sys


def _split(sys: LFR, names):
    """Indices (into M's rows / cols) of the z / w channels of ``names`` and of everything else."""
    slices = sys.channel_slices()
    z_all, w_all = sys.nstates + np.arange(sys.nz), sys.nstates + np.arange(sys.nw)
    z_sub = np.concatenate([z_all[slices[k][0]] for k in names] + [z_all[:0]])  # [] if no names
    w_sub = np.concatenate([w_all[slices[k][1]] for k in names] + [w_all[:0]])
    rows_keep = np.setdiff1d(np.arange(sys.M.shape[-2]), z_sub)
    cols_keep = np.setdiff1d(np.arange(sys.M.shape[-1]), w_sub)
    return z_sub, w_sub, rows_keep, cols_keep


def _partitions(M, z_sub, w_sub, rows_keep, cols_keep) -> dict:
    """``M_ss, M_sk, M_ks, M_kk``: substituted (s) and kept (k) rows / columns of ``M``."""
    return {
        "Mss": M[..., z_sub[:, None], w_sub[None, :]],
        "Msk": M[..., z_sub[:, None], cols_keep[None, :]],
        "Mks": M[..., rows_keep[:, None], w_sub[None, :]],
        "Mkk": M[..., rows_keep[:, None], cols_keep[None, :]],
    }


def _schedule(pattern: np.ndarray):
    """Topological levels of the dependency graph ``w_i <- w_j`` for ``pattern[i, j] != 0``.

    Returns a list of ``(level_indices, groups)`` where ``groups`` lists the positions (within
    the level) of each strongly connected component with more than one node; those need a small
    solve, the other nodes only a division.
    """
    graph = sp.csr_matrix(pattern.astype(bool))
    ncomp, labels = connected_components(graph, directed=True, connection="strong")
    # condensation DAG: comp(i) depends on comp(j) if pattern[i, j]; a component's depth is the
    # longest dependency path below it (relaxed until it settles: at most ncomp passes)
    rows, cols = np.nonzero(pattern)
    a, b = labels[rows], labels[cols]
    a, b = a[a != b], b[a != b]
    depth = np.zeros(ncomp, dtype=int)
    for _ in range(ncomp):
        deeper = depth.copy()
        np.maximum.at(deeper, a, depth[b] + 1)
        if np.array_equal(deeper, depth):
            break
        depth = deeper
    node_depth = depth[labels]
    levels = []
    for lev in range(int(node_depth.max(initial=-1)) + 1):
        idx = np.flatnonzero(node_depth == lev)
        comp = labels[idx]
        groups = [np.flatnonzero(comp == c) for c in np.unique(comp)]
        levels.append((idx, [g for g in groups if g.size > 1]))
    return levels


def _scalar_plan(sys: LFR, names):
    """Static part of closing scalar blocks ``names``: partitions of ``M`` with the substituted
    channels permuted into topological level order, and the level boundaries (cached per LFR)."""
    key = ("scalar", tuple(names))
    plan = sys._cache.get(key)
    if plan is not None:
        return plan
    z_sub, w_sub, rows_keep, cols_keep = _split(sys, names)
    M = sys.M
    Mss = M[..., z_sub[:, None], w_sub[None, :]]
    pattern = np.any(Mss != 0, axis=tuple(range(Mss.ndim - 2))) if Mss.ndim > 2 else Mss != 0
    levels = _schedule(pattern)
    perm = np.concatenate([idx for idx, _ in levels]) if levels else np.zeros(0, int)
    bounds, start = [], 0
    for idx, groups in levels:
        stop = start + idx.size
        coupled = bool(start) and bool(np.any(pattern[np.ix_(idx, perm[:start])]))
        multi = np.zeros(idx.size, dtype=bool)
        for grp in groups:
            multi[grp] = True
        bounds.append((start, stop, coupled, np.flatnonzero(~multi), groups))
        start = stop
    plan = {"perm": perm, "bounds": bounds}
    plan.update(_partitions(M, z_sub[perm], w_sub[perm], rows_keep, cols_keep))
    if M.ndim == 2:
        plan["cols_used"] = np.flatnonzero(np.any(plan["Msk"] != 0, axis=0))
        plan["rows_used"] = np.flatnonzero(np.any(plan["Mks"] != 0, axis=1))
        plan["Msk_used"] = np.ascontiguousarray(plan["Msk"][:, plan["cols_used"]])
        plan["Mks_used"] = np.ascontiguousarray(plan["Mks"][plan["rows_used"]])
    sys._cache[key] = plan
    return plan


def _close_scalar(sys: LFR, deltas: Mapping, workers: int = 1) -> LFR:
    names = sorted(deltas)
    plan = _scalar_plan(sys, names)
    entries = {e.spec.name: e for e in sys.block_entries}
    batch = sys.batch_shape
    arrays = []
    for name in names:
        arr = np.asarray(deltas[name])
        batch = _broadcast(batch, arr.shape, name)
        arrays.append((arr, entries[name].reps))
    # per-channel normalized values in level order, shape batch + (ns,)
    d = np.concatenate(
        [np.broadcast_to(arr[..., None], batch + (reps,)) for arr, reps in arrays], axis=-1
    )[..., plan["perm"]]
    if sys.batch_shape == () and batch != ():
        flat = d.reshape(-1, d.shape[-1])
        Mkk = plan["Mkk"]
        new_M = np.empty((flat.shape[0],) + Mkk.shape, dtype=np.result_type(Mkk, flat))
        # chunks keep the work arrays cache-sized
        step = max(1, SUBS_CHUNK_ENTRIES // max(1, flat.shape[1] * plan["Msk"].shape[1]))
        starts = range(0, flat.shape[0], step)

        def work(k):
            new_M[k : k + step] = _close_scalar_values_batched(plan, flat[k : k + step], names)

        with make_executor(workers, "threads") as threads:
            threads.map(work, starts)
        new_M = new_M.reshape(batch + new_M.shape[-2:])
    else:
        new_M = _close_scalar_general(plan, d, batch, names)
    remaining = tuple(e for e in sys.block_entries if e.spec.name not in deltas)
    return sys._replace(new_M, blocks=remaining)


def _broadcast(batch, shape, name):
    try:
        return np.broadcast_shapes(batch, shape)
    except ValueError:
        raise ValueError(
            f"usubs: values of block {name!r} with batch shape {shape} do not broadcast with the "
            f"other values / model array (batch {batch})"
        ) from None


def _ill_posed(names):
    return ValueError(
        "usubs: the substituted values make the LFR ill-posed "
        f"(I - Delta*Dzw singular) for blocks {names}"
    )


def _close_scalar_general(plan, d, batch, names):
    Mss, Msk, Mks, Mkk = plan["Mss"], plan["Msk"], plan["Mks"], plan["Mkk"]
    dtype = np.result_type(Mss, d)
    ns, nk = Mss.shape[-1], Msk.shape[-1]
    W = np.empty(batch + (ns, nk), dtype=dtype)
    for start, stop, coupled, singles, groups in plan["bounds"]:
        rhs = Msk[..., start:stop, :]
        if coupled:
            rhs = rhs + Mss[..., start:stop, :start] @ W[..., :start, :]
        rhs = np.broadcast_to(rhs, batch + rhs.shape[-2:])
        d_lev = d[..., start:stop]
        block = Mss[..., start:stop, start:stop]
        if singles.size:
            diag = np.diagonal(block, axis1=-2, axis2=-1)[..., singles]
            denom = 1.0 - d_lev[..., singles] * diag
            if np.any(np.abs(denom) < 1e-14):
                raise _ill_posed(names)
            W[..., start + singles, :] = (d_lev[..., singles] / denom)[..., None] * rhs[
                ..., singles, :
            ]
        for grp in groups:
            dg = d_lev[..., grp]
            loop = np.eye(grp.size) - dg[..., :, None] * block[..., grp[:, None], grp[None, :]]
            try:
                W[..., start + grp, :] = np.linalg.solve(loop, dg[..., :, None] * rhs[..., grp, :])
            except np.linalg.LinAlgError:
                raise _ill_posed(names) from None
    new_M = Mkk + Mks @ W
    return np.broadcast_to(new_M, batch + new_M.shape[-2:])


def _close_scalar_values_batched(plan, d, names):
    """Hot path: one certain-structure LFR, ``N`` value sets ``d`` of shape ``(N, ns)``.

    The recursion runs on the narrower side: over the used columns of ``M_sk``
    (:func:`_close_scalar_values_right`) or over the used rows of ``M_ks``
    (:func:`_close_scalar_values_left`); both give the same ``M'``.
    """
    if plan["rows_used"].size < plan["cols_used"].size:
        return _close_scalar_values_left(plan, d, names)
    return _close_scalar_values_right(plan, d, names)


def _close_scalar_values_right(plan, d, names):
    """``M' = M_kk + M_ks W`` with ``(I - Delta M_ss) W = Delta M_sk`` solved level by level.

    ``W`` is stored as ``(ns, N, nk)`` (``nk`` used columns of ``M_sk``) so that every coupling
    and the final product are single large matrix products over all models at once.
    """
    Mkk = plan["Mkk"]
    cols, rows = plan["cols_used"], plan["rows_used"]
    N = d.shape[0]
    W = _level_recursion(
        plan["Mss"], plan["Msk_used"], np.ascontiguousarray(d.T), plan["bounds"], names
    )
    update = (plan["Mks_used"] @ W.reshape(W.shape[0], -1)).reshape(rows.size, N, cols.size)
    out = np.empty((N,) + Mkk.shape, dtype=np.result_type(Mkk, update))
    out[:] = Mkk
    out[:, rows[:, None], cols[None, :]] += np.swapaxes(update, 0, 1)
    return out


def _close_scalar_values_left(plan, d, names):
    """Transposed hot path: ``M' = M_kk + Z M_sk`` with ``Z = M_ks Delta (I - M_ss Delta)^-1``.

    Since ``(I - Delta M_ss)^-1 Delta = Delta (I - M_ss Delta)^-1``, this equals
    :func:`_close_scalar_values_right`. ``Z^T`` solves the transposed system
    ``(I - Delta M_ss^T) Z^T = Delta M_ks^T``, whose dependencies run the other way: with the
    channel order reversed it is the same level recursion (:func:`_level_recursion`) on
    ``M_ss^T``, with the rows of ``M_ks`` (``nr`` used ones) in place of the columns of ``M_sk``.
    """
    Mkk = plan["Mkk"]
    cols, rows = plan["cols_used"], plan["rows_used"]
    N = d.shape[0]
    tr = plan.get("transposed")
    if tr is None:
        tr = plan["transposed"] = _transposed_plan(plan)
    d_rev = np.ascontiguousarray(d[:, ::-1].T)
    Z = _level_recursion(tr["Mss"], tr["rhs"], d_rev, tr["bounds"], names)  # (ns, N, nr) reversed
    update = (Z.reshape(Z.shape[0], -1).T @ tr["lhs"]).reshape(N, rows.size, cols.size)
    out = np.empty((N,) + Mkk.shape, dtype=np.result_type(Mkk, update))
    out[:] = Mkk
    out[:, rows[:, None], cols[None, :]] += update
    return out


def _transposed_plan(plan):
    """The transposed problem of :func:`_close_scalar_values_left` with the channel order
    reversed (so that its levels again depend only on earlier ones): ``M_ss^T``, the used rows
    of ``M_ks`` as right-hand side, the used columns of ``M_sk`` (reversed) for the final
    product, and the level bounds mirrored (built once per plan)."""
    ns = plan["Mss"].shape[0]
    bounds = []
    for (start, stop, _, singles, groups), coupled in zip(
        reversed(plan["bounds"]), reversed(_coupled_below(plan)), strict=True
    ):
        last = stop - start - 1  # position p within the level becomes last - p
        bounds.append(
            (ns - stop, ns - start, coupled, last - singles[::-1], [last - g[::-1] for g in groups])
        )
    return {
        "Mss": np.ascontiguousarray(plan["Mss"][::-1, ::-1].T),
        "rhs": np.ascontiguousarray(plan["Mks_used"][:, ::-1].T),
        "lhs": np.ascontiguousarray(plan["Msk_used"][::-1]),
        "bounds": bounds,
    }


def _coupled_below(plan):
    """Per level: does any later level depend on it (``M_ss[stop:, start:stop] != 0``)?"""
    Mss = plan["Mss"]
    return [bool(np.any(Mss[stop:, start:stop])) for start, stop, *_ in plan["bounds"]]


def _level_recursion(Mss, rhs0, dt, bounds, names):
    """``W`` with ``(I - Delta M_ss) W = Delta R`` for ``N`` value sets, level by level.

    Parameters
    ----------
    Mss : numpy.ndarray
        ``(ns, ns)`` channel coupling, channels in topological level order (a level depends
        only on earlier ones, and on itself through its strongly connected groups).
    rhs0 : numpy.ndarray
        ``(ns, k)`` right-hand side ``R``.
    dt : numpy.ndarray
        ``(ns, N)`` normalized values per channel and model.
    bounds : list
        ``(start, stop, coupled, singles, groups)`` per level: ``coupled`` if the level depends
        on earlier ones; ``singles`` / ``groups`` positions (within the level) of the channels
        that need a division / a small solve.
    names : list of str
        Block names (for the ill-posedness message).

    Returns
    -------
    numpy.ndarray
        ``W`` stored as ``(ns, N, k)``: every coupling is one large matrix product.
    """
    ns, N = dt.shape
    k = rhs0.shape[1]
    W = np.empty((ns, N, k), dtype=np.result_type(Mss, dt))
    for start, stop, coupled, singles, groups in bounds:
        size = stop - start
        rhs = np.broadcast_to(rhs0[start:stop, None, :], (size, N, k))
        if coupled:
            prod = Mss[start:stop, :start] @ W[:start].reshape(start, N * k)
            rhs = rhs + prod.reshape(size, N, k)
        d_lev = dt[start:stop]  # (size, N)
        block = Mss[start:stop, start:stop]
        if singles.size:
            denom = 1.0 - d_lev[singles] * np.diagonal(block)[singles, None]
            if np.any(np.abs(denom) < 1e-14):
                raise _ill_posed(names)
            W[start + singles] = (d_lev[singles] / denom)[..., None] * rhs[singles]
        for grp in groups:
            if grp.size == 2:  # closed form (Cramer), no per-model LAPACK call
                W[start + grp] = _solve_pair(block[np.ix_(grp, grp)], d_lev[grp], rhs[grp], names)
                continue
            dg = d_lev[grp].T  # (N, g)
            loop = np.eye(grp.size) - dg[:, :, None] * block[np.ix_(grp, grp)]
            rhs_g = np.swapaxes(rhs[grp], 0, 1) * dg[:, :, None]  # (N, g, k)
            try:
                W[start + grp] = np.swapaxes(np.linalg.solve(loop, rhs_g), 0, 1)
            except np.linalg.LinAlgError:
                raise _ill_posed(names) from None
    return W


def _solve_pair(block, d, rhs, names):
    """``(I - diag(d) B) X = diag(d) R`` for a 2-channel loop ``B (2, 2)``, values ``d (2, N)``
    and ``R (2, N, k)``, all models at once: ``X (2, N, k)``."""
    a = 1.0 - d[0] * block[0, 0]
    b = -d[0] * block[0, 1]
    c = -d[1] * block[1, 0]
    e = 1.0 - d[1] * block[1, 1]
    det = a * e - b * c
    if np.any(np.abs(det) < 1e-14):
        raise _ill_posed(names)
    r0 = d[0][:, None] * rhs[0]
    r1 = d[1][:, None] * rhs[1]
    inv = (1.0 / det)[:, None]
    return np.stack(
        [(e[:, None] * r0 - b[:, None] * r1) * inv, (a[:, None] * r1 - c[:, None] * r0) * inv]
    )


def _close_full(sys: LFR, deltas: Mapping) -> LFR:
    names = sorted(deltas)
    z_sub, w_sub, rows_keep, cols_keep = _split(sys, names)
    entries = {e.spec.name: e for e in sys.block_entries}
    batch = sys.batch_shape
    for name in names:
        batch = _broadcast(batch, np.asarray(deltas[name]).shape[:-2], name)
    dtype = np.result_type(sys.M, *(np.asarray(deltas[k]) for k in names))
    Delta = np.zeros(batch + (w_sub.size, z_sub.size), dtype=dtype)
    w0 = z0 = 0
    for name in names:
        p, q = entries[name].spec.shape
        value = np.broadcast_to(np.asarray(deltas[name]), batch + (p, q))
        for _ in range(entries[name].reps):
            Delta[..., w0 : w0 + p, z0 : z0 + q] = value
            w0 += p
            z0 += q
    Mss, Msk, Mks, Mkk = _partitions(sys.M, z_sub, w_sub, rows_keep, cols_keep).values()
    loop = np.eye(w_sub.size) - Delta @ Mss
    try:
        W = np.linalg.solve(loop, Delta @ Msk)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"usubs: the substituted values make the LFR ill-posed for blocks {names}"
        ) from None
    new_M = np.broadcast_to(Mkk, batch + Mkk.shape[-2:]) + Mks @ W
    remaining = tuple(e for e in sys.block_entries if e.spec.name not in deltas)
    return sys._replace(new_M, blocks=remaining)


def usample(sys: LFR, n: int, rng, *, names=None):
    """Draw ``n`` random instances of the blocks of ``sys`` (MATLAB ``usample``).

    ``ureal`` values are uniform in their physical range, ``ucomplex`` uniform in the disc and
    ``ultidyn`` static real gains with norm uniform in ``[0, bound]``.

    Parameters
    ----------
    sys : LFR
        Uncertain model.
    n : int
        Number of samples.
    rng : numpy.random.Generator or int
        Random generator (or a seed for ``numpy.random.default_rng``).
    names : sequence of str, optional
        Blocks to sample (default: all); the others stay uncertain.

    Returns
    -------
    models : LFR
        Model array with batch shape ``(n,)``.
    values : pandas.DataFrame
        One row per sample, one column per scalar block (physical values); ``ultidyn`` samples
        are stored as objects (arrays).
    """
    import pandas as pd

    if not isinstance(rng, np.random.Generator):
        if rng is None:
            raise ValueError("usample: pass a numpy.random.Generator (or a seed) explicitly")
        rng = np.random.default_rng(rng)
    n = int(n)
    if n < 1:
        raise ValueError(f"usample: number of samples must be >= 1, got {n}")
    specs = sys.uncertainty
    names = list(specs) if names is None else list(names)
    _known(sys, names, "usample")
    values = {name: specs[name].sample(rng, n) for name in names}
    table = pd.DataFrame({k: (list(v) if v.ndim > 1 else v) for k, v in values.items()})
    table.index.name = "sample"
    return usubs(sys, values), table


def lftdata(sys: LFR, names=None):
    """Split ``sys`` into a certain part and normalized blocks (MATLAB ``lftdata``).

    Parameters
    ----------
    sys : LFR
        Uncertain model (model arrays allowed).
    names : sequence of str, optional
        Blocks to pull out (default: all). The others stay inside ``M``.

    Returns
    -------
    M : LFR
        Inputs ``[w_sel; u]`` and outputs ``[z_sel; y]`` (the pulled-out Delta channels first, in
        block name order), holding the remaining blocks.
    Delta : LFR
        Block-diagonal normalized blocks (``ureal(name, 0, range=(-1, 1))``,
        ``ucomplex(name, 0, 1)``, ``ultidyn(name, shape, 1)``), each repeated as often as it occurs,
        so that ``lft(Delta, M)`` is ``sys`` in normalized coordinates. Each normalized block
        keeps the ``unit`` and ``quantity`` of the block it stands for (its value is ``delta``,
        dimensionless; the unit says what ``delta`` scales).
    """
    from oos_drake.lfr.blocks import UComplex, ULTIDyn, UReal
    from oos_drake.lfr.core import BlockEntry, append_systems

    names = sorted(sys.uncertainty if names is None else names)
    _known(sys, names, "lftdata")
    n = sys.nstates
    z_sub, w_sub, rows_keep, cols_keep = _split(sys, names)
    n_int_r = n + sys.nz - z_sub.size
    n_int_c = n + sys.nw - w_sub.size
    rows = np.concatenate([rows_keep[:n_int_r], z_sub, rows_keep[n_int_r:]])
    cols = np.concatenate([cols_keep[:n_int_c], w_sub, cols_keep[n_int_c:]])
    remaining = tuple(e for e in sys.block_entries if e.spec.name not in names)
    out_names = in_names = None
    if sys.output_names is not None:
        out_names = [None] * z_sub.size + list(sys.output_names)
    if sys.input_names is not None:
        in_names = [None] * w_sub.size + list(sys.input_names)
    M = LFR(
        sys.M[..., rows[:, None], cols[None, :]],
        n,
        remaining,
        input_names=in_names,
        output_names=out_names,
    )
    atoms = []
    for entry in sys.block_entries:
        if entry.spec.name not in names:
            continue
        spec = entry.spec
        facts = {"unit": spec.unit, "quantity": spec.quantity}
        if isinstance(spec, UReal):
            unit = UReal(spec.name, 0.0, -1.0, 1.0, **facts)
        elif isinstance(spec, UComplex):
            unit = UComplex(spec.name, 0.0, 1.0, **facts)
        else:
            unit = ULTIDyn(spec.name, spec.io_shape, 1.0, **facts)
        atom = LFR(unit.atom(), 0, (BlockEntry(unit, 1),))
        atoms.extend([atom] * entry.reps)
    Delta = append_systems(atoms) if atoms else LFR.from_matrix(np.zeros((0, 0)))
    return M, Delta
