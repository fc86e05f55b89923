"""Worst cases against brute force: robstab's destabilizing size vs vertices + random points on
models extracted with ``oos ulinearize``, and mussv's lower bound on repeated complex scalar
blocks vs a brute-force search over the blocks' phases.

Run: ``python benchmarks/bench_worst_cases.py`` (needs pydrake). Prints one table per part.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

ROOT = Path(__file__).resolve().parents[1]


def _abscissa(loop, names, X):
    """Spectral abscissa of ``A + Bw Delta (I - Dzw Delta)^{-1} Cz`` at normalized parameters."""
    A, Bw, Cz, Dzw = (np.asarray(m) for m in (loop.A, loop.Bw, loop.Cz, loop.Dzw))
    slices = loop.channel_slices()
    out = []
    for x in X:
        delta = np.zeros((Dzw.shape[1], Dzw.shape[0]))
        for value, name in zip(x, names, strict=True):
            z, w = slices[name]
            delta[w, z] = value * np.eye(w.stop - w.start)
        Acl = A + Bw @ delta @ np.linalg.solve(np.eye(Dzw.shape[0]) - Dzw @ delta, Cz)
        out.append(np.linalg.eigvals(Acl).real.max())
    return np.array(out)


def _first_crossing(loop, names, d, t_max, steps=60):
    ts = np.linspace(0.0, t_max, steps + 1)[1:]
    bad = np.flatnonzero(_abscissa(loop, names, ts[:, None] * d[None]) >= 0)
    if bad.size == 0:
        return np.inf
    lo, hi = (ts[bad[0] - 1] if bad[0] else 0.0), ts[bad[0]]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _abscissa(loop, names, [mid * d])[0] >= 0 else (mid, hi)
    return hi


def box_brute_force(loop, t_max, rng, random_points=1000):
    """Smallest first instability along the rays of all vertices and ``random_points``
    random directions (screened at the best level found so far)."""
    names = list(loop.uncertainty)
    k = len(names)
    V = 2.0 * ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) - 1.0
    R = rng.uniform(-1, 1, (random_points, k))
    best = {}
    for label, D in (("vertex", V), ("random", R / np.abs(R).max(axis=1, keepdims=True))):
        level = t_max
        for d in D[_abscissa(loop, names, t_max * D) >= 0]:
            level = min(level, _first_crossing(loop, names, d, level))
        best[label] = level
    return best


def _loops():
    from oos_drake.app.main import main
    from oos_drake.lfr import LFR, feedback, load_lfr

    out = Path("/tmp") / "bench_worst_cases"
    data = ROOT / "tests" / "robust" / "data"
    loops = {}
    args = ["ulinearize", str(data / "sprung_hub.sdf")]
    args += ["--parameters", str(data / "sprung_hub_parameters.toml")]
    args += ["--input", "sprung_hub_actuation", "--output", "sprung_hub_state[0,3]"]
    assert main([*args, "--out", str(out), "--name", "hub"]) == 0
    hub = load_lfr(out / "hub.npz")
    for kp, kd, tau in ((4000.0, 4000.0, 0.15), (2000.0, 2500.0, 0.3)):
        K = LFR.from_ss([[-1 / tau]], np.array([[kp, kd]]) / tau, [[-1.0]], np.zeros((1, 2)))
        loops[f"sprung hub, PD {kp:g}/{kd:g}, lag {tau:g} s"] = feedback(hub, K, sign=1)
    servicer = ROOT / "examples" / "servicer"
    args = ["ulinearize", str(servicer / "servicer.sdf")]
    args += ["--parameters", str(servicer / "servicer_parameters.toml")]
    args += ["--input", "servicer_actuation", "--output", "servicer_state[0,1,2,7,8,9]"]
    assert main([*args, "--out", str(out), "--name", "servicer"]) == 0
    G = load_lfr(out / "servicer.npz")
    K = LFR.from_ss(-np.eye(3) / 0.3, np.hstack([np.eye(3) * 200, np.eye(3) * 300]) / 0.3,
                    -np.eye(3), np.zeros((3, 6)))  # fmt: skip
    loops["servicer example, PD 200/300, lag 0.3 s"] = feedback(G, K, sign=1)
    return loops


def robstab_part():
    from oos_drake.robust import robstab

    print("robstab destabilizing size vs vertices + 1000 random directions")
    print(f"{'model':44s} {'robstab':>9s} {'source':>16s} {'vertex':>9s} {'random':>9s} "
          f"{'vs best':>8s} {'time':>6s}")  # fmt: skip
    for label, loop in _loops().items():
        clock = time.perf_counter()
        res = robstab(loop, guaranteed=False)
        seconds = time.perf_counter() - clock
        brute = box_brute_force(loop, 1.3 * res.upper, np.random.default_rng(123))
        excess = 100 * (res.upper / min(brute.values()) - 1)
        print(
            f"{label:44s} {res.upper:9.5f} {res.worst_case_source:>16s} "
            f"{brute['vertex']:9.5f} {brute['random']:9.5f} {excess:+7.3f}% {seconds:5.1f}s"
        )


def complex_part(trials=40):
    from oos_drake.robust import mussv

    reps = (2, 1, 2, 1)
    blk = [[r, 0] for r in reps]
    n = sum(reps)
    owner = np.repeat(np.arange(len(reps)), reps)
    rng = np.random.default_rng(2)
    ratios = []
    for _ in range(trials):
        M = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))

        def rho(th, M=M):
            th = np.atleast_2d(th)
            full = np.concatenate([np.zeros((th.shape[0], 1)), th], axis=1)
            D = np.zeros((th.shape[0], n, n), complex)
            D[:, np.arange(n), np.arange(n)] = np.exp(1j * full[:, owner])
            return np.abs(np.linalg.eigvals(M @ D)).max(axis=1)

        P = rng.uniform(-np.pi, np.pi, (20000, len(reps) - 1))
        values = rho(P)
        brute = max(
            -minimize(
                lambda t: -rho(t)[0],
                P[i],
                method="Nelder-Mead",
                options=dict(xatol=1e-9, fatol=1e-12, maxiter=4000),
            ).fun  # fmt: skip
            for i in np.argsort(-values)[:5]
        )
        with_phases = mussv(M, blk).lower
        power_only = mussv(M, blk, phase_search=False).lower
        ratios.append((power_only / brute, with_phases / brute))
    ratios = np.array(ratios)
    print(f"\nmussv lower bound / phase brute force, {trials} random 6x6, BLK {blk}")
    print(f"  power iteration only: min {ratios[:, 0].min():.4f}, mean {ratios[:, 0].mean():.4f}")
    print(f"  with phase search:    min {ratios[:, 1].min():.4f}, mean {ratios[:, 1].mean():.4f}")


if __name__ == "__main__":
    robstab_part()
    complex_part()
