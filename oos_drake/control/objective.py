"""Multi-model H-infinity objective ``gamma(K) = max_i ||F_l(P_i, K)||_inf`` and subgradients.

For a static gain ``K`` and ``D22 = 0`` the closed loop is
``T_i(s) = P11 + P12 K (I - P22 K)^-1 P21`` and its differential is
``dT = G12 dK G21`` with ``G12 = C_cl (sI - A_cl)^-1 B2 + D12``,
``G21 = C2 (sI - A_cl)^-1 B_cl + D21``. If ``sigma_max(T_i(j w0)) = gamma`` is simple with
singular vectors ``u, v`` at the peak frequency ``w0``, Apkarian-Noll's (sub)gradient is

.. math::

    \\frac{\\partial \\gamma}{\\partial K} =
    \\mathrm{Re}\\left(G_{21}(j w_0)\\, v\\, u^H G_{12}(j w_0)\\right)^T .

The objective is evaluated for the whole model array at once (:func:`peak_gain`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.blas import with_single_threaded_blas
from oos_drake.control.interconnection import WeightedInterconnection
from oos_drake.control.loop_response import LoopSigma
from oos_drake.robust.peak_gain import ModalResponse, PeakGain, peak_gain


@dataclass(frozen=True)
class Evaluation:
    """Objective value, subgradient and per-model peak gains at one gain ``K``.

    Attributes
    ----------
    gamma : float
        ``max_i ||M_i||_inf`` (``inf`` if a closed loop is unstable).
    gradient : numpy.ndarray, shape (3, 6)
        Subgradient of ``gamma`` w.r.t. ``K`` (of the spectral abscissa when unstable).
    peaks : PeakGain
        Per-model peak gains and frequencies.
    """

    gamma: float
    gradient: np.ndarray
    peaks: PeakGain


def loop_sigma(interconnection: WeightedInterconnection, K):
    """The fast sampler of the closed-loop gains at ``K`` (None when unavailable).

    See :mod:`oos_drake.control.loop_response`: the plant's modal form replaces the per-gain
    closed-loop eigenvectors.
    """
    loop = interconnection.loop
    return None if loop is None else LoopSigma(loop, K)


@with_single_threaded_blas
def peak_gradients(
    interconnection: WeightedInterconnection, K, index, omega, which=None, *, points=None
):
    """Values and gradients of ``sigma_max(M_i(j w))`` w.r.t. ``K`` at given (model, frequency).

    Parameters
    ----------
    interconnection : WeightedInterconnection
        Batched over models.
    K : array_like, shape (3, 6)
    index : array_like of int, shape (k,)
        Model indices.
    omega : array_like, shape (k,)
        Frequencies [rad/s].
    which : array_like of int, shape (k,), optional
        Which singular value (0 = largest, default); the others give the extra pieces of a
        multiple largest singular value.
    points : callable, optional
        ``omega -> p``: the complex points where the transfer ``C (p I - A)^-1 B + D`` is
        evaluated (default ``p = j omega``; for a discrete-time loop whose peaks were found on
        its bilinear image, ``p = (1 + j omega) / (1 - j omega)``, i.e. ``z``). Forces the LU
        path.

    Returns
    -------
    tuple
        ``(sigma (k,), gradient (k, 3, 6))``: from the plant's modal form when the
        interconnection has one (:meth:`LoopResponse.gain_sensitivity`), else by LU solves on
        the closed loop.
    """
    index = np.atleast_1d(np.asarray(index, dtype=int))
    which = np.zeros(index.size, dtype=int) if which is None else np.asarray(which, dtype=int)
    return _gradients(*_sensitivities(interconnection, K, index, omega, points), which)


def _sensitivities(interconnection, K, index, omega, points=None):
    """``(T, G12, G21)`` at (model ``index``, frequency ``omega``): the closed loop and the
    pieces of its differential ``dT = G12 dK G21`` (see :func:`peak_gradients`)."""
    index = np.atleast_1d(np.asarray(index, dtype=int))
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    K = np.asarray(K, dtype=float)
    loop = interconnection.loop
    if loop is not None and points is None:
        return loop.gain_sensitivity(K, omega, index)
    A, B1, B2, C1, C2, D11, D12, D21 = (M[index] for M in interconnection.partitions())
    A_cl = A + B2 @ K @ C2
    B_cl = B1 + B2 @ K @ D21
    C_cl = C1 + D12 @ K @ C2
    D_cl = D11 + D12 @ K @ D21
    n = A.shape[-1]
    rhs = np.concatenate([B_cl, B2], axis=-1).astype(complex)
    p = 1j * omega if points is None else points(omega)
    X = np.linalg.solve(p[:, None, None] * np.eye(n) - A_cl, rhs)
    nd = B1.shape[-1]
    T = C_cl @ X[..., :nd] + D_cl
    G12 = C_cl @ X[..., nd:] + D12
    G21 = C2 @ X[..., :nd] + D21
    return T, G12, G21


def _gradients(T, G12, G21, which, svd=None):
    """Singular value ``which`` of ``T`` and its gradient ``Re(G21 v u^H G12)^T``
    (``svd``: ``numpy.linalg.svd(T)`` when already computed)."""
    U, S, Vh = np.linalg.svd(T) if svd is None else svd
    rows = np.arange(T.shape[0])
    u, v = U[rows, :, which], np.conj(Vh[rows, which, :])
    M = (G21 @ v[..., None]) @ (np.conj(u)[..., None, :] @ G12)
    return S[rows, which], np.swapaxes(np.real(M), -1, -2)


@dataclass(frozen=True)
class ActiveSet:
    """The nearly active peaks at one gain: the local model of ``gamma`` used by the bundle step.

    Attributes
    ----------
    gamma : float
        Objective value (``inf`` when a loop is unstable).
    values : numpy.ndarray, shape (k,)
        Peak values within ``eps`` of ``gamma`` (the first is the maximum).
    gradients : numpy.ndarray, shape (k, 3, 6)
        Their gradients w.r.t. ``K``.
    models, omegas : numpy.ndarray, shape (k,)
        Model index and frequency [rad/s] of each peak.
    peaks : PeakGain
    """

    gamma: float
    values: np.ndarray
    gradients: np.ndarray
    models: np.ndarray
    omegas: np.ndarray
    peaks: PeakGain
    which: np.ndarray | None = None


def active_set(
    interconnection: WeightedInterconnection,
    K,
    *,
    eps: float = 0.05,
    max_peaks: int = 24,
    focus: float = 0.2,
    workers: int = 1,
    points=None,
    eigen=None,
    closed=None,
) -> ActiveSet:
    """Evaluate ``gamma(K)`` and collect every local peak within ``eps`` (relative) of it.

    ``workers``: threads of the eigendecompositions (see :func:`peak_gain`); ``points``: see
    :func:`peak_gradients` (the peaks are searched on ``interconnection.close(K)``);
    ``eigen``: ``(lambda, V, V^-1)`` of the closed loop's ``A`` when already computed (see
    :class:`~oos_drake.robust.peak_gain.ModalResponse`); ``closed``: ``interconnection.close(K)``
    when already formed.
    """
    M = interconnection.close(K) if closed is None else closed
    peaks = peak_gain(
        M.A,
        M.B,
        M.C,
        M.D,
        focus=max(focus, eps),
        workers=workers,
        evaluator=loop_sigma(interconnection, K),
        modal=None if eigen is None else ModalResponse(M.A, M.B, M.C, M.D, eigen=eigen),
    )
    worst = peaks.worst
    if not np.isfinite(peaks.gamma[worst]):
        k = int(np.argmax(peaks.spectral_abscissa))
        g = abscissa_gradient(interconnection, K, k)
        return ActiveSet(
            np.inf,
            np.array([peaks.spectral_abscissa[k]]),
            g[None],
            np.array([k]),
            np.array([np.nan]),
            peaks,
        )
    gamma = float(peaks.gamma[worst])
    sig = np.where(np.isnan(peaks.peak_sigma), -np.inf, peaks.peak_sigma)
    rows, cols = np.nonzero(sig >= (1.0 - eps) * gamma)
    order = np.argsort(-sig[rows, cols])[: 4 * max_peaks]
    models = np.concatenate([[worst], rows[order]])
    omegas = np.concatenate([[peaks.omega[worst]], peaks.peak_omega[rows[order], cols[order]]])
    # drop repeats of the maximum (same model, same frequency)
    keep = np.ones(models.size, dtype=bool)
    keep[1:] = ~((models[1:] == worst) & np.isclose(omegas[1:], omegas[0], rtol=1e-6, atol=1e-12))
    models, omegas = models[keep], omegas[keep]
    # second singular values close to the first: a multiple sigma_max is nonsmooth even at a
    # fixed frequency, its subdifferential is spanned by the pieces of each singular pair
    # (one closed-loop solve per peak: the second singular values and every gradient come
    # from the same T, G12, G21 and the same SVD)
    T, G12, G21 = _sensitivities(interconnection, K, models, omegas, points)
    svd = np.linalg.svd(T)
    if min(M.B.shape[-1], M.C.shape[-2]) > 1:
        multiple = svd[1][:, 1] >= (1.0 - eps) * gamma
    else:  # one singular value only
        multiple = np.zeros(models.size, dtype=bool)
    rows = np.concatenate([np.arange(models.size), np.flatnonzero(multiple)])
    models, omegas = models[rows], omegas[rows]
    which = np.concatenate([np.zeros(keep.sum(), int), np.ones(int(multiple.sum()), int)])
    svd = tuple(part[rows] for part in svd)
    values, grads = _gradients(T[rows], G12[rows], G21[rows], which, svd)
    values[0] = gamma
    # configurations often share a peak (e.g. the DC disturbance rejection does not depend on
    # the inertia): keep one copy of each (value, gradient) so the cap keeps distinct pieces
    scale = max(np.abs(grads).max(), 1e-300)
    signature = np.round(
        np.concatenate([values[:, None] / gamma, grads.reshape(values.size, -1) / scale], axis=1),
        8,
    )
    _, first = np.unique(signature, axis=0, return_index=True)
    first = np.sort(first)[:max_peaks]  # keeps index 0 (the maximum) and the value order
    return ActiveSet(
        gamma, values[first], grads[first], models[first], omegas[first], peaks, which[first]
    )


def abscissa_gradient(interconnection: WeightedInterconnection, K, index: int):
    """Gradient of the spectral abscissa of model ``index`` w.r.t. ``K`` (simple eigenvalue)."""
    A, _, B2, _, C2, *_ = (M[index] for M in interconnection.partitions())
    A_cl = A + B2 @ np.asarray(K, dtype=float) @ C2
    lam, V = np.linalg.eig(A_cl)
    k = int(np.argmax(lam.real))
    W = np.linalg.inv(V)
    x, y = V[:, k], W[k, :]  # right and left eigenvectors, y x = 1
    # d lambda = y B2 dK C2 x
    return np.real(np.outer(B2.T @ y, C2 @ x).T).T


def evaluate(
    interconnection: WeightedInterconnection, K, *, focus=0.2, **peak_options
) -> Evaluation:
    """Evaluate ``gamma(K)`` over the model array and a subgradient at the worst model.

    ``focus`` (see :func:`peak_gain`) refines only the models near the maximum: ``gamma`` is
    exact, the per-model values of the others are sampled lower bounds. ``focus=None`` refines all.
    """
    M = interconnection.close(K)
    peak_options.setdefault("evaluator", loop_sigma(interconnection, K))
    peaks = peak_gain(M.A, M.B, M.C, M.D, focus=focus, **peak_options)
    worst = peaks.worst
    if np.isfinite(peaks.gamma[worst]):
        grad = peak_gradients(interconnection, K, [worst], [float(peaks.omega[worst])])[1][0]
        return Evaluation(float(peaks.gamma[worst]), grad, peaks)
    k = int(np.argmax(peaks.spectral_abscissa))
    return Evaluation(np.inf, abscissa_gradient(interconnection, K, k), peaks)
