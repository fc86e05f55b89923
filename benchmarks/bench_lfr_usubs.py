"""Benchmark: vectorized ``usubs`` + batched ``freqresp`` vs a per-sample python-control loop.

The model is a flexible spacecraft built with the LFR algebra only: a rigid hub (3 axes, uncertain
principal inertias) carrying three appendages, each rotated about the hub z axis by a scheduled
angle ``theta_i`` (``tau_i = tan(theta_i / 4)``, Cayley form: 16 occurrences per appendage) and
carrying 9 flexible modes with uncertain frequency (3 occurrences), damping (asymmetric range:
bilinear, 1 occurrence) and participation gain (2 occurrences). Inputs: 3 hub torques [N m];
outputs: 3 hub attitude angles [rad]. That is 60 states and about 200 Delta occurrences.

Fast path: ``usubs`` with arrays of N value sets (one model array, no Python loop per model) and
``freqresp`` of the array (no Python loop per frequency). The state matrix of this model is, like
that of every flexible spacecraft in modal coordinates, 2x2-block diagonal (one block per mode)
up to a rank-3 coupling through the hub, and its inputs and outputs sit on the hub: ``freqresp``
detects this and evaluates ``C (sI - A)^-1 B`` with the Woodbury identity, without any
eigendecomposition (``oos_drake.lfr.coupled_modes``: one real matrix product and closed-form 3x3
solves per model); models it cannot treat take the modal route (one LAPACK ``dgeev`` per model).
The script prints how many models took each route. It is timed with 1 worker thread and with 2
worker threads (the ``workers`` argument of ``usubs`` and ``freqresp``:
chunks of models on a thread pool; numpy's LAPACK/BLAS calls and array loops release the GIL).
BLAS itself is single-threaded everywhere (``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=1``, set below
before numpy is imported), so the baseline loop is single-threaded.

Baseline: for each value set, ``usubs`` with scalars, ``to_ss()`` and
``control.frequency_response``. The baseline is timed on a subset of the samples (half before,
half after the fast paths, since the machine is shared) and scaled linearly to N; it is a loop of
identical iterations. Each repeat measures all three in the same window and gives its own ratios;
the script prints every repeat, the spread, wall-clock and CPU (process) times and the load
average. For scale it also times the eigendecomposition of every model's state matrix alone
(LAPACK ``dgeev``, one thread), which the modal route needs once per model (the floor of that
route, not of the block + low-rank route).

Run: ``python benchmarks/bench_lfr_usubs.py [--samples 1000] [--baseline-samples 40] [--repeats 7]``
(``--models`` is an alias of ``--samples``; use e.g. ``--models 200 --repeats 1`` while iterating).
"""

from __future__ import annotations

import os

# Explicit thread settings, before numpy is imported: BLAS/LAPACK single-threaded in both paths
# (OpenBLAS threads spinning on small matrices under contention slow everything erratically);
# the fast path's parallelism, when asked for, is its own thread pool over chunks of models.
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["OMP_NUM_THREADS"] = "1"
os.environ["MKL_NUM_THREADS"] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import control  # noqa: E402
import numpy as np  # noqa: E402
from scipy.linalg import lapack  # noqa: E402

import oos_drake.lfr.frequency as lfr_frequency  # noqa: E402
from oos_drake.lfr import append, feedback, freqresp, inv, ureal, usubs  # noqa: E402


def rotation_z(tau):
    """Rotation about z by theta, tau = tan(theta/4): R = [(I - tau N)^-1 (I + tau N)]^2 with
    N = skew(e_z) = U V^T (rank 2), so tau enters as tau*I2 per Cayley factor (4 occurrences)."""
    U = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    V = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 0.0]])  # U V^T = skew(e_z)
    tau_I2 = append(tau, tau)
    tau_N = U @ tau_I2 @ V.T
    cayley = inv(np.eye(3) - tau_N) * (np.eye(3) + tau_N)
    cayley_T = (np.eye(3) - tau_N) * inv(np.eye(3) + tau_N)  # transpose of the factor
    return cayley * cayley, cayley_T * cayley_T


def flexible_spacecraft(n_appendages: int = 3, modes_per_appendage: int = 9, seed: int = 7):
    rng = np.random.default_rng(seed)
    integ = control.tf(1, [1, 0])
    inertia = [
        ureal(f"J{axis}", nom, percent=10)
        for axis, nom in zip("xyz", (900.0, 1100.0, 700.0), strict=True)
    ]
    appendages = []
    for i in range(n_appendages):
        tau = ureal(f"tau{i}", 0.0, range=(-1.0, 1.0))  # scheduled angle parameter
        R, R_T = rotation_z(tau)
        modes, gains, directions = [], [], []
        for j in range(modes_per_appendage):
            w0 = 0.6 * (1.45**j) * (1 + 0.1 * i)  # modal frequency [rad/s]
            w = ureal(f"w{i}_{j}", w0, percent=10)
            xi = ureal(f"xi{i}_{j}", 0.005, range=(0.002, 0.01))  # asymmetric -> bilinear
            g = ureal(f"g{i}_{j}", 1.0, percent=20)
            K = 2 * xi * w + w * w * integ  # f = K v, v = (r - f)/s
            modes.append(feedback(K * integ, 1))
            gains.append(g)
            directions.append(rng.standard_normal(3) * np.sqrt(30.0 / (1 + j)))
        L = np.stack(directions, axis=1)  # 3 x modes participation
        Gm = append(*gains)
        appendages.append(R * L * Gm * append(*modes) * Gm * (-L.T) * R_T)
    torque = appendages[0]
    for app in appendages[1:]:
        torque = torque + app
    J_inv = append(*(inv(J) for J in inertia))
    accel = feedback(J_inv, torque, sign=1)  # a = J^-1 (u + T_app(a)),  T_app = -R L g f ...
    double_integ = append(*([integ * integ] * 3))
    return double_integ * accel


class Clock:
    """Wall-clock and process CPU time of a block (CPU time sums all threads of the process)."""

    def __enter__(self):
        self.wall0, self.cpu0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.wall0
        self.cpu = time.process_time() - self.cpu0


def fast_path(sys, values, omega, workers):
    with Clock() as c_subs:
        models = usubs(sys, values, workers=workers)
    with Clock() as c_fr:
        resp = freqresp(models, omega, workers=workers)
    return models, resp, c_subs, c_fr


def relative_difference(resp, ref):
    """Max over samples and frequencies of ||G - G_ref||_F / ||G_ref||_F."""
    nb, nf = ref.shape[:2]
    err = np.linalg.norm((resp - ref).reshape(nb, nf, -1), axis=-1)
    return float(np.max(err / np.linalg.norm(ref.reshape(nb, nf, -1), axis=-1)))


def spread(values):
    v = np.asarray(values)
    return f"median {np.median(v):6.1f}x  (min {v.min():.1f}x, max {v.max():.1f}x)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", "--models", type=int, default=1000, help="value sets (models)")
    parser.add_argument("--baseline-samples", type=int, default=40)
    parser.add_argument("--frequencies", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2, help="worker threads of the fast path")
    args = parser.parse_args(argv)

    load0 = os.getloadavg()
    t0 = time.perf_counter()
    sys = flexible_spacecraft()
    t_build = time.perf_counter() - t0
    n_occ = sum(sys.occurrences.values())
    print(
        f"model: {sys.nstates} states, {sys.noutputs}x{sys.ninputs} I/O, "
        f"{len(sys.occurrences)} blocks, {n_occ} Delta occurrences (built in {t_build:.2f} s)"
    )
    print(
        f"threads: BLAS/LAPACK OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']} "
        f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}; baseline loop 1 thread; fast path "
        f"1 and {args.threads} worker threads; os.cpu_count()={os.cpu_count()}"
    )
    print(f"load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")

    rng = np.random.default_rng(2026)
    specs = sys.uncertainty
    values = {name: spec.sample(rng, args.samples) for name, spec in specs.items()}
    omega = np.logspace(-2, 2, args.frequencies)
    nb = min(args.baseline_samples, args.samples)
    scale = args.samples / nb
    configs = [1] if args.threads <= 1 else [1, args.threads]

    def run_baseline(indices, store):
        wall = cpu = 0.0
        for k in indices:
            with Clock() as c:
                ss_k = usubs(sys, {name: v[k] for name, v in values.items()}).to_ss()
                fr = control.frequency_response(ss_k, omega, squeeze=False)
                store[k] = np.moveaxis(np.asarray(fr.complex), -1, 0)
            wall += c.wall
            cpu += c.cpu
        return wall, cpu

    rows = []
    reference = {}
    for rep in range(args.repeats):
        # a different subset of baseline samples per repeat, half before and half after
        subset = [(rep * nb + i) % args.samples for i in range(nb)]
        wall_a, cpu_a = run_baseline(subset[0::2], reference)
        fast = {w: fast_path(sys, values, omega, w) for w in configs}
        wall_b, cpu_b = run_baseline(subset[1::2], reference)
        base_wall, base_cpu = (wall_a + wall_b) * scale, (cpu_a + cpu_b) * scale
        ref = np.stack([reference[k] for k in subset])
        row = {"base_wall": base_wall, "base_cpu": base_cpu, "load": os.getloadavg()[0]}
        for w, (_, resp, c_subs, c_fr) in fast.items():
            row[w] = {
                "subs": c_subs.wall,
                "fr": c_fr.wall,
                "wall": c_subs.wall + c_fr.wall,
                "cpu": c_subs.cpu + c_fr.cpu,
                "rel": relative_difference(resp[subset], ref),
            }
        if len(configs) > 1:
            row["same"] = bool(np.array_equal(fast[configs[0]][1], fast[configs[-1]][1]))
        rows.append(row)
        models = fast[1][0]

    # which route answered: one more (untimed) freqresp, counting what the block + low-rank
    # route accepted; the other models took the modal route (one dgeev per model)
    n = models.nstates
    core, _, _ = lfr_frequency._integrator_tail(models.M[:, :n, :n])
    accepted = []
    route = lfr_frequency.coupled_response

    def counting_route(*route_args, **route_kwargs):
        ok = route(*route_args, **route_kwargs)
        accepted.append(int(np.sum(ok)))
        return ok

    lfr_frequency.coupled_response = counting_route
    try:
        models.freqresp(omega)
    finally:
        lfr_frequency.coupled_response = route
    taken = sum(accepted)
    # for scale: one dgeev (eigenvalues + right eigenvectors) of every model's state matrix, on
    # the core that the modal route diagonalizes (the rigid-body integrator tail is handled in
    # closed form)
    A = models.M[:, core[:, None], core[None, :]]
    with Clock() as c_eig:
        for a in A:
            lapack.dgeev(np.array(a, order="F"), compute_vl=0, overwrite_a=1)

    print(
        f"\n{args.samples} value sets x {omega.size} frequencies; baseline timed on {nb} samples "
        f"per repeat and scaled x{scale:.1f}"
    )
    header = f"{'repeat':>6s} {'load':>5s} {'baseline':>9s}"
    for w in configs:
        header += f" | {w}T usubs {w}T freqresp {w}T total {w}T ratio"
    print(header + "   [wall-clock seconds]")
    for i, row in enumerate(rows):
        line = f"{i:6d} {row['load']:5.1f} {row['base_wall']:9.2f}"
        for w in configs:
            r = row[w]
            line += (
                f" | {r['subs']:8.3f} {r['fr']:11.3f} {r['wall']:8.3f} "
                f"{row['base_wall'] / r['wall']:7.1f}x"
            )
        print(line)
    print("\nspeed-up over the per-sample loop (same run, wall-clock):")
    for w in configs:
        ratios = [row["base_wall"] / row[w]["wall"] for row in rows]
        print(f"  fast path, {w} worker thread(s): {spread(ratios)}")
    print("CPU time (process time, summed over threads) — less sensitive to the machine load:")
    base_cpu = np.median([row["base_cpu"] for row in rows])
    print(f"  baseline loop: median {base_cpu:.2f} s")
    for w in configs:
        cpu = [row[w]["cpu"] for row in rows]
        ratios = [row["base_cpu"] / row[w]["cpu"] for row in rows]
        print(f"  fast path, {w} thread(s): median {np.median(cpu):.3f} s, ratio {spread(ratios)}")
    print(
        f"routes: {taken} of {args.samples} models by the block + low-rank route "
        f"(no eigendecomposition), {args.samples - taken} by the modal route"
    )
    print(
        f"for scale: LAPACK dgeev of every model's {core.size}x{core.size} core state matrix "
        f"(of {n} states; what the modal route needs), 1 thread: {c_eig.wall:.3f} s wall, "
        f"{c_eig.cpu:.3f} s CPU; baseline / that = "
        f"{np.median([row['base_cpu'] for row in rows]) / c_eig.cpu:.1f}x CPU"
    )
    rel = max(row[w]["rel"] for row in rows for w in configs)
    print(
        f"agreement with python-control on the {nb * args.repeats} baseline samples: max relative "
        f"difference {rel:.2e}"
        + (
            f"; {configs[-1]}-thread result bitwise equal to 1-thread: "
            f"{all(row['same'] for row in rows)}"
            if len(configs) > 1
            else ""
        )
    )
    load1 = os.getloadavg()
    print(f"load average at end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
