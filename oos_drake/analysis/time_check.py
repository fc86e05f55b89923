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

from oos_drake.lfr import LFR, lft, usubs

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


def close_with_perturbation(sys: LFR, normalized: dict, omega: float) -> LFR:
    """Certain closed loop ``F_u(M, Delta)`` for normalized block values.

    Parameters
    ----------
    sys : LFR
        One uncertain model.
    normalized : dict
        Block name -> normalized value: float for ``ureal``, complex ``(p, q)`` matrix (its value
        at ``omega``) for ``ultidyn``. Blocks not given stay nominal.
    omega : float
        Frequency [rad/s] the ultidyn values refer to.

    Returns
    -------
    LFR
        Without uncertain blocks (real-rational: ultidyn blocks are realized by stable all-pass
        factors of the same norm).
    """
    from oos_drake.robust.lfr_analysis import realize_complex_matrix

    kinds = {name: spec.kind for name, spec in sys.uncertainty.items()}
    unknown = [k for k in normalized if k not in kinds]
    if unknown:
        raise ValueError(f"close_with_perturbation: unknown block(s) {unknown}")
    reals = {
        k: float(np.real(normalized.get(k, 0.0))) for k, kind in kinds.items() if kind == "ureal"
    }
    out = usubs(sys, reals, normalized=True) if reals else sys
    # blocks left: ultidyn; those not given are nominal (zero)
    left = [e for e in out.block_entries]
    if not left:
        return out
    A, Bw, Bu = np.asarray(out.A), np.asarray(out.Bw), np.asarray(out.Bu)
    Cz, Cy = np.asarray(out.Cz), np.asarray(out.Cy)
    D = np.block(
        [[np.asarray(out.Dzw), np.asarray(out.Dzu)], [np.asarray(out.Dyw), np.asarray(out.Dyu)]]
    )
    open_sys = LFR.from_ss(A, np.hstack([Bw, Bu]), np.vstack([Cz, Cy]), D)
    import control

    parts = []
    for entry in left:
        spec = entry.spec
        p, q = spec.shape
        value = normalized.get(spec.name)
        if value is None:
            parts.append(control.ss([], [], [], np.zeros((p, q))))
        else:
            value = spec.bound * np.asarray(value, complex).reshape(p, q)
            parts.append(realize_complex_matrix(value, omega))
    delta_sys = control.append(*parts) if len(parts) > 1 else parts[0]
    nw, nz = out.nw, out.nz
    return lft(delta_sys, open_sys, nw, nz).with_names(
        inputs=sys.input_names, outputs=sys.output_names
    )


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
    closed = close_with_perturbation(sys, normalized, omega)
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
