r"""H-infinity norm of continuous-time state-space models (MATLAB ``hinfnorm``), batched.

The front end of the package's one H-infinity norm (:mod:`oos_drake.robust.peak_gain`): a
lower bound (``sigma_max`` at the pole frequencies; for larger models the peak of the modal
frequency grid, :func:`~.peak_gain.peak_gain`) is raised to the norm and certified by the
Boyd-Balakrishnan / Bruinsma-Steinbuch level sets (:func:`~.peak_gain.certify_peaks`, all
models together): for a level ``gamma`` above ``sigma_max(D)``,
``gamma`` is a singular value of ``G(j omega)`` exactly when the Hamiltonian

.. math::

    H(\gamma) = \begin{bmatrix} A + B R^{-1} D^T C & \gamma B R^{-1} B^T \\
        -\gamma C^T S^{-1} C & -(A + B R^{-1} D^T C)^T \end{bmatrix},\quad
    R = \gamma^2 I - D^T D,\ S = \gamma^2 I - D D^T

has the eigenvalue ``j omega``; at ``(1 + 2 tol)`` times the reported norm it has none, which
makes that level a certified upper bound (``benchmarks/bench_hinf_paths.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.blas import with_single_threaded_blas
from oos_drake.robust.peak_gain import certify_peaks, peak_gain, sigma_max_exact

#: Models with more states start the level sets from :func:`~.peak_gain.peak_gain`'s refined
#: grid peak (fewer Hamiltonian eigenvalue problems); smaller ones from the pole frequencies
#: (cheaper than the grid). Measured in ``benchmarks/bench_hinf_paths.py``.
GRID_START_STATES = 12


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
    """``(A, B, C, D)`` real arrays with matching batch dims from several inputs."""
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
        if np.iscomplexobj(X) and np.any(X.imag != 0):
            raise ValueError(f"hinfnorm: {name} is complex; only real models are supported")
    return tuple(np.asarray(X.real if np.iscomplexobj(X) else X, dtype=float) for X in (A, B, C, D))


def _lfr_matrices(sys):
    """State-space matrices of an LFR without uncertain blocks (possibly batched)."""
    ss = sys if hasattr(sys, "A") else sys.to_ss()
    return ss.A, ss.B, ss.C, ss.D


@with_single_threaded_blas
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
    Al, Bl, Cl, Dl = A[live], B[live], C[live], D[live]
    if n > GRID_START_STATES:  # start from the refined peak of the modal grid
        grid = peak_gain(Al, Bl, Cl, Dl)
        start, where = grid.gamma, grid.omega
    else:  # start from sigma_max at omega = 0 and the (lightly damped first) pole frequencies
        pl = poles[live]
        wp = np.abs(pl)
        order = np.argsort(-pl.real / np.maximum(wp, 1e-300), axis=1)[:, : min(n, 12)]
        wtest = np.concatenate(
            [
                np.zeros((live.size, 1)),
                np.take_along_axis(np.abs(pl.imag), order, 1),
                np.take_along_axis(wp, order, 1),
            ],
            axis=1,
        )
        s = sigma_max_exact(Al, Bl, Cl, Dl, wtest)
        best = np.argmax(s, axis=1)
        start, where = s[np.arange(live.size), best], wtest[np.arange(live.size), best]
    norm[live], peak[live], upper[live] = certify_peaks(
        Al, Bl, Cl, Dl, start, where, rtol=tol, max_iterations=max_iter
    )
    return _shape(batch, norm, peak, upper)


def _shape(batch, norm, peak, upper):
    def f(x):
        x = x.reshape(batch)
        return float(x) if x.ndim == 0 else x

    return HinfResult(f(norm), f(peak), f(upper))
