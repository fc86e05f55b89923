r"""H-infinity norm of continuous-time state-space models, batched.

Boyd-Balakrishnan / Bruinsma-Steinbuch level-set iteration: for a level ``gamma`` above
``sigma_max(D)``, ``gamma`` is a singular value of ``G(j omega)`` exactly when the Hamiltonian

.. math::

    H(\gamma) = \begin{bmatrix} A + B R^{-1} D^T C & \gamma B R^{-1} B^T \\
        -\gamma C^T S^{-1} C & -(A + B R^{-1} D^T C)^T \end{bmatrix},\quad
    R = \gamma^2 I - D^T D,\ S = \gamma^2 I - D D^T

(scaled form) has the eigenvalue ``j omega``. Starting from a lower bound (``sigma_max`` at
``omega = 0``, ``infinity`` and the lightly damped pole frequencies), each step takes the
imaginary-axis eigenvalues of ``H((1 + 2 tol) gamma_lb)``, evaluates ``sigma_max`` at the
midpoints of the intervals they bound, and raises ``gamma_lb``; when ``H`` has no imaginary
eigenvalue the level is an upper bound. Convergence is quadratic. All systems of a batch
advance together (stacked eigenvalue problems).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HinfResult:
    """H-infinity norm of a model or a batch of models.

    Attributes
    ----------
    norm : float or numpy.ndarray
        ``max_omega sigma_max(G(j omega))`` (``inf`` for unstable models or poles on the
        imaginary axis), batch shape.
    peak_frequency : float or numpy.ndarray
        Frequency [rad/s] where the peak is attained (``inf`` when the peak is at infinite
        frequency, ``nan`` for unstable models).
    upper : float or numpy.ndarray
        Certified upper bound (level with no imaginary Hamiltonian eigenvalue).
    """

    norm: float | np.ndarray
    peak_frequency: float | np.ndarray
    upper: float | np.ndarray


def _as_matrices(sys):
    """``(A, B, C, D)`` float/complex arrays with matching batch dims from several inputs."""
    if isinstance(sys, tuple | list) and len(sys) == 4:
        A, B, C, D = (np.asarray(x) for x in sys)
    elif hasattr(sys, "A") and hasattr(sys, "B") and hasattr(sys, "dt"):
        dt = getattr(sys, "dt", 0)
        if dt not in (0, None):
            raise ValueError(f"hinfnorm: only continuous-time models are supported, got dt={dt}")
        A, B, C, D = (np.asarray(x) for x in (sys.A, sys.B, sys.C, sys.D))
    elif hasattr(sys, "to_ss") or hasattr(sys, "nominal"):
        if getattr(sys, "occurrences", None):
            raise ValueError(
                "hinfnorm: the LFR still has uncertain blocks; use wcgain or usubs first"
            )
        A, B, C, D = (np.asarray(x) for x in _lfr_matrices(sys))
    else:
        raise ValueError(
            "hinfnorm: expected (A, B, C, D), a control.StateSpace or an LFR, "
            f"got {type(sys).__name__}"
        )
    if A.ndim < 2 or A.shape[-1] != A.shape[-2]:
        raise ValueError(f"hinfnorm: A must be square (..., n, n), got shape {A.shape}")
    n = A.shape[-1]
    if B.shape[-2] != n or C.shape[-1] != n or D.shape[-2:] != (C.shape[-2], B.shape[-1]):
        raise ValueError(
            f"hinfnorm: inconsistent shapes A{A.shape} B{B.shape} C{C.shape} D{D.shape}"
        )
    for name, X in zip("ABCD", (A, B, C, D), strict=True):
        if not np.all(np.isfinite(X)):
            raise ValueError(f"hinfnorm: {name} has non-finite entries")
    return A, B, C, D


def _lfr_matrices(sys):
    """State-space matrices of an LFR without uncertain blocks (possibly batched)."""
    for attr in ("A", "a"):
        if hasattr(sys, attr):
            return sys.A, sys.B, sys.C, sys.D
    ss = sys.to_ss()
    return ss.A, ss.B, ss.C, ss.D


def sigma_max_at(A, B, C, D, omega):
    """``sigma_max(C (j omega I - A)^{-1} B + D)`` for batched systems ``(B, ...)`` and ``(B, F)``.

    Parameters
    ----------
    A, B, C, D : arrays with a leading batch axis
    omega : array (batch, F) [rad/s]

    Returns
    -------
    numpy.ndarray (batch, F)
    """
    n = A.shape[-1]
    eye = np.eye(n)
    jw = 1j * omega[..., None, None]
    X = np.linalg.solve(
        jw * eye - A[:, None], np.broadcast_to(B[:, None], omega.shape + B.shape[-2:])
    )
    G = C[:, None] @ X + D[:, None]
    return np.linalg.norm(G, ord=2, axis=(-2, -1))


def hinfnorm(sys, *, tol: float = 1e-8, max_iter: int = 50) -> HinfResult:
    """H-infinity norm (peak gain over frequency) of continuous-time models.

    Parameters
    ----------
    sys : tuple or control.StateSpace or LFR
        ``(A, B, C, D)`` with optional leading batch dims (``A (..., n, n)``, ``B (..., n, m)``,
        ``C (..., p, n)``, ``D (..., p, m)``), a ``control.StateSpace``, or an LFR without
        uncertain blocks.
    tol : float
        Relative accuracy of the norm.
    max_iter : int
        Maximum level-set iterations.

    Returns
    -------
    HinfResult

    Raises
    ------
    ValueError
        For discrete-time models, inconsistent shapes or non-finite matrices.

    Examples
    --------
    >>> import numpy as np
    >>> res = hinfnorm((np.array([[-1.0]]), np.array([[1.0]]), np.array([[2.0]]), np.zeros((1, 1))))
    >>> round(res.norm, 6)
    2.0
    """
    A, B, C, D = _as_matrices(sys)
    batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2], C.shape[:-2], D.shape[:-2])
    n, m, p = A.shape[-1], B.shape[-1], C.shape[-2]
    A = np.broadcast_to(A, batch + (n, n)).reshape(-1, n, n)
    B = np.broadcast_to(B, batch + (n, m)).reshape(-1, n, m)
    C = np.broadcast_to(C, batch + (p, n)).reshape(-1, p, n)
    D = np.broadcast_to(D, batch + (p, m)).reshape(-1, p, m)
    nb = A.shape[0]
    norm = np.zeros(nb)
    peak = np.full(nb, np.inf)
    upper = np.zeros(nb)
    sigD = np.linalg.norm(D, ord=2, axis=(-2, -1)) if min(p, m) > 0 else np.zeros(nb)
    if n == 0 or min(p, m) == 0:
        norm[:] = sigD
        upper[:] = sigD
        return _shape(batch, norm, peak, upper)
    poles = np.linalg.eigvals(A)
    unstable = np.any(poles.real >= -1e-12 * np.maximum(1.0, np.abs(poles)), axis=1)
    norm[unstable], peak[unstable], upper[unstable] = np.inf, np.nan, np.inf
    live = np.flatnonzero(~unstable)
    if live.size == 0:
        return _shape(batch, norm, peak, upper)
    # initial lower bound: omega = 0, infinity and the pole frequencies (lightly damped first)
    pl = poles[live]
    wp = np.abs(pl)
    damping = -pl.real / np.maximum(wp, 1e-300)
    order = np.argsort(damping, axis=1)[:, : min(n, 12)]
    wtest = np.concatenate(
        [
            np.zeros((live.size, 1)),
            np.take_along_axis(np.abs(pl.imag), order, 1),
            np.take_along_axis(wp, order, 1),
        ],
        axis=1,
    )
    Al, Bl, Cl, Dl = A[live], B[live], C[live], D[live]
    s = sigma_max_at(Al, Bl, Cl, Dl, wtest)
    best = np.argmax(s, axis=1)
    glb = s[np.arange(live.size), best]
    wpk = wtest[np.arange(live.size), best]
    at_inf = sigD[live] >= glb
    glb = np.where(at_inf, sigD[live], glb)
    wpk = np.where(at_inf, np.inf, wpk)
    gub = np.full(live.size, np.inf)
    active = glb > 0
    gub[~active] = 0.0
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        gamma = (1 + 2 * tol) * glb[idx]
        Ham = _hamiltonian(Al[idx], Bl[idx], Cl[idx], Dl[idx], gamma)
        ev = np.linalg.eigvals(Ham)
        scale = np.maximum(np.max(np.abs(ev), axis=1, keepdims=True), 1e-300)
        imag_axis = np.abs(ev.real) <= 1e-7 * scale
        for j, i in enumerate(idx):
            w = np.sort(np.abs(ev[j].imag[imag_axis[j]]))
            w = np.unique(np.round(w / scale[j, 0], 12)) * scale[j, 0] if w.size else w
            if w.size == 0:
                gub[i] = gamma[j]
                active[i] = False
                continue
            mids = 0.5 * (w[:-1] + w[1:]) if w.size > 1 else w
            mids = np.concatenate([mids, w])
            sm = sigma_max_at(
                Al[i : i + 1], Bl[i : i + 1], Cl[i : i + 1], Dl[i : i + 1], mids[None]
            )[0]
            k = int(np.argmax(sm))
            if sm[k] <= glb[i] * (1 + tol):
                gub[i] = gamma[j]
                active[i] = False
                continue
            glb[i], wpk[i] = sm[k], mids[k]
    gub = np.where(np.isinf(gub), glb * (1 + 2 * tol), gub)
    norm[live], peak[live], upper[live] = glb, wpk, gub
    return _shape(batch, norm, peak, upper)


def _hamiltonian(A, B, C, D, gamma):
    m = B.shape[-1]
    p = C.shape[-2]
    g2 = (gamma**2)[:, None, None]
    DT = np.swapaxes(D, -1, -2)
    R = g2 * np.eye(m) - DT @ D
    S = g2 * np.eye(p) - D @ DT
    Ri = np.linalg.inv(R)
    Si = np.linalg.inv(S)
    BT = np.swapaxes(B, -1, -2)
    CT = np.swapaxes(C, -1, -2)
    F = A + B @ Ri @ DT @ C
    g = gamma[:, None, None]
    top = np.concatenate([F, g * (B @ Ri @ BT)], axis=-1)
    bot = np.concatenate([-g * (CT @ Si @ C), -np.swapaxes(F, -1, -2)], axis=-1)
    return np.concatenate([top, bot], axis=-2)


def _shape(batch, norm, peak, upper):
    def f(x):
        x = x.reshape(batch)
        return float(x) if x.ndim == 0 else x

    return HinfResult(f(norm), f(peak), f(upper))
