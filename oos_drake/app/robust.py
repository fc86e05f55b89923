"""``oos robust mussv|hinfnorm|robstab|sweep``: mu bounds, H-infinity norms, stability margins.

Files are ``.npz`` (numpy) or ``.mat`` (MATLAB, e.g. written by ``save``): ``mussv`` reads the
variables ``M`` and ``blk`` (MATLAB BLK rows); ``hinfnorm`` reads ``A``, ``B``, ``C``, ``D``.
Model arrays are shaped as each format's home does: in a ``.mat`` file the batch dimensions come
last (MATLAB's ``M(:, :, k)``, ``sum(c) x sum(r) x K``), in a ``.npz`` file first
(``M[k]``, ``(K, sum(c), sum(r))``).

Examples::

    oos robust mussv case.mat                    # M and blk from MATLAB
    oos robust mussv sweep.npz --out bounds.npz  # batch: writes upper, lower, delta, D, G
    oos robust hinfnorm plant.npz
    oos robust robstab closed_loop.npz           # LFR file (lfr.to_npz / to_mat, oos ulinearize)
    oos robust robstab loop.npz --out mu.csv     # also the mu bounds per frequency (sweep table)
    oos robust sweep loops.npz --out mu.parquet  # LFR model array: every model (robust_sweep)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from oos_drake.app.args import add_out_argument


def _load(path: str, names) -> dict:
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if p.suffix == ".npz":
        with np.load(p) as data:
            found = {k: np.asarray(data[k]) for k in data.files}
    elif p.suffix == ".mat":
        from oos_drake.lfr.matfile import read_mat

        found = read_mat(p, matrices=("M", "A", "B", "C", "D"))
    else:
        raise ValueError(f"{path}: expected a .npz or .mat file, got {p.suffix or 'no suffix'!r}")
    missing = [n for n in names if n not in found]
    if missing:
        raise ValueError(f"{path}: missing variable(s) {missing} (found {sorted(found)})")
    return {n: found[n] for n in names}


def _mussv(args: argparse.Namespace) -> int:
    from oos_drake.robust import mussv

    data = _load(args.file, ["M", "blk"])
    res = mussv(data["M"], data["blk"])
    upper, lower = np.atleast_1d(res.upper), np.atleast_1d(res.lower)
    print(f"blk {res.blk.tolist()}; {upper.size} matrix(es)")
    if upper.size <= 20:
        for k, (u, lo) in enumerate(zip(upper, lower, strict=True)):
            print(f"  [{k}] mu in [{lo:.6g}, {u:.6g}]")
    print(f"peak: mu in [{lower.max():.6g}, {upper.max():.6g}]")
    if args.out:
        from oos_drake.files import atomic_write_bytes

        # np.savez's own naming (".npz" appended when missing), written atomically
        out = Path(args.out if str(args.out).endswith(".npz") else f"{args.out}.npz")
        arrays = dict(upper=res.upper, lower=res.lower, delta=res.delta)
        arrays.update(D_left=res.D_left, D_right=res.D_right, G=res.G)
        atomic_write_bytes(out, lambda stream: np.savez(stream, **arrays))
        print(f"bounds and certificates written to {out}")
    return 0


def _hinfnorm(args: argparse.Namespace) -> int:
    from oos_drake.robust import hinfnorm

    data = _load(args.file, ["A", "B", "C", "D"])
    res = hinfnorm(tuple(data[k] for k in "ABCD"))
    norm = np.atleast_1d(res.norm)
    freq = np.atleast_1d(res.peak_frequency)
    for k, (g, w) in enumerate(zip(norm, freq, strict=True)):
        print(f"  [{k}] ||G||_inf = {g:.8g} at {w:.6g} rad/s")
    return 0


def _load_lfr(args: argparse.Namespace):
    """The LFR of ``args.file``, after checking that ``--out`` (if any) is a table file."""
    from oos_drake.lfr import load_lfr

    if args.out and Path(args.out).suffix not in (".csv", ".parquet"):
        raise ValueError(f"--out {args.out}: expected a .csv or .parquet file")
    return load_lfr(args.file)


def _robstab(args: argparse.Namespace) -> int:
    from oos_drake.robust import robstab

    sys = _load_lfr(args)
    res = robstab(sys, blocks=args.blocks)
    if not res.nominal_stable:
        print(f"{args.file}: the nominal model is unstable (margin 0)")
        return 0
    print(f"{args.file}: {sys.nstates} states, blocks {list(sys.occurrences.items())}")
    print(res.summary())
    for name, value in res.worst_case.items():
        print(f"  destabilizing {name} = {value}")
    if args.out:
        _write_table(res.table(subset=",".join(args.blocks) if args.blocks else "total"), args.out)
        print(f"mu bounds per frequency written to {args.out}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from oos_drake.robust import robust_sweep

    sys = _load_lfr(args)
    subsets = {",".join(args.blocks): args.blocks} if args.blocks else None
    table = robust_sweep(sys, subsets=subsets, n_jobs=args.workers)
    print(f"{args.file}: {table['model'].nunique()} model(s), blocks {list(sys.occurrences)}")
    peaks = table.groupby(["subset", "model"], sort=False).agg(
        lower=("mu lower [-]", "max"),
        upper=("mu upper [-]", "max"),
        guaranteed=("mu upper guaranteed [-]", "first"),
        covered=("covered", "first"),
        reason=("reason", "first"),
    )
    for (subset, model), row in peaks.iterrows():
        axis = (
            f"<= {row.guaranteed:.6g} on the whole frequency axis"
            if row.covered
            else f"not proved on the whole frequency axis: {row.reason}"
        )
        grid = f"peak mu in [{row.lower:.6g}, {row.upper:.6g}] on the grid"
        print(f"  {subset} [{model}]: {grid}, {axis}")
    if args.out:
        _write_table(table, args.out)
        print(f"mu bounds per model and frequency written to {args.out}")
    return 0


def _write_table(table, path: str) -> None:
    """Write a table atomically as CSV or Parquet, chosen by the suffix of ``path`` (checked by
    :func:`_load_lfr`)."""
    from oos_drake.files import atomic_write_parquet, atomic_write_text

    if Path(path).suffix == ".parquet":
        atomic_write_parquet(table, Path(path))
    else:
        atomic_write_text(table.to_csv(index=False), Path(path))


def register(subparsers) -> None:
    """Add ``oos robust ...`` to the ``oos`` parser."""
    robust = subparsers.add_parser(
        "robust",
        help="structured singular value and H-infinity norm of stored matrices",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = robust.add_subparsers(dest="robust_command", metavar="ACTION", required=True)
    mu = commands.add_parser("mussv", help="mu upper/lower bounds of M for the structure blk")
    mu.add_argument("file", help=".npz or .mat file with variables M and blk")
    add_out_argument(mu, required=False, help=".npz file for bounds, delta and scalings")
    mu.set_defaults(func=_mussv)
    hinf = commands.add_parser("hinfnorm", help="H-infinity norm of (A, B, C, D)")
    hinf.add_argument("file", help=".npz or .mat file with variables A, B, C, D")
    hinf.set_defaults(func=_hinfnorm)
    stab = commands.add_parser("robstab", help="robust stability margin of a stored LFR")
    stab.add_argument("file", help=".npz or .mat LFR file (oos_drake.lfr.load_lfr)")
    stab.add_argument("--blocks", nargs="+", default=None, help="analyze only these blocks")
    add_out_argument(
        stab,
        required=False,
        help=".csv or .parquet file for the mu bounds per frequency (the mu sweep table)",
    )
    stab.set_defaults(func=_robstab)
    sweep = commands.add_parser(
        "sweep", help="mu bounds of every model of a stored LFR model array (robust_sweep)"
    )
    sweep.add_argument("file", help=".npz or .mat LFR file, possibly a model array")
    sweep.add_argument("--blocks", nargs="+", default=None, help="analyze only these blocks")
    sweep.add_argument("--workers", type=int, default=1, help="worker processes")
    add_out_argument(sweep, required=False, help=".csv or .parquet file for the mu sweep table")
    sweep.set_defaults(func=_sweep)
