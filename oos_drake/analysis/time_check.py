r"""Linear time-domain check of the worst cases: APE and torque against the requirements.

At a critical configuration the uncertain closed loop is closed with a perturbation (real
blocks by value, each ``ultidyn`` block by a stable real-rational realization of its worst
complex value at the critical frequency,
:func:`oos_drake.robust.lfr_analysis.realize_complex_matrix`)
and simulated (exact zero-order-hold discretization) for a disturbance ``d_ext``: a unit step of
the normalized disturbance on the three axes (the torque ``W_n,ext`` of the design) plus a unit
sine at the critical frequency. Outputs are unweighted: ``phi = W_p e_p`` [rad] against the APE
requirement ``W_p`` and ``u = e_u / W_u`` [N m] against the torque bound ``1 / W_u``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import scipy.signal

from oos_drake.lfr import LFR

#: Columns of the time-domain summary.
TIME_COLUMNS = [
    "case",
    "study",
    "model",
    "time [s]",
    "scale [-]",
    "frequency [Hz]",
    "ape max [rad]",
    "ape requirement [rad]",
    "torque max [N m]",
    "torque requirement [N m]",
    "stable",
]


def simulate(closed: LFR, frequency_hz: float, *, duration: float = 600.0, dt: float = 0.05):
    """Response of ``e`` to ``d_ext`` = unit step + unit sine at ``frequency_hz`` (3 axes).

    Returns
    -------
    t : (K,) ndarray [s]
    e : (K, 6) ndarray (weighted errors)
    stable : bool
    """
    n = closed.nstates
    M = np.real(np.asarray(closed.M))
    A, B, C, D = M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]
    stable = bool(n == 0 or np.max(np.linalg.eigvals(A).real) < 1e-9)
    t = np.arange(0.0, duration + dt / 2, dt)
    d = np.zeros((t.size, B.shape[1]))
    d[:, :3] = 1.0 + np.sin(2 * np.pi * frequency_hz * t)[:, None]
    Ad, Bd, *_ = scipy.signal.cont2discrete((A, B, C, D), dt, method="zoh")  # exact ZOH
    x = np.zeros(n)
    e = np.empty((t.size, C.shape[0]))
    for k in range(t.size):
        e[k] = C @ x + D @ d[k]
        x = Ad @ x + Bd @ d[k]
        if not np.all(np.isfinite(x)) or np.abs(x).max() > 1e12:
            e[k + 1 :] = np.nan
            break
    return t, e, stable


def check_case(
    sys: LFR,
    normalized: dict,
    omega: float,
    spec,
    *,
    case: str,
    study: str,
    model: int,
    time: float,
    scale: float,
    duration: float = 600.0,
    dt: float = 0.05,
):
    """Simulate one perturbed closed loop and summarize APE and torque (a table row + signals)."""
    from oos_drake.analysis.performance_twin import perturbed_loop

    closed = perturbed_loop(sys, normalized, omega)
    f_hz = omega / (2 * np.pi) if np.isfinite(omega) and omega > 0 else 0.01
    t, e, stable = simulate(closed, f_hz, duration=duration, dt=dt)
    phi = e[:, :3] * spec.pointing_requirement
    u = e[:, 3:] / spec.control_weight
    row = {
        "case": case,
        "study": study,
        "model": int(model),
        "time [s]": float(time),
        "scale [-]": float(scale),
        "frequency [Hz]": float(f_hz),
        "ape max [rad]": float(np.nanmax(np.abs(phi))) if np.isfinite(phi).any() else np.inf,
        "ape requirement [rad]": spec.pointing_requirement,
        "torque max [N m]": float(np.nanmax(np.abs(u))) if np.isfinite(u).any() else np.inf,
        "torque requirement [N m]": 1.0 / spec.control_weight,
        "stable": stable,
    }
    signals = pd.DataFrame(
        {
            "case": case,
            "t [s]": t,
            **{f"phi_{a} [rad]": phi[:, i] for i, a in enumerate("xyz")},
            **{f"u_{a} [N m]": u[:, i] for i, a in enumerate("xyz")},
        }
    )
    return row, signals
