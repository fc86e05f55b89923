"""Benchmark: mussv on the paper-sized structure vs an LMI D-G upper bound written with cvxpy.

Structure: 2 x [-3, 0] (masses), 4 x [-2, 0] (modal frequencies), one full [3, 3] (additive LTI),
nine [1, 0] (multiplicative complex scalars): M is 26 x 26, 16 blocks. Matrices are frequency
responses of a synthetic closed loop with that structure (see ``bench_robust_sweep.py``).

Baseline (what a Python user writes today): for a trial beta, find ``D_k >= I`` and Hermitian
``G_k`` with ``M^* D_l M + j (G M - M^* G^*) - beta^2 D_r <= 0`` with cvxpy (Clarabel), bisect on
beta. Both are timed in the same run, on one BLAS thread.

Prints wall and CPU time per matrix for both bounds and each bound (CPU is the robust figure on
a shared machine) for independent matrices (the headline) and with ``continuation=True``
(neighbouring frequencies warm-start each other: the sweep use case), the same algorithm
in numpy (the tests' oracles) in the same run, the first-call compile time of the numba kernels
(fresh processes, excluded from the per-matrix times), eigen-decompositions per matrix, the
speed-up over cvxpy and the relative difference of the values (same run), the upper/lower gap
and the certificate checks, and the per-matrix time of the upper bound on small batches (1, 2, 4
and 8 matrices: lone calls, warm-started points), then issue 29's reference case (Gaussian 26 x 26
matrices, batched and single calls, with the compiled D-G optimizer's share of the CPU time, the
eigenvalue problems per matrix and the gap) for this checkout and for the ``oos_drake`` of the git
revision ``--baseline`` (default ``main``, extracted with ``git archive``), in alternating fresh
processes of the same run, with the ratios; ``--frontier`` adds the time vs accuracy of the upper
bound for several iteration budgets.

Run: ``.venv/bin/python benchmarks/bench_mussv.py [--matrices 200] [--lmi 3] [--frontier]``;
issue 29's reference case alone: ``benchmarks/bench_mussv.py --gaussian-only [--baseline REV]
[--rounds N]``.

Two checkouts back to back (same load; the bounds of the second against the first's)::

    cd benchmarks
    PYTHONPATH=/path/to/main python bench_mussv.py --no-compile --save-values /tmp/main.npz
    PYTHONPATH=/path/to/branch python bench_mussv.py --no-compile --compare-values /tmp/main.npz
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from oos_drake.robust.blocks import REAL, parse_blk

#: The two runs of issue 29's reference case (:func:`gaussian_case`).
CASES = ("batched", "single")

#: Sizes of the small batches timed matrix by matrix (lone matrices, warm-started points).
SMALL_BATCHES = (1, 2, 4, 8)


def cvxpy_dg_upper_bound(M, blk, *, rtol: float = 1e-4, solver: str = "CLARABEL"):
    """Return ``(beta, n_solves)``: the LMI D-G upper bound of mu by bisection on beta."""
    import cvxpy as cp

    s = parse_blk(blk)
    M = np.asarray(M, dtype=complex)
    c, r = s.m_shape
    beta2 = cp.Parameter(nonneg=True)
    cons = []
    quad = 0
    right = 0
    gterm = 0
    for b in s.blocks:
        Mk = M[b.c_slice, :]  # rows of M feeding this block
        Er = np.zeros((r, b.rows))
        Er[b.r_slice, :] = np.eye(b.rows)
        if b.repeated:
            Dk = cp.Variable((b.rows, b.rows), hermitian=True)
            cons.append(Dk >> np.eye(b.rows))
            quad = quad + Mk.conj().T @ Dk @ Mk
            right = right + Er @ Dk @ Er.T
            if b.kind == REAL:
                Gk = cp.Variable((b.rows, b.rows), hermitian=True)
                GM = Er @ Gk @ Mk
                gterm = gterm + 1j * (GM - GM.H)
        else:
            dk = cp.Variable(nonneg=True)
            cons.append(dk >= 1)
            quad = quad + dk * (Mk.conj().T @ Mk)
            right = right + dk * (Er @ Er.T)
    lmi = quad + gterm - beta2 * right
    lmi = (lmi + lmi.H) / 2
    prob = cp.Problem(cp.Minimize(0), cons + [lmi << 0])
    lo, hi = 0.0, float(np.linalg.norm(M, 2)) * (1 + 1e-9)
    n_solves = 0
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        beta2.value = mid**2
        try:
            prob.solve(solver=solver)
            feasible = prob.status in ("optimal", "optimal_inaccurate")
        except cp.error.SolverError:
            feasible = False
        n_solves += 1
        if feasible:
            hi = mid
        else:
            lo = mid
    return hi, n_solves


def _clock() -> tuple[float, float]:
    """(wall, CPU) time of this process [s]: the machine is shared, the CPU time is the robust
    figure; the wall time is what a user sees on an idle machine."""
    return time.perf_counter(), time.process_time()


def _since(t0, n=1) -> tuple[float, float]:
    """(wall, CPU) seconds per item since ``t0 = _clock()``."""
    w, c = _clock()
    return (w - t0[0]) / n, (c - t0[1]) / n


def compile_times() -> tuple[float, float]:
    """(first call with an empty numba cache, first call with the cache filled) [s, wall].

    Each is a fresh process running ``mussv`` on 2 and on 8 matrices with the paper's
    structure (the lane optimizer with idle lanes and with all busy) from a fresh cache
    directory: the first
    pays the compilation of the kernels (as CI does on a fresh clone), the second only loads
    them (as every later process does).
    """
    import subprocess
    import sys
    import tempfile

    code = (
        "import time; t0 = time.perf_counter(); import numpy as np; "
        "from oos_drake.robust import mussv; "
        "from bench_robust_sweep import PAPER_BLK; "
        "M = np.random.default_rng(0).standard_normal((8, 26, 26)) + 0j; "
        "mussv(M[:2], PAPER_BLK); mussv(M, PAPER_BLK); t1 = time.perf_counter(); "
        "mussv(M[:2], PAPER_BLK); mussv(M, PAPER_BLK); "
        "print(t1 - t0 - (time.perf_counter() - t1))"
    )
    out = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        bench_dir = os.path.dirname(os.path.abspath(__file__))
        for _ in range(2):
            res = subprocess.run(
                [sys.executable, "-c", code],
                env=env,
                cwd=bench_dir,
                capture_output=True,
                text=True,
                check=True,
            )
            out.append(float(res.stdout.strip().splitlines()[-1]))
    return out[0], out[1]


def gaussian_case(reps: int, n: int = 64) -> dict:
    """Issue 29 item 6's reference case, measured with whatever ``oos_drake`` is imported:
    Gaussian 26 x 26 complex matrices with the paper's structure, one thread.

    Returns CPU per matrix [s] of ``mussv`` batched (``batched``) and in single-matrix calls
    (``single``), the share of the compiled D-G optimizer (``mu_lanes.dg_minimize_lanes``) in
    each (``*_kernel``; the rest is the Python around it: balancing, certification, the lower
    bound), the mean eigenvalue problems per matrix of the upper bound (``evaluations``) and
    the gap ``upper / lower - 1`` of both runs (``*_gap_median``, ``*_gap_max``) and the bounds
    themselves (``*_upper``, ``*_lower``: lists, one entry per matrix).
    """
    from bench_robust_sweep import PAPER_BLK

    import oos_drake.robust.mu_lanes as mu_lanes
    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import mussv

    limit_blas_threads(1)
    rng = np.random.default_rng(0)
    M = (rng.standard_normal((n, 26, 26)) + 1j * rng.standard_normal((n, 26, 26))) / 5
    kernel = mu_lanes.dg_minimize_lanes
    spent = [0.0]
    evals = []

    def timed_kernel(*a):
        t0 = time.process_time()
        kernel(*a)
        spent[0] += time.process_time() - t0
        evals.append(a[-1].copy())  # n_evals of the call (per matrix)

    mussv(M[:8], PAPER_BLK)
    mussv(M[:1], PAPER_BLK)
    out = {}
    mu_lanes.dg_minimize_lanes = timed_kernel  # mu_upper calls it through the module
    try:
        for name, run in (
            ("batched", lambda: [mussv(M, PAPER_BLK)]),
            ("single", lambda: [mussv(M[k], PAPER_BLK) for k in range(n)]),
        ):
            best = None
            for _ in range(reps):
                spent[0] = 0.0
                evals.clear()
                t0 = time.process_time()
                res = run()
                total = (time.process_time() - t0) / n
                if best is None or total < best[0]:
                    best = (total, spent[0] / n, np.concatenate(evals), res)
            total, k, ev, res = best
            upper = np.concatenate([np.ravel(r.upper) for r in res])
            lower = np.concatenate([np.ravel(r.lower) for r in res])
            gap = upper / lower - 1
            out[name + "_upper"] = upper.tolist()  # the baseline's bounds, compared with
            out[name + "_lower"] = lower.tolist()  # this checkout's (gaussian_vs_baseline)
            out[name] = total
            out[name + "_kernel"] = k
            out[name + "_gap_median"] = float(np.median(gap))
            out[name + "_gap_max"] = float(np.max(gap))
            if name == "batched":
                out["evaluations"] = float(np.mean(ev))
    finally:
        mu_lanes.dg_minimize_lanes = kernel
    return out


def baseline_checkout(ref: str) -> str:
    """A copy of ``oos_drake`` at git revision ``ref`` (``git archive`` into a directory of the
    system's temporary directory named after the commit, reused by later runs); returns the
    directory to put on ``PYTHONPATH``.

    The numba caches of modules identical in ``ref`` and in this checkout are copied along with
    the source's modification time (numba checks it): only changed kernels compile.
    """
    import shutil
    import subprocess
    import tempfile

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    git = ["git", "-C", root]
    sha = subprocess.run(
        git + ["rev-parse", "--verify", f"{ref}^{{commit}}"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    dest = os.path.join(tempfile.gettempdir(), "oos_bench_baseline", sha)
    if not os.path.isdir(os.path.join(dest, "oos_drake")):
        tmp = dest + f".part{os.getpid()}"
        os.makedirs(tmp, exist_ok=True)
        archive = subprocess.run(
            git + ["archive", "--format=tar", sha, "oos_drake"], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        changed = set(
            subprocess.run(
                git + ["diff", "--name-only", sha, "--", "oos_drake"],
                capture_output=True,
                text=True,
                check=True,
            ).stdout.split()
        )
        for dirpath, _dirs, files in os.walk(os.path.join(root, "oos_drake")):
            cache = os.path.join(dirpath, "__pycache__")
            for f in files:
                rel = os.path.relpath(os.path.join(dirpath, f), root)
                target = os.path.join(tmp, rel)
                if not f.endswith(".py") or rel in changed or not os.path.isfile(target):
                    continue
                stem = f[:-3] + "."
                nb = (
                    [
                        c
                        for c in os.listdir(cache)
                        if c.startswith(stem) and c.endswith((".nbi", ".nbc"))
                    ]
                    if os.path.isdir(cache)
                    else []
                )
                if not nb:
                    continue
                os.makedirs(os.path.join(os.path.dirname(target), "__pycache__"), exist_ok=True)
                for c in nb:
                    shutil.copy2(
                        os.path.join(cache, c),
                        os.path.join(os.path.dirname(target), "__pycache__", c),
                    )
                st = os.stat(os.path.join(dirpath, f))
                os.utime(target, ns=(st.st_atime_ns, st.st_mtime_ns))
        try:
            os.replace(tmp, dest)
        except OSError:  # another run got there first
            shutil.rmtree(tmp, ignore_errors=True)
    return dest


def _gaussian_in_process(pythonpath: str, reps: int) -> dict:
    """:func:`gaussian_case` in a fresh process with ``oos_drake`` from ``pythonpath``."""
    import json
    import subprocess

    bench_dir = os.path.dirname(os.path.abspath(__file__))
    code = f"import json, bench_mussv; print(json.dumps(bench_mussv.gaussian_case({int(reps)})))"
    env = dict(os.environ, PYTHONPATH=pythonpath)
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=bench_dir, capture_output=True, text=True
    )
    if res.returncode != 0:
        raise RuntimeError(f"gaussian case with PYTHONPATH={pythonpath} failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def gaussian_vs_baseline(reps: int, baseline: str | None = "main", rounds: int = 2) -> None:
    """Print issue 29 item 6's reference case (:func:`gaussian_case`) for this checkout and,
    same run, for the git revision ``baseline`` (:func:`baseline_checkout`), in alternating
    fresh processes (``rounds`` each, the fastest kept: a shared machine), with the ratios."""
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    runs = {"this checkout": here}
    if baseline:
        runs[f"baseline {baseline}"] = baseline_checkout(baseline)
    got = {}
    for _ in range(max(1, rounds)):  # alternating: both see the same load
        for name, path in runs.items():
            r = _gaussian_in_process(path, reps)
            if name not in got or r["batched"] + r["single"] < sum(got[name][k] for k in CASES):
                got[name] = r
    print(
        "Gaussian 26 x 26, paper structure, 1 thread, 64 matrices (issue 29: <= 1 ms batched, "
        "<= 3 ms single; fresh processes, fastest of "
        f"{max(1, rounds)} x {reps} runs)"
    )
    print(
        f"{'CPU per matrix [ms]':36}{'total':>8}{'D-G kernel':>12}{'rest':>8}"
        f"{'eig/matrix':>12}{'gap median':>12}{'gap max':>10}"
    )
    for name, r in got.items():
        for case in CASES:
            t, k = r[case], r[case + "_kernel"]
            ev = f"{r['evaluations']:12.1f}" if case == "batched" else f"{'':12}"
            print(
                f"{'  ' + name + ', ' + case:36}{t * 1e3:8.2f}{k * 1e3:12.2f}{(t - k) * 1e3:8.2f}"
                f"{ev}{r[case + '_gap_median'] * 100:11.2f}%{r[case + '_gap_max'] * 100:9.2f}%"
            )
    if baseline:
        new, old = got["this checkout"], got[f"baseline {baseline}"]
        print(
            f"ratio this checkout / {baseline} (CPU): batched "
            f"{new['batched'] / old['batched']:.2f}, "
            f"single {new['single'] / old['single']:.2f}; D-G kernel batched "
            f"{new['batched_kernel'] / old['batched_kernel']:.2f}, single "
            f"{new['single_kernel'] / old['single_kernel']:.2f}"
        )
        for case in CASES:  # same matrices: the bounds must not move beyond round-off
            ch = {
                k: np.asarray(new[f"{case}_{k}"]) / np.asarray(old[f"{case}_{k}"]) - 1
                for k in ("upper", "lower")
            }
            gap_new = np.asarray(new[f"{case}_upper"]) / np.asarray(new[f"{case}_lower"])
            gap_old = np.asarray(old[f"{case}_upper"]) / np.asarray(old[f"{case}_lower"])
            ch["gap"] = gap_new / gap_old - 1
            print(
                f"bounds vs {baseline}, {case} (relative change per matrix, median / max |.|): "
                + ", ".join(
                    f"{k} {np.median(v):+.1e} / {np.max(np.abs(v)):.1e}" for k, v in ch.items()
                )
            )


def main(argv=None):
    import warnings

    from bench_robust_sweep import PAPER_BLK, paper_like_lfr

    from oos_drake.blas import limit_blas_threads
    from oos_drake.robust import mussv
    from oos_drake.robust.lfr_analysis import delta_channel_response
    from oos_drake.robust.mu import (
        UPPER_ITERATIONS,
        UPPER_PATIENCE,
        UPPER_TEMPERATURES,
        UPPER_TOL,
        _lower_bound,
        _upper_bound,
    )
    from oos_drake.robust.mu_upper import mu_upper_bound

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--matrices", type=int, default=200)
    parser.add_argument("--lmi", type=int, default=3, help="matrices solved by the cvxpy baseline")
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="runs of each timed batch; the fastest (by CPU) is reported (shared machine)",
    )
    parser.add_argument(
        "--no-compile",
        dest="compile",
        action="store_false",
        help="skip the compile-time measurement (two fresh processes)",
    )
    parser.add_argument(
        "--baseline",
        default="main",
        help="git revision whose oos_drake the issue-29 reference case is compared with, same "
        "run ('' : none)",
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=2,
        help="alternating fresh processes per checkout in issue 29's reference case (the fastest "
        "is kept: more rounds, less noise on a loaded machine)",
    )
    parser.add_argument(
        "--gaussian-only",
        action="store_true",
        help="only issue 29's reference case (Gaussian matrices) against --baseline",
    )
    parser.add_argument(
        "--frontier",
        action="store_true",
        help="also print time vs accuracy of the upper bound for several iteration budgets",
    )
    parser.add_argument(
        "--save-values",
        metavar="NPZ",
        help="write the upper bounds (full batch, small batches) to this file, e.g. to compare "
        "two checkouts with --compare-values",
    )
    parser.add_argument(
        "--compare-values",
        metavar="NPZ",
        help="print the relative difference of the upper bounds to those saved by --save-values",
    )
    args = parser.parse_args(argv)
    if args.gaussian_only:
        gaussian_vs_baseline(max(1, args.repeats), args.baseline or None, args.rounds)
        return
    limit_blas_threads(1)
    warnings.filterwarnings("ignore")
    lfr = paper_like_lfr(1)
    omega = np.geomspace(0.1, 200.0, args.matrices)
    M = delta_channel_response(lfr.A[0], lfr.Bw[0], lfr.Cz[0], lfr.Dzw[0], omega)
    s = parse_blk(PAPER_BLK)
    n = len(M)

    def upper(Ms):  # the upper bound exactly as mussv runs it (defaults)
        return mu_upper_bound(
            Ms,
            s,
            max_iter=UPPER_ITERATIONS,
            tol=UPPER_TOL,
            temperatures=UPPER_TEMPERATURES,
            patience=UPPER_PATIENCE,
        )

    t_compile = compile_times() if args.compile else None
    mussv(M[:16], PAPER_BLK)  # warm-up (imports, caches): the lane optimizer (batches) ...
    upper(M[:1])  # ... and single-matrix calls (seven idle lanes)
    reps = max(1, args.repeats)

    def best(run):
        """``(result, (wall, CPU) per matrix)``: the fastest of ``reps`` runs (shared machine)."""
        times = []
        for _ in range(reps):
            t0 = _clock()
            out = run()
            times.append(_since(t0, n))
        return out, min(times, key=lambda t: t[1])

    res, t_both = best(lambda: mussv(M, PAPER_BLK))
    up, t_up = best(lambda: upper(M))
    # small batches (a lone matrix, warm-started points): contiguous slices spread over the grid
    small = {}
    for size in SMALL_BATCHES:
        starts = np.linspace(0, n - size, min(8, n - size + 1)).round().astype(int)
        vals, t_small = best(
            lambda size=size, starts=starts: [upper(M[k : k + size]).upper for k in starts]
        )
        small[size] = (np.concatenate(vals), tuple(v * n / (size * len(starts)) for v in t_small))
    evals = float(np.mean(up.evaluations))
    _, t_lo = best(
        lambda: _lower_bound(
            M, s, up, restarts=4, iters=60, rng=np.random.default_rng(0), restart_gap=1.02
        )
    )
    # the same algorithms in numpy (the tests' oracles, tests/robust/oracles.py) in mussv's
    # place of the kernels, same run: the speed-up is load-robust
    import oos_drake.robust.mu as mu_module

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../tests/robust"))
    import oracles

    kernels = mu_module.mu_upper_bound, mu_module.mu_lower_bound
    try:
        mu_module.mu_upper_bound, mu_module.mu_lower_bound = (
            oracles.mu_upper_bound,
            oracles.mu_lower_bound,
        )
        res_np, t_both_np = best(lambda: mussv(M, PAPER_BLK))
    finally:
        mu_module.mu_upper_bound, mu_module.mu_lower_bound = kernels
    # continuation along the frequency axis (neighbouring frequencies warm-start each other)
    res_c, t_both_c = best(lambda: mussv(M, PAPER_BLK, continuation=True))
    up_c, t_up_c = best(lambda: _upper_bound(M, s, UPPER_ITERATIONS, UPPER_TOL, continuation=True))
    evals_c = float(np.mean(up_c.evaluations))

    pick = np.linspace(0, n - 1, args.lmi).round().astype(int)
    pick = np.unique(np.r_[pick, np.argmax(res.upper)])[: max(args.lmi, 1)]
    lmi_vals, lmi_times = [], []
    for k in pick:
        t0 = _clock()
        beta, _ = cvxpy_dg_upper_bound(M[k], PAPER_BLK)
        lmi_times.append(_since(t0))
        lmi_vals.append(beta)
    ours_1 = []
    for k in pick:  # single-matrix calls, no batching advantage
        t0 = _clock()
        ub = upper(M[k : k + 1]).upper[0]
        ours_1.append((_since(t0), ub))
    lmi_t = np.mean(lmi_times, axis=0)
    one_t = np.mean([o[0] for o in ours_1], axis=0)
    rel = np.array([o[1] for o in ours_1]) / np.array(lmi_vals) - 1
    rel_batch = res.upper[pick] / np.array(lmi_vals) - 1
    gap = res.upper / np.maximum(res.lower, 1e-300)
    chk = res.check(M)
    print(
        f"structure: {len(PAPER_BLK)} blocks, M {s.n_cols} x {s.n_rows}; batch of {n} "
        f"frequency-response matrices, 1 BLAS thread, load average {os.getloadavg()[0]:.1f}; "
        f"times: fastest of {reps} runs"
    )
    if t_compile is not None:
        print(
            f"first call in a fresh process, wall (not in the per-matrix times): "
            f"{t_compile[0]:.1f} s with an empty numba cache (compilation), "
            f"{t_compile[1]:.2f} s with the cache filled"
        )
    print(f"{'time per matrix [ms]':44}{'wall':>10}{'CPU':>10}")
    for name, t in (
        ("mussv, both bounds (independent matrices)", t_both),
        ("  upper bound only", t_up),
        ("  lower bound only", t_lo),
        ("  upper bound, single-matrix call", one_t),
        ("mussv, both bounds, numpy oracles (tests)", t_both_np),
        ("mussv, both bounds (continuation)", t_both_c),
        ("  upper bound only (continuation)", t_up_c),
        ("cvxpy LMI D-G bound (bisection)", lmi_t),
    ):
        print(f"{name:44}{t[0] * 1e3:10.2f}{t[1] * 1e3:10.2f}")
    print(f"{'upper bound, small batches (per matrix)':44}")
    for size, (_, t) in small.items():
        print(f"{f'  batch of {size}':44}{t[0] * 1e3:10.2f}{t[1] * 1e3:10.2f}")
    values = {"full": up.upper, **{f"batch{k}": v for k, (v, _) in small.items()}}
    if args.save_values:
        np.savez(args.save_values, **values)
    if args.compare_values:
        with np.load(args.compare_values) as ref:
            for key, v in values.items():
                print(
                    f"upper bounds vs {args.compare_values} ({key}): max rel. diff "
                    f"{np.max(np.abs(v / ref[key] - 1)):.1e}"
                )
    print(
        f"target <= 2 ms per matrix for both bounds: independent matrices "
        f"{'MET' if t_both[1] <= 2e-3 else 'NOT met'} (CPU {t_both[1] * 1e3:.2f} ms), "
        f"continuation {'MET' if t_both_c[1] <= 2e-3 else 'NOT met'} "
        f"(CPU {t_both_c[1] * 1e3:.2f} ms)"
    )
    print(
        f"compiled vs numpy oracles (same run, CPU): {t_both_np[1] / t_both[1]:.2f}x; "
        f"numpy-oracle bounds vs compiled: upper max rel. diff "
        f"{np.max(np.abs(res_np.upper / res.upper - 1)):.1e}"
    )
    print(
        f"eigen-decompositions per matrix (upper bound): {evals:.1f} independent, "
        f"{evals_c:.1f} continuation; CPU per evaluation incl. overheads "
        f"{t_up[1] / evals * 1e6:.0f} us"
    )
    print(
        f"speed-up of the upper bound vs cvxpy (CPU, same run): batched {lmi_t[1] / t_up[1]:.0f}x, "
        f"single call {lmi_t[1] / one_t[1]:.0f}x (target >= 50x)"
    )
    print(
        f"upper bound vs cvxpy value: max rel. diff {np.max(np.abs(rel)):.2e} single, "
        f"{np.max(np.abs(rel_batch)):.2e} batched (target <= 1e-2); "
        f"(ours - lmi)/lmi = {np.array2string(rel_batch, precision=4)}"
    )
    rel_c = res_c.upper[pick] / np.array(lmi_vals) - 1
    print(
        f"continuation vs cvxpy value: (ours - lmi)/lmi = {np.array2string(rel_c, precision=4)}; "
        f"vs independent: max {np.max(res_c.upper / res.upper - 1):+.2e}, "
        f"min {np.min(res_c.upper / res.upper - 1):+.2e}"
    )
    gap_c = res_c.upper / np.maximum(res_c.lower, 1e-300)
    for name, g, r in (("independent", gap, res), ("continuation", gap_c, res_c)):
        print(
            f"upper/lower gap ({name}): median {np.median(g):.4f}, max {np.max(g):.4f}; "
            f"at the peak {g[np.argmax(r.upper)]:.4f}; lower = 0 at {(r.lower == 0).sum()} of {n}"
        )
    chk_c = res_c.check(M)
    print(
        f"certificates: max LMI eig {np.max(chk['lmi_max_eig']):.1e} independent, "
        f"{np.max(chk_c['lmi_max_eig']):.1e} continuation (<= 0); max sigma_min(I - M delta) "
        f"{np.nanmax(chk['singularity']):.1e}, {np.nanmax(chk_c['singularity']):.1e}; "
        f"max | ||delta|| lower - 1 | {np.nanmax(np.abs(chk['delta_norm_error'])):.1e}"
    )
    gaussian_vs_baseline(reps, args.baseline or None, args.rounds)
    if args.frontier:
        ref = mu_upper_bound(
            M, s, max_iter=600, tol=1e-12, temperatures=(30.0, 300.0, 3000.0, 30000.0)
        ).upper
        for name, u in (("independent", res.upper), ("continuation", res_c.upper)):
            ex = u / ref - 1
            print(
                f"mussv upper bound ({name}) vs a fully converged D-G bound: "
                f"median {np.median(ex):+.2e}, max {np.max(ex):+.2e}"
            )
        print("upper bound: iterations -> CPU ms/matrix, eigen-decompositions, excess over a")
        print("fully converged D-G bound (600 iterations, 4 stages): median / max")
        for iters in (0, 10, 20, 30, 40, 60, 80, UPPER_ITERATIONS):

            def run(iters=iters, full=False):
                r = mu_upper_bound(
                    M,
                    s,
                    max_iter=iters,
                    tol=UPPER_TOL,
                    temperatures=UPPER_TEMPERATURES,
                    patience=UPPER_PATIENCE,
                )
                return r if full else r.upper

            t0 = _clock()
            u = run()
            t = _since(t0, n)
            ev = float(np.mean(run(full=True).evaluations))
            ex = u / ref - 1
            print(
                f"  {iters:3d} it: {t[1] * 1e3:6.2f} ms, {ev:5.1f} eig, "
                f"{np.median(ex):.2e} / {np.max(ex):.2e}"
            )


if __name__ == "__main__":
    main()
