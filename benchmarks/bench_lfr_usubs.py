"""Benchmark: vectorized ``usubs`` + batched ``freqresp`` vs a per-sample python-control loop.

The model is a flexible spacecraft built with the LFR algebra only: a rigid hub (3 axes, uncertain
principal inertias) carrying three appendages, each rotated about the hub z axis by a scheduled
angle ``theta_i`` (``tau_i = tan(theta_i / 4)``, Cayley form: 16 occurrences per appendage) and
carrying 9 flexible modes with uncertain frequency (3 occurrences), damping (asymmetric range:
bilinear, 1 occurrence) and participation gain (2 occurrences). Inputs: 3 hub torques [N m];
outputs: 3 hub attitude angles [rad]. That is 60 states and about 200 Delta occurrences.

Fast path: ``usubs`` with arrays of N value sets (one model array, no Python loop per model) and
``freqresp`` of the array (no Python loop per frequency). Baseline: for each value set, ``usubs``
with scalars, ``to_ss()`` and ``control.frequency_response``. The baseline is timed on a subset
of the samples (half before, half after the fast path, since the machine is shared) and scaled
linearly to N; it is a loop of identical iterations. The script also times numpy's ``eig`` of every
model's ``A`` alone: the batched response needs one eigendecomposition per model, so that line is
a floor for the fast path.

Run: ``python benchmarks/bench_lfr_usubs.py [--samples 1000] [--baseline-samples 40]``
"""

from __future__ import annotations

import os

# One BLAS thread: the machine is shared, and OpenBLAS threads spinning on small matrices under
# contention slow both paths down erratically. Set before numpy is imported; both paths use it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import control  # noqa: E402
import numpy as np  # noqa: E402

from oos_drake.lfr import append, feedback, inv, ureal, usubs  # noqa: E402


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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--baseline-samples", type=int, default=40)
    parser.add_argument("--frequencies", type=int, default=500)
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    sys = flexible_spacecraft()
    t_build = time.perf_counter() - t0
    n_occ = sum(sys.occurrences.values())
    print(
        f"model: {sys.nstates} states, {sys.noutputs}x{sys.ninputs} I/O, "
        f"{len(sys.occurrences)} blocks, {n_occ} Delta occurrences (built in {t_build:.2f} s)"
    )

    rng = np.random.default_rng(2026)
    specs = sys.uncertainty
    values = {name: spec.sample(rng, args.samples) for name, spec in specs.items()}
    omega = np.logspace(-2, 2, args.frequencies)

    nb = min(args.baseline_samples, args.samples)
    first = list(range(0, nb, 2))
    second = list(range(1, nb, 2))
    baseline = {}
    loop_times = {"usubs+to_ss": 0.0, "frequency_response": 0.0}

    def run_baseline(indices):
        for k in indices:
            t0 = time.perf_counter()
            ss_k = usubs(sys, {name: v[k] for name, v in values.items()}).to_ss()
            t1 = time.perf_counter()
            fr = control.frequency_response(ss_k, omega, squeeze=False)
            baseline[k] = np.moveaxis(np.asarray(fr.complex), -1, 0)
            t2 = time.perf_counter()
            loop_times["usubs+to_ss"] += t1 - t0
            loop_times["frequency_response"] += t2 - t1

    # the machine is shared: time half the baseline before and half after the vectorized path
    run_baseline(first)
    t0 = time.perf_counter()
    models = usubs(sys, values)
    t_subs = time.perf_counter() - t0
    t0 = time.perf_counter()
    resp = models.freqresp(omega)
    t_fr = time.perf_counter() - t0
    t_fast = t_subs + t_fr
    run_baseline(second)
    t_base_subset = sum(loop_times.values())
    scale = args.samples / nb
    t_base = t_base_subset * scale

    # reference floor: one LAPACK eigendecomposition of A per model (what freqresp must do)
    n = models.nstates
    t0 = time.perf_counter()
    np.linalg.eig(models.M[:, :n, :n])
    t_eig = time.perf_counter() - t0

    ref_resp = np.stack([baseline[k] for k in range(nb)])
    err = np.linalg.norm((resp[:nb] - ref_resp).reshape(nb, omega.size, -1), axis=-1)
    ref = np.linalg.norm(ref_resp.reshape(nb, omega.size, -1), axis=-1)
    rel = float(np.max(err / ref))

    print(f"{args.samples} value sets x {omega.size} frequencies")
    print(f"{'path':46s} {'time [s]':>10s}")
    print(f"{'vectorized usubs (one model array)':46s} {t_subs:10.3f}")
    print(f"{'batched freqresp of the model array':46s} {t_fr:10.3f}")
    print(f"{'vectorized total':46s} {t_fast:10.3f}")
    print(f"{'  (floor: numpy eig of every A alone)':46s} {t_eig:10.3f}")
    print(
        f"{'loop: usubs + to_ss + frequency_response':46s} {t_base:10.3f}  "
        f"(timed on {nb} samples, {t_base_subset:.3f} s, scaled x{scale:.1f})"
    )
    print(f"{'  of which usubs + to_ss':46s} {loop_times['usubs+to_ss'] * scale:10.3f}")
    print(
        f"{'  of which control.frequency_response':46s} "
        f"{loop_times['frequency_response'] * scale:10.3f}"
    )
    print(
        f"speed-up: {t_base / t_fast:.1f}x   max relative difference on the {nb} common "
        f"samples: {rel:.2e}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
