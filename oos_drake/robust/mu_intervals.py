r"""Frequency intervals on which fixed D-G scalings prove a mu bound, and covers of the axis.

The D-G upper bound of :func:`~oos_drake.robust.mussv` at one frequency is the LMI
(:attr:`MuResult.G <oos_drake.robust.MuResult>` convention)

.. math::

    \Phi(\omega) = M^* D_l M + j (G M - M^* G^*) - \beta^2 D_r
        = \begin{bmatrix} M \\ I \end{bmatrix}^*
          \begin{bmatrix} D_l & -j G^* \\ j G & -\beta^2 D_r \end{bmatrix}
          \begin{bmatrix} M \\ I \end{bmatrix} \preceq 0,
    \qquad M = M(j\omega) = C (j\omega I - A)^{-1} B + D,

which proves ``mu(M(j omega)) <= beta``. With ``D_l, D_r, G, beta`` fixed it is a
frequency-domain inequality in ``M(j omega)``: ``lambda_max(Phi)`` is continuous in ``omega``
and changes sign only where ``Phi(j omega)`` is singular, i.e. (``A`` without imaginary
eigenvalues, ``Phi(inf) = R`` nonsingular) where the Hamiltonian

.. math::

    H = \begin{bmatrix} A - B R^{-1} S^* & -B R^{-1} B^* \\
        -Q + S R^{-1} S^* & -A^* + S R^{-1} B^* \end{bmatrix},\quad
    Q = C^* \Pi_{11} C,\ S = C^* (\Pi_{11} D + \Pi_{12}),\
    R = \begin{bmatrix} D \\ I \end{bmatrix}^* \Pi \begin{bmatrix} D \\ I \end{bmatrix}

has the eigenvalue ``j omega`` (the construction of the Hamiltonian test of an H-infinity norm,
:mod:`oos_drake.robust.hinf`). :func:`dg_interval` takes those eigenvalues (generously: every
eigenvalue within ``1e-6`` relative of the axis; spurious ones only cost a check), evaluates
``lambda_max(Phi)`` once inside each piece they cut the axis into, and returns the largest
interval around ``omega_0`` whose pieces are all negative: exact up to the eigenvalue
round-off, no sampling. It works after the congruence with the Cholesky factors of ``D_l`` and
``D_r`` (as :func:`~oos_drake.robust.mu_upper.lmi_residual`), which keeps the inertia and the
accuracy when the scalings are ill-conditioned.

Discrete time: ``M(e^{j omega T})`` is the continuous-time response, at ``nu = tan(omega T / 2)``,
of the Cayley transform of the realization (``z = (1 + s) / (1 - s)``), so the same test covers
the unit circle ``0 <= omega <= pi / T``.

:func:`cover_axis` covers ``[0, inf)`` (or ``[0, pi / T]``) with such intervals (Roos and
Biannic, ACC 2010; SMAC): it solves the bound at seed frequencies, proves every point at the
running level ``L = max(floor, (1 + slack) beta_i so far)`` (a higher level only widens an
interval: ``-L^2 D_r`` decreases; an interval proved at a lower level stays valid when ``L``
grows), and adds points at the edges and in the middle of every gap until the intervals cover
the axis. The guaranteed bound is the largest level; the :class:`AxisCertificate` keeps the
points, their scalings, levels and intervals, and :meth:`AxisCertificate.check` proves them again.
A cover that cannot close says so: poles of ``M`` on the axis (``M`` unbounded: the gap around
them is never filled), an infinite level, or ``max_rounds`` rounds without a proof in a gap (with
what stopped the points there, e.g. a ``Phi(inf)`` too ill-conditioned for the Hamiltonian
test) end with ``covered`` False, the unproved ``gaps``, a one-line ``reason`` and the bound
:attr:`AxisCertificate.upper_on_cover` that holds everywhere else.

The cover tests lazily (``cover_axis(lazy=True)``, the default): a point that lies in no gap
of the intervals proved so far is not tested (its interval stays NaN unless a gap is left
next to it). Every interval of the certificate is still one of :func:`dg_interval`.

A gap is filled by solving points at its edges (moved into the gap by a fraction of the
neighbouring intervals' width, :data:`EDGE_SHIFT`) and in its middle. ``cover_axis(bands=True)``
first tries, in the narrow gaps, one scaling chosen for the whole gap (:func:`band_scalings`:
the D-G bound minimized over several frequencies at once); it only changes which scalings are
tested, and is off by default (it costs more than it saves on the analysis' covers).

The scalings of each point are conditioned block by block and, across blocks, with the largest
spread of :data:`SPREAD_FLOORS` that still proves the level at the point
(:func:`proving_scalings`): the optimal scalings of an LFR with badly scaled channels are far
apart between blocks, and bringing them closer than the slack allows leaves no interval at all.

The same works for the skewed-mu bound of :func:`~oos_drake.robust.wcgain`: the rows of the
performance outputs are divided by the gain level ``gamma`` and the LMI is taken at
``beta = 1``; dividing them by a larger ``gamma`` only lowers ``Phi`` (``G`` has no performance
columns), so a larger level again only widens an interval.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response
from oos_drake.robust.mu import (
    CONTINUATION_PATIENCE,
    CONTINUATION_TEMPERATURE,
    UPPER_ITERATIONS,
    UPPER_TOL,
    _upper_bound,
)
from oos_drake.robust.mu_upper import LMI_ROUNDOFF, mu_upper_bound

#: Eigenvalues of the Hamiltonian within this distance of the imaginary axis (relative to the
#: largest eigenvalue modulus) are candidate crossings. Generous on purpose: a spurious candidate
#: only adds one evaluation of ``Phi``; a missed one would be a hole in the proof.
AXIS_TOLERANCE = 1e-6
#: ``lambda_max(Phi)`` relative to the size of its terms must be below ``-STRICT`` in a piece of
#: the axis for the piece to count as proved (the round-off of forming ``Phi``, as for the
#: certificate check of :func:`~oos_drake.robust.mu_upper.lmi_residual`).
STRICT = LMI_ROUNDOFF
#: Default relative slack above the optimal bound at each point (intervals of non-zero width).
SLACK = 0.005
#: Smallest eigenvalue of each diagonal block of the D scalings relative to the block's largest
#: (see :meth:`Scalings.conditioned`).
CONDITION_FLOOR = 1e-10
#: Smallest scaling relative to the largest of all blocks, tried in turn until the conditioned
#: scalings prove the level at their frequency (:func:`proving_scalings`): the first keeps the
#: scaled realization of :class:`_Multiplier` accurate; the next ones are needed by LFRs whose
#: channels are badly scaled (optimal scalings 1e-12 apart between blocks).
SPREAD_FLOORS = (1e-10, 1e-12, 1e-14, 0.0)
#: Largest margin, relative to the level's term ``||P22|| = beta^2`` of the scaled ``Phi``, that
#: the interval test of :func:`dg_interval` gives up to leave weakly seen modes out of its
#: Hamiltonian (cost ``(2 k)^3`` for ``k`` modes kept). The modes ``i`` left out, with
#: ``M = C V diag(1 / (j nu - lambda_i)) V^{-1} B + D`` in the scaled form, change ``M`` by
#: ``E(j nu)``, ``||E|| <= e = sum_i ||C v_i|| ||w_i B|| / |Re lambda_i|`` at every frequency;
#: for any ``t > 0``, ``M^* P11 M <= (1 + t) M_k^* P11 M_k + (1 + 1 / t) E^* P11 E`` (``P11``
#: positive semidefinite) and ``E^* P12 + P12^* E <= 2 e ||P12||``, so with ``t = e / s``,
#: ``s = sqrt(||P22|| / ||P11||)``, the ``Phi`` of ``M_k`` with ``P11 (1 + e / s)`` and
#: ``P22 + delta I``, ``delta = ||P11|| (e^2 + e s) + 2 e ||P12||``, is an upper bound of
#: ``Phi(M)`` at every frequency: where it is negative, so is ``Phi(M)``. Its crossings and
#: signs are those of the reduced realization (the Hamiltonian and the pieces' test points
#: alike). The modes are left out by increasing residue bound while ``delta`` stays within this
#: budget (on the make-run mission subsets about half of the modes the plain test keeps); a
#: point that the reduced ``Phi`` does not prove is tested on the whole realization.
DROP_BUDGET = 1e-6


@dataclass(frozen=True)
class Realization:
    """State-space realization ``(A, B, C, D)`` of the matrix ``M`` seen by the uncertainty.

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        ``(n, n), (n, r), (c, n), (c, r)`` real or complex.
    sample_time : float or None
        None for continuous time, else the sample time [s] of a discrete-time model.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    sample_time: float | None = None

    def __post_init__(self):
        A, B, C, D = (np.atleast_2d(np.asarray(x)) for x in (self.A, self.B, self.C, self.D))
        n = A.shape[0] if A.size else 0
        A = A.reshape(n, n)
        B = B.reshape(n, D.shape[1])
        C = C.reshape(D.shape[0], n)
        for name, x in zip("ABCD", (A, B, C, D), strict=True):
            if x.dtype.kind not in "biufc" or not np.all(np.isfinite(x)):
                raise ValueError(f"Realization: {name} must be finite numbers")
        ts = self.sample_time
        if ts is not None and not (np.isfinite(ts) and ts > 0):
            raise ValueError(f"Realization: sample_time must be None or > 0 [s], got {ts!r}")
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "C", C)
        object.__setattr__(self, "D", D)

    @classmethod
    def from_lti(cls, sys) -> Realization:
        """From a ``control.StateSpace`` / ``TransferFunction`` (``dt = 0``: continuous,
        ``dt > 0``: discrete with that sample time; ``dt = True`` is refused: no sample time)."""
        import control

        dt = getattr(sys, "dt", 0)
        if dt is True:
            raise ValueError(
                "Realization: discrete-time model without a sample time (dt=True); "
                "give dt > 0 [s] so that the unit circle maps to frequencies"
            )
        ss = control.ss(sys)
        return cls(ss.A, ss.B, ss.C, ss.D, None if not dt else float(dt))

    @property
    def nyquist(self) -> float:
        """End of the frequency axis [rad/s]: ``inf`` or ``pi / sample_time``."""
        return np.inf if self.sample_time is None else np.pi / self.sample_time

    def axis_poles(self) -> np.ndarray:
        """Frequencies [rad/s] in ``[0, nyquist]`` of the poles of ``M`` within round-off
        (1e-10 relative) of the imaginary axis (unit circle), sorted: ``M`` is unbounded there
        and no interval of :func:`dg_interval` reaches them."""
        if not self.A.size:
            return np.zeros(0)
        lam = np.linalg.eigvals(self.A)
        if self.sample_time is None:
            dist = np.abs(lam.real)
            scale = max(1.0, float(np.max(np.abs(lam))))
            omega = np.abs(lam.imag)
        else:
            dist = np.abs(np.abs(lam) - 1.0)
            scale = 1.0
            omega = np.abs(np.angle(lam)) / self.sample_time
        return np.unique(omega[dist <= 1e-10 * scale])

    def check_axis(self) -> None:
        """Raise ``ValueError`` if ``M`` has a pole on the imaginary axis (unit circle)."""
        poles = self.axis_poles()
        if poles.size:
            where = "imaginary axis" if self.sample_time is None else "unit circle"
            raise ValueError(
                f"the model has a pole on the {where} at omega = {poles[0]:.6g} rad/s: M is "
                "unbounded there, no frequency-axis certificate exists"
            )

    def continuous(self) -> tuple:
        """``(A, B, C, D)`` whose response at ``j nu`` is ``M`` at :meth:`to_nu` ``(omega)``."""
        if self.sample_time is None:
            return self.A, self.B, self.C, self.D
        if "_continuous" in self.__dict__:
            return self.__dict__["_continuous"]
        n = self.A.shape[0]
        if n == 0:
            return self.A, self.B, self.C, self.D
        P = np.eye(n) + self.A  # Cayley: z = (1 + s) / (1 - s)
        Pi_B = np.linalg.solve(P, self.B)
        C_Pi = np.linalg.solve(P.T, self.C.T).T
        Ac = np.linalg.solve(P, self.A - np.eye(n))
        out = (Ac, np.sqrt(2.0) * Pi_B, np.sqrt(2.0) * C_Pi, self.D - self.C @ Pi_B)
        object.__setattr__(self, "_continuous", out)  # computed once per realization
        return out

    def modal(self):
        """``(poles, V, V^{-1})`` of the continuous-time ``A`` (:meth:`continuous`);
        ``(poles, None, None)`` when its eigenvectors are too ill-conditioned (condition number
        above 1e8), None without states; computed once per realization (every interval of a
        cover shares it)."""
        if "_modal" not in self.__dict__:
            A = self.continuous()[0]
            modal = None
            if A.shape[0]:
                lam, V = np.linalg.eig(A)
                cond = np.linalg.cond(V)
                modal = (lam, V, np.linalg.inv(V)) if cond < 1e8 else (lam, None, None)
            object.__setattr__(self, "_modal", modal)
        return self.__dict__["_modal"]

    def hamiltonian_modes(self) -> np.ndarray | None:
        """Boolean mask of the modes of :meth:`modal` that the Hamiltonian test keeps; None
        without a usable modal form (then the test uses the whole realization).

        A mode whose residue bound ``|C v_i| |w_i B| / |Re lambda_i|`` (its largest
        contribution to ``M`` at any frequency) is below ``cond(V) eps 1e-3`` times the
        largest one is not seen by ``M`` to the round-off of the modal form itself, which every
        evaluation of ``M`` in :class:`_Multiplier` already carries: it is uncontrollable or
        unobservable from the channels of ``M`` (the make-run mission subsets' ``M`` keep 38-78
        of the closed loop's 81 modes, the modes left out at most 3e-14 of the largest, 1000
        times below the modal form's round-off; the docking loops' total subset keeps nearly
        all). Leaving those modes out of the Hamiltonian changes none of its
        imaginary-axis eigenvalues beyond that round-off and makes its eigenproblem
        ``(2 k)^2`` instead of ``(2 n)^2`` (cost ``k^3``); the signs between its candidates are
        still evaluated on the whole ``M``. Computed once per realization.
        """
        if "_hamiltonian_modes" not in self.__dict__:
            keep = None
            lam, V, V_inv = self.modal() or (None, None, None)
            if V is not None:
                _, B, C, _ = self.continuous()
                reach = np.linalg.norm(C @ V, axis=0) * np.linalg.norm(V_inv @ B, axis=1)
                reach = reach / np.maximum(np.abs(lam.real), 1e-300)
                tol = 1e-3 * np.linalg.cond(V) * np.finfo(float).eps
                keep = reach > tol * max(float(np.max(reach)), 1e-300)
            object.__setattr__(self, "_hamiltonian_modes", keep)
        return self.__dict__["_hamiltonian_modes"]

    def to_nu(self, omega):
        """Continuous-time frequency of the Cayley image (identity in continuous time)."""
        omega = np.asarray(omega, dtype=float)
        if self.sample_time is None:
            return omega
        theta = np.clip(omega * self.sample_time, 0.0, np.pi)
        with np.errstate(over="ignore"):
            return np.where(theta >= np.pi, np.inf, np.tan(theta / 2.0))

    def from_nu(self, nu):
        """Inverse of :meth:`to_nu` [rad/s]."""
        nu = np.asarray(nu, dtype=float)
        if self.sample_time is None:
            return nu
        return 2.0 * np.arctan(nu) / self.sample_time

    def response(self, omega) -> np.ndarray:
        """``M`` at the frequencies ``omega`` [rad/s]: ``(F, c, r)`` (``inf``: the feedthrough)."""
        nu = np.atleast_1d(self.to_nu(omega))
        A, B, C, D = self.continuous()
        out = np.empty((nu.size,) + D.shape, dtype=complex)
        fin = np.isfinite(nu)
        out[~fin] = D
        if np.any(fin):
            out[fin] = delta_channel_response(A, B, C, D, nu[fin])
        return out

    def scale_rows(self, rows: slice, factor: float) -> Realization:
        """The realization with the outputs ``rows`` multiplied by ``factor``."""
        C, D = self.C.astype(complex if np.iscomplexobj(self.C) else float), self.D.copy()
        C[rows] *= factor
        D = D.astype(np.result_type(D, float))
        D[rows] *= factor
        return Realization(self.A, self.B, C, D, self.sample_time)


@dataclass(frozen=True)
class Scalings:
    """D-G scalings of one frequency (the :class:`~oos_drake.robust.MuResult` convention).

    Attributes
    ----------
    D_left, D_right, G : numpy.ndarray
        ``(c, c)``, ``(r, r)`` Hermitian positive definite and ``(r, c)``.
    """

    D_left: np.ndarray
    D_right: np.ndarray
    G: np.ndarray

    def conditioned(
        self, floor: float = CONDITION_FLOOR, spread: float = SPREAD_FLOORS[0]
    ) -> Scalings:
        """Each diagonal block ``D_b`` of ``D_l`` and ``D_r`` replaced by ``D_b + e_b I``,
        ``e_b = max(floor * lambda_max(D_b), spread * lambda_max(D_r))``.

        The blocks are the connected components of the scalings' sparsity pattern (a repeated
        scalar's full ``D_b``, equal on both sides; a full block's scalar, one entry at a time),
        so the structure is kept. The optimal scalings of a real ``M`` (``omega = 0``) or a
        bound reached by unbounded scalings can make a block ``D_b`` singular to 1e16, where the
        sign of ``Phi`` is round-off; after this each block is conditioned to ``1 / floor``.

        ``floor`` is relative to each block: the change of ``Phi`` is at most ``floor`` times
        its own terms in the scaled form (:class:`_Multiplier`). ``spread`` bounds the ratio of
        different blocks' scalings, which carries the channel scaling of the LFR (an ``M`` with
        entries of 1e4 in the row of a badly scaled channel and 1e-6 in its column has optimal
        scalings 1e-12 apart): it adds ``e ||M||^2`` to ``Phi``, which can exceed the slack of
        the level (the RCT two-mass example, ``spread = 1e-10``: no interval at all), so
        :func:`proving_scalings` lowers it until the scalings prove the level; a smaller
        ``spread`` costs accuracy of the scaled realization, and :func:`dg_interval` checks the
        sign at the point anyway.
        """
        top = float(np.max(np.linalg.eigvalsh(0.5 * (self.D_right + np.conj(self.D_right.T)))))
        least = spread * max(top, 0.0)
        return Scalings(
            _floor_blocks(self.D_left, floor, least),
            _floor_blocks(self.D_right, floor, least),
            self.G,
        )


def _diagonal_blocks(D: np.ndarray) -> list:
    """Index ranges of the diagonal blocks of a block-diagonal ``D`` (the scalings of a block
    structure: contiguous blocks): a block ends at ``i`` when no nonzero entry of the rows up to
    ``i`` lies right of column ``i``."""
    pattern = np.abs(np.asarray(D)) > 0
    n = pattern.shape[0]
    cols = np.arange(n)
    reach = np.where(pattern.any(axis=1), np.max(np.where(pattern, cols, -1), axis=1), cols)
    ends = np.flatnonzero(np.maximum.accumulate(np.maximum(reach, cols)) == cols)
    starts = np.r_[0, ends[:-1] + 1]
    return [np.arange(a, b + 1) for a, b in zip(starts, ends, strict=True)]


def _block_extremes(D: np.ndarray, blocks: list) -> tuple:
    """``(smallest, largest)`` eigenvalues of each diagonal block ``D[idx, idx]`` of ``blocks``
    (arrays in the order of ``blocks``): the blocks of one size in one batched ``eigvalsh``."""
    low, high = np.empty(len(blocks)), np.empty(len(blocks))
    sizes = np.array([idx.size for idx in blocks])
    for size in np.unique(sizes):
        which = np.flatnonzero(sizes == size)
        rows = np.array([blocks[k] for k in which])  # (blocks, size)
        if size == 1:
            ev = np.real(D[rows[:, 0], rows[:, 0]])[:, None]
        else:
            ev = np.linalg.eigvalsh(D[rows[:, :, None], rows[:, None, :]])
        low[which], high[which] = ev[:, 0], ev[:, -1]
    return low, high


def _floor_blocks(D: np.ndarray, floor: float, least: float = 0.0) -> np.ndarray:
    """``D`` with ``max(floor * lambda_max(D_b), least) I`` added to each diagonal block
    ``D_b``."""
    D = 0.5 * (np.asarray(D) + np.conj(np.asarray(D).T))
    out = D.astype(np.result_type(D, float), copy=True)
    diagonal = np.diagonal(D).real
    if not np.any(D - np.diag(np.diagonal(D))):  # scalar blocks only: one entry each
        out[np.diag_indices_from(out)] += np.maximum(floor * np.maximum(diagonal, 0.0), least)
        return out
    blocks = _diagonal_blocks(D)
    _, top = _block_extremes(D, blocks)
    add = np.maximum(floor * np.maximum(top, 0.0), least)
    for idx, a in zip(blocks, add, strict=True):
        out[idx, idx] += a
    return out


def _block_conditions(D: np.ndarray) -> tuple:
    """``(smallest, largest)`` eigenvalue of the worst-conditioned diagonal block of ``D``."""
    D = np.asarray(D)
    worst = (1.0, 1.0)  # a 1 x 1 block has ratio 1
    if not np.any(D - np.diag(np.diagonal(D))):
        return worst
    blocks = [idx for idx in _diagonal_blocks(D) if idx.size > 1]
    for lo, hi in zip(*_block_extremes(D, blocks), strict=True):
        if lo * worst[1] < worst[0] * hi:  # lo / hi < worst ratio
            worst = (float(lo), float(hi))
    return worst


class _Multiplier:
    """``Phi`` of fixed scalings and level on a realization, in the Cholesky-scaled form."""

    def __init__(self, real: Realization, sc: Scalings, beta: float, reduce: bool = False):
        A, B, C, D = real.continuous()
        scaled = True
        herm = lambda X: 0.5 * (X + np.conj(X.T))  # noqa: E731
        Dl, Dr, G = herm(np.asarray(sc.D_left)), herm(np.asarray(sc.D_right)), np.asarray(sc.G)
        c, r = D.shape
        try:
            Ll = np.linalg.cholesky(Dl)
            Lr = np.linalg.cholesky(Dr)
            B = np.linalg.solve(Lr, np.conj(B.T)).conj().T  # B L_r^{-*}
            C = np.conj(Ll.T) @ C
            D = np.conj(Ll.T) @ np.linalg.solve(Lr, np.conj(D.T)).conj().T
            Gh = np.linalg.solve(Lr, np.linalg.solve(Ll, np.conj(G.T)).conj().T)
            self.P11 = np.eye(c)
            self.P12 = -1j * np.conj(Gh.T)
            self.P22 = -(beta**2) * np.eye(r)
        except np.linalg.LinAlgError:  # not numerically definite: the unscaled form
            scaled = False
            self.P11 = Dl.astype(complex)
            self.P12 = -1j * np.conj(G.T)
            self.P22 = -(beta**2) * Dr
        self.A, self.B, self.C, self.D = A, B, C, D
        # modal form, once: every later evaluation of M is O(n) per entry (ends are bisected)
        self._modal = None
        self._keep = None
        self.poles = np.zeros(0)
        self.dropped = 0.0  # bound on ||M - M_kept|| on the axis (reduced test), else 0
        if A.shape[0]:
            lam, V, V_inv = real.modal()
            self.poles = lam
            if V is not None:
                self._modal = (lam, C @ V, V_inv @ B)
                self._keep = real.hamiltonian_modes()
        # ||P22||: beta^2 in the scaled form (P22 = -beta^2 I), no SVD
        self.ref = float(beta**2) if scaled else np.linalg.norm(self.P22, 2)
        if reduce and self._modal is not None and scaled:
            self._reduce()

    def _reduce(self):
        """Leave out the modes whose summed residue bound ``e >= ||M(j nu) - M_k(j nu)||`` (all
        ``nu``) keeps the margin ``delta`` below :data:`DROP_BUDGET` of the level's term, and
        make the tested ``Phi`` that of ``M_k`` with ``P11 (1 + e / s)`` and ``P22 + delta I``
        (``s = sqrt(||P22|| / ||P11||)``): an upper bound of ``Phi(M)`` at every frequency
        (see :data:`DROP_BUDGET`), so every piece where it is negative is proved for ``M``."""
        lam, CV, VB = self._modal
        with np.errstate(divide="ignore"):
            reach = np.linalg.norm(CV, axis=0) * np.linalg.norm(VB, axis=1) / np.abs(lam.real)
        reach = np.where(np.isfinite(reach), reach, np.inf)
        p11, p12 = 1.0, np.linalg.norm(self.P12, 2)  # scaled form only: P11 = I
        s = np.sqrt(self.ref / max(p11, 1e-300))

        def margin(e):
            return p11 * (e * e + e * s) + 2.0 * e * p12

        order = np.argsort(reach, kind="stable")
        total = np.cumsum(reach[order])
        n = int(np.searchsorted(margin(total) > DROP_BUDGET * self.ref, True))
        drop = np.zeros(lam.size, dtype=bool)
        drop[order[:n]] = True
        if self._keep is not None:
            drop |= ~self._keep  # the round-off modes of Realization.hamiltonian_modes too
        if not drop.any() or drop.all():
            return
        e = float(np.sum(reach[drop]))
        if not np.isfinite(e):
            return
        self.dropped = e
        keep = ~drop
        self._modal = (lam[keep], CV[:, keep], VB[keep])
        self._keep = None  # the modal form is the reduced one: all of its modes are tested
        self.P11 = self.P11 * (1.0 + e / s)
        self.P22 = self.P22 + margin(e) * np.eye(self.P22.shape[0])

    def response(self, nu) -> np.ndarray:
        """The scaled ``M(j nu)``, ``(F, c, r)`` (``nu`` may hold inf)."""
        nu = np.atleast_1d(np.asarray(nu, dtype=float))
        M = np.empty((nu.size,) + self.D.shape, dtype=complex)
        fin = np.isfinite(nu)
        M[~fin] = self.D
        if np.any(fin) and self._modal is not None:
            lam, CV, VB = self._modal
            # (C V) diag(1 / (j nu - lambda)) (V^-1 B) at every frequency as ONE matrix product
            # (a numpy einsum of three operands loops in C without BLAS: 10-100x slower here)
            resolvent = 1.0 / (1j * nu[fin, None] - lam[None, :])
            left = (CV[None, :, :] * resolvent[:, None, :]).reshape(-1, lam.size)
            M[fin] = self.D + (left @ VB).reshape(resolvent.shape[0], *self.D.shape)
        elif np.any(fin):
            M[fin] = delta_channel_response(self.A, self.B, self.C, self.D, nu[fin])
        return M

    def max_eig(self, nu) -> np.ndarray:
        """``lambda_max(Phi(j nu))`` relative to the size of its terms (``nu`` may hold inf)."""
        M = self.response(nu)
        MH = np.conj(np.swapaxes(M, -1, -2))
        cross = MH @ self.P12
        Phi = MH @ self.P11 @ M + cross + np.conj(np.swapaxes(cross, -1, -2)) + self.P22
        Phi = 0.5 * (Phi + np.conj(np.swapaxes(Phi, -1, -2)))
        # size of the terms entry by entry (what the round-off of forming Phi scales with)
        aM, aMH = np.abs(M), np.abs(MH)
        size = aMH @ np.abs(self.P11) @ aM + 2.0 * aMH @ np.abs(self.P12) + np.abs(self.P22)
        size = np.linalg.norm(size, axis=(-2, -1))
        return np.linalg.eigvalsh(Phi)[:, -1] / size

    def crossings(self, shift: float | None = None) -> np.ndarray:
        """Candidate ``nu >= 0`` where ``Phi(j nu)`` may be singular (Hamiltonian eigenvalues).

        Without ``shift`` the Hamiltonian is that of the realization, whose ``R`` is
        ``Phi(inf)``; ``ValueError`` when that is singular or too ill-conditioned (e.g. a large
        feedthrough where the scalings do not prove the level). With ``shift = nu_0`` it is that
        of ``M`` in the variable ``p = 1 / (s - j nu_0)`` (``s = j nu`` maps to ``p = j w``,
        ``nu = nu_0 - 1 / w``; realization ``(A - j nu_0 I)^{-1}``, ``(A - j nu_0 I)^{-1} B``,
        ``-C (A - j nu_0 I)^{-1}``, ``M(j nu_0)``), whose ``R`` is ``Phi(j nu_0)``: negative
        definite wherever the scalings prove the level, so the test always exists there.
        """
        A, B, C, D = self.A, self.B, self.C, self.D
        keep = self._keep
        if shift is not None:
            if self._modal is not None:
                lam, CV, VB = self._modal
                r = 1.0 / (lam - 1j * shift)
                A, B, C = np.diag(r), r[:, None] * VB, -CV * r[None, :]
            else:
                A0 = np.linalg.inv(A - 1j * shift * np.eye(A.shape[0]))
                A, B, C = A0, A0 @ B, -C @ A0
            D = self.response([shift])[0]
        elif keep is not None or self.dropped:  # the modes M sees / the reduced test keeps
            lam, CV, VB = self._modal
            A, B, C = np.diag(lam), VB, CV
        if keep is not None and self._modal is not None:
            A, B, C = A[np.ix_(keep, keep)], B[keep], C[:, keep]
        n = A.shape[0]
        if n == 0:
            return np.zeros(0)
        P11, P12, P22 = self.P11, self.P12, self.P22
        DH, CH = np.conj(D.T), np.conj(C.T)
        R = DH @ P11 @ D + DH @ P12 + np.conj(P12.T) @ D + P22
        R = 0.5 * (R + np.conj(R.T))
        ev = np.linalg.eigvalsh(R)
        if np.min(np.abs(ev)) <= 1e-12 * max(np.max(np.abs(ev)), self.ref):
            raise ValueError(
                "Phi(inf) is singular or ill-conditioned (above 1e12) at this level: "
                "no Hamiltonian test"
            )
        Q = CH @ P11 @ C
        S = CH @ (P11 @ D + P12)
        RiSH = np.linalg.solve(R, np.conj(S.T))
        RiBH = np.linalg.solve(R, np.conj(B.T))
        H = np.block(
            [
                [A - B @ RiSH, -B @ RiBH],
                [-Q + S @ RiSH, -np.conj(A.T) + S @ RiBH],
            ]
        )
        lam = scipy.linalg.eigvals(H, overwrite_a=True, check_finite=False)
        scale = max(float(np.max(np.abs(lam))), 1e-300)
        near = np.abs(lam.real) <= AXIS_TOLERANCE * scale
        w = lam.imag[near]
        if shift is not None:  # back to nu; w = 0 is nu = inf (an end of every piece anyway)
            w = w[np.abs(w) > 1e-300]
            w = shift - 1.0 / w
            return np.unique(np.maximum(w[w >= -AXIS_TOLERANCE * max(shift, 1.0)], 0.0))
        w = w[w >= -AXIS_TOLERANCE * scale]
        return np.unique(np.maximum(w, 0.0))


def dg_interval(real: Realization, scalings: Scalings, beta: float, omega0: float):
    """Largest frequency interval around ``omega0`` on which the scalings prove ``mu <= beta``.

    Parameters
    ----------
    real : Realization
        Realization of ``M`` (no pole on the imaginary axis / unit circle).
    scalings : Scalings
        D-G scalings found at ``omega0``.
    beta : float
        Level to prove (``> 0``); the LMI must hold strictly at ``omega0``.
    omega0 : float
        Frequency [rad/s], ``0 <= omega0 <= real.nyquist``.

    Returns
    -------
    tuple of float
        ``(lo, hi)`` [rad/s] with ``0 <= lo <= omega0 <= hi <= real.nyquist`` (``hi`` may be
        ``inf``): ``Phi(omega) <= 0`` for every ``omega`` in ``[lo, hi]``, and ``Phi`` has a
        positive eigenvalue just outside each finite end below the axis end.

    Raises
    ------
    ValueError
        If the LMI does not hold strictly at ``omega0``, or ``Phi(inf)`` is singular.
    """
    problem = _definiteness(scalings)
    if problem:
        raise ValueError(f"dg_interval: {problem}; use Scalings.conditioned()")
    mult = _Multiplier(real, scalings, beta, reduce=True)
    nu0 = float(real.to_nu(omega0))
    if mult.dropped and mult.max_eig([nu0])[0] >= -STRICT:  # the margin of the modes left out
        mult = _Multiplier(real, scalings, beta)  # is too much here: the whole realization
    if mult.max_eig([nu0])[0] >= -STRICT:
        raise ValueError(
            f"dg_interval: the scalings do not prove mu <= {beta:.6g} strictly at "
            f"omega = {omega0:.6g} rad/s"
        )
    try:
        cand = mult.crossings()
    except ValueError:  # Phi(inf) unusable: the Hamiltonian of p = 1 / (s - j nu0) instead
        cand = mult.crossings(shift=nu0)
    bounds = np.concatenate([[0.0], cand[cand > 0], [np.inf]])
    bounds = np.unique(bounds)
    # one test point inside each piece (the sign of lambda_max is constant there)
    lo_b, hi_b = bounds[:-1], bounds[1:]
    last = np.isinf(hi_b)
    rho = float(np.max(np.abs(mult.poles))) if mult.poles.size else 0.0
    tail = 2.0 * lo_b + max(1.0, rho)
    mids = np.where(last, tail, 0.5 * (lo_b + np.where(last, 0.0, hi_b)))
    # the test points and nu = inf in one evaluation
    values = mult.max_eig(np.append(mids, np.inf) if last[-1] else mids)
    ok = values[: mids.size] < -STRICT
    if last[-1]:
        ok[-1] &= values[-1] < -STRICT
    k = int(np.searchsorted(bounds, nu0, side="right") - 1)
    k = min(max(k, 0), ok.size - 1)
    if not ok[k]:  # nu0 sits on a spurious candidate: the piece to its right holds it too
        raise ValueError(f"dg_interval: inconsistent sign at omega = {omega0:.6g} rad/s")
    right = k
    while right + 1 < ok.size and ok[right + 1]:
        right += 1
    left = k
    while left - 1 >= 0 and ok[left - 1]:
        left -= 1
    # the ends are eigenvalues of H, accurate to its round-off: move each end inside to the
    # last point where lambda_max is strictly negative (bisection from the piece's test point)
    nu_lo, nu_hi = _inner_ends(
        mult,
        (bounds[left] if left > 0 else 0.0, bounds[right + 1] if right + 1 < ok.size else np.inf),
        (mids[left], mids[right]),
    )
    lo, hi = float(real.from_nu(nu_lo)), float(real.from_nu(nu_hi))
    return lo, min(hi, real.nyquist)


def _definiteness(scalings) -> str:
    """Why ``D_left`` or ``D_right`` of ``scalings`` is not positive definite to round-off for
    :func:`dg_interval` (block conditions and spread of :data:`CONDITION_FLOOR` and
    :data:`SPREAD_FLOORS`), "" if both are; computed once per :class:`Scalings` (a cover tests
    the same scalings at several levels, and on the next configuration as prior points)."""
    if "_definiteness" in scalings.__dict__:
        return scalings.__dict__["_definiteness"]
    problem = ""
    for name, Dx in (("D_left", scalings.D_left), ("D_right", scalings.D_right)):
        Dx = 0.5 * (Dx + np.conj(np.asarray(Dx).T))
        low, high = _block_conditions(Dx)
        ev = np.linalg.eigvalsh(Dx)
        if not (low > 0.1 * CONDITION_FLOOR * high and ev[0] > 0.1 * SPREAD_FLOORS[-1] * ev[-1]):
            problem = (
                f"a block of {name} is not positive definite to round-off "
                f"(eigenvalues {low:.3g} .. {high:.3g})"
            )
            break
    object.__setattr__(scalings, "_definiteness", problem)
    return problem


def _inner_ends(mult, ends, insides):
    """:func:`_inner_end` of the two ends ``(lower, upper)`` of a piece, their first steps in
    one evaluation (an end at 0 or infinity is kept as it is)."""
    steps = np.array([0.0, 1e-10, 1e-8, 1e-6, 1e-4])
    todo = [k for k in (0, 1) if np.isfinite(ends[k]) and not (k == 0 and ends[k] == 0.0)]
    out = list(ends)
    if not todo:
        return tuple(out)
    nus = np.concatenate([ends[k] + steps * (insides[k] - ends[k]) for k in todo])
    values = mult.max_eig(nus).reshape(len(todo), steps.size)
    for row, k in zip(values, todo, strict=True):
        good = np.flatnonzero(row < -STRICT)
        if good.size:
            out[k] = ends[k] + steps[good[0]] * (insides[k] - ends[k])
        else:
            out[k] = _inner_end(mult, ends[k], insides[k], first=False)
    return tuple(out)


def _inner_end(mult, end, inside, first=True):
    """``end`` if ``Phi(end) < 0`` strictly, else the point nearest to ``end`` (towards
    ``inside``, where ``Phi < 0``) at which it is: the crossing itself (``lambda_max = 0``) is
    only known to the round-off of the Hamiltonian's eigenvalues. Tries steps of 1e-10 .. 1e-4
    of the distance first (one evaluation each), then bisects."""
    if not np.isfinite(end):
        return end
    steps = np.array([0.0, 1e-10, 1e-8, 1e-6, 1e-4])
    values = mult.max_eig(end + steps * (inside - end)) if first else np.zeros(steps.size)
    for t, value in zip(steps, values, strict=True):
        if value < -STRICT:
            return end + t * (inside - end)
    a, b = inside, end
    for _ in range(200):
        m = 0.5 * (a + b)
        if m in (a, b) or abs(b - a) <= 1e-10 * abs(b):
            break
        if mult.max_eig([m])[0] < -STRICT:
            a = m
        else:
            b = m
    return a


@dataclass(frozen=True)
class AxisCertificate:
    """Intervals that together prove a bound on the whole frequency axis.

    Attributes
    ----------
    upper : float
        Guaranteed bound on ``[0, nyquist]`` (``inf`` if the cover did not close; then
        :attr:`upper_on_cover` holds on the proved intervals).
    omega : numpy.ndarray
        ``(K,)`` frequencies [rad/s] where scalings were computed, sorted.
    optimal : numpy.ndarray
        ``(K,)`` bound found at each point (mu upper bound, or worst-case gain level; NaN for
        a ``prior`` point of :func:`cover_axis`, whose scalings come from another model).
    level : numpy.ndarray
        ``(K,)`` level proved on each point's interval (``>= (1 + slack) optimal``).
    interval : numpy.ndarray
        ``(K, 2)`` ``[lo, hi]`` [rad/s] proved at ``level``.
    added : numpy.ndarray
        ``(K,)`` True for points the cover added (not seeds).
    scalings : tuple of Scalings
        The scalings of each point.
    slack : float
        Relative slack above each point's optimal bound.
    covered : bool
        True when the intervals cover ``[0, nyquist]``.
    realization : Realization
        The realization of ``M`` the intervals refer to.
    performance_rows : int
        0 for a mu bound; else the number of trailing outputs of ``M`` divided by the level
        (skewed mu of a worst-case gain, LMI at ``beta = 1``).
    reason : str
        Why the cover did not close (which frequencies, and what stopped it); empty when
        ``covered``.
    gaps : tuple
        ``(lo, hi)`` [rad/s] pieces of ``[0, nyquist]`` left unproved (empty when ``covered``).
    """

    upper: float
    omega: np.ndarray
    optimal: np.ndarray
    level: np.ndarray
    interval: np.ndarray
    added: np.ndarray
    scalings: tuple
    slack: float
    covered: bool
    realization: Realization = field(repr=False, default=None)
    performance_rows: int = 0
    reason: str = ""
    gaps: tuple = ()

    @property
    def nyquist(self) -> float:
        """End of the frequency axis [rad/s]."""
        return self.realization.nyquist

    @property
    def upper_on_cover(self) -> float:
        """Largest level of the proved intervals: the bound on their union (the whole axis when
        ``covered``; else everywhere but :attr:`gaps`); 0 without any interval."""
        proved = np.isfinite(self.interval[:, 0]) if self.interval.size else np.zeros(0, bool)
        return float(np.max(self.level[proved])) if np.any(proved) else 0.0

    def summary(self) -> str:
        """One line: the bound and where it holds (and why not everywhere)."""
        if self.covered:
            return f"<= {self.upper:.6g} on the whole axis ({self.omega.size} points)"
        return f"<= {self.upper_on_cover:.6g} except on the gaps; {self.reason}"

    def essential(self) -> np.ndarray:
        """Indices of a smallest subset of the points whose intervals still cover the axis
        (greedy: from 0, always the interval that reaches farthest); empty if not covered.
        Their scalings are the natural first candidates of a neighbouring model's cover
        (``prior`` of :func:`cover_axis`)."""
        if not self.covered:
            return np.zeros(0, dtype=int)
        rows = np.flatnonzero(np.all(np.isfinite(self.interval) | np.isposinf(self.interval), 1))
        chosen, reach = [], 0.0
        while reach < self.nyquist:
            start = rows[self.interval[rows, 0] <= reach]
            if not start.size:
                break
            best = start[np.argmax(self.interval[start, 1])]
            if self.interval[best, 1] <= reach:
                break
            chosen.append(int(best))
            reach = float(self.interval[best, 1])
        return np.array(sorted(chosen), dtype=int)

    def check(self) -> dict:
        """Prove the cover again: recompute every interval from its scalings and level.

        Returns
        -------
        dict
            ``intervals_hold`` (every recomputed interval contains the stored one),
            ``covered`` (their union covers ``[0, nyquist]``), ``upper`` (max level).
        """
        held, spans = True, []
        for w, lev, sc, (lo, hi) in zip(
            self.omega, self.level, self.scalings, self.interval, strict=True
        ):
            if not np.isfinite(lo):  # a point whose interval is not part of the proof
                continue
            real, beta = _level_problem(self.realization, self.performance_rows, lev)
            a, b = dg_interval(real, sc, beta, w)
            held &= a <= lo * (1 + 1e-12) and b >= hi * (1 - 1e-12)
            spans.append((a, b))
        return {
            "intervals_hold": bool(held),
            "covered": not _gaps(np.array(spans).reshape(-1, 2), self.nyquist),
            "upper": float(np.max(self.level)) if self.level.size else 0.0,
        }


def _level_problem(real: Realization, performance_rows: int, level: float):
    """Realization and ``beta`` of the LMI that proves ``level``."""
    if performance_rows == 0:
        return real, level
    c = real.D.shape[0]
    return real.scale_rows(slice(c - performance_rows, c), 1.0 / level), 1.0


def _gaps(intervals: np.ndarray, end: float) -> list:
    """Uncovered pieces ``(a, b)`` of ``[0, end]`` by closed intervals (NaN rows: none)."""
    spans = intervals[np.all(np.isfinite(intervals) | np.isposinf(intervals), axis=1)]
    spans = spans[np.argsort(spans[:, 0], kind="stable")]
    gaps, reach = [], 0.0
    for lo, hi in spans:
        if lo > reach:
            gaps.append((reach, lo))
        reach = max(reach, hi)
    if reach < end or spans.size == 0:
        gaps.append((reach, end))
    return gaps


#: A gap ``(a, b)`` with ``b <= (1 + NARROW_GAP) a`` gets its middle solved only, not its edges
#: too (the intervals of the paper's covers near their peak are about 1 % wide: one point
#: closes such a gap); if its middle was tried already, its edges and middle as any gap's.
NARROW_GAP = 0.005


#: Where the interval next to a gap edge is known (log-width ``L``), the point solved for that
#: edge is moved into the gap by this fraction of ``L`` (:func:`_new_points`): an interval as
#: wide around it (the intervals of neighbouring points are about as wide: mu's margin below
#: the level changes slowly) still overlaps the neighbour's, and reaches ``(0.5 +
#: EDGE_SHIFT) L`` past the edge instead of ``0.5 L``.
EDGE_SHIFT = 0.4


def _new_points(gaps, end, known, widths=None):
    """Frequencies to solve in the gaps: both edges and an interior point (the middle only of
    a gap narrower than :data:`NARROW_GAP` whose middle was not tried yet).

    ``widths`` (optional): per gap ``(a, b)``, the log-widths ``(L_a, L_b)`` [-] of the
    proved intervals that end at ``a`` and start at ``b`` (NaN where unknown). An edge with a
    width gets its point moved into the gap, to ``a exp(EDGE_SHIFT L_a)`` and ``b
    exp(-EDGE_SHIFT L_b)`` (:data:`EDGE_SHIFT`); where these would cross, the gap gets its
    (geometric) middle only; the middle is added only where intervals as wide around the two
    points would not meet. Only where the points are solved changes: every interval is still
    proved by :func:`dg_interval`, and a point whose interval falls short leaves a smaller gap
    for the next round."""
    known = np.asarray(known, dtype=float)

    def tried(w):
        return known.size and np.min(np.abs(w - known)) <= 1e-12 * max(w, 1e-300)

    pts = []
    for k, (a, b) in enumerate(gaps):
        if a > 0 and np.isfinite(b) and b <= (1.0 + NARROW_GAP) * a and not tried(0.5 * (a + b)):
            pts.append(0.5 * (a + b))  # its edges too once the middle was tried
            continue
        la, lb = (np.nan, np.nan) if widths is None else widths[k]
        if a > 0 and np.isfinite(b) and (np.isfinite(la) or np.isfinite(lb)):
            la, lb = np.nan_to_num(la), np.nan_to_num(lb)  # an unknown width: the edge itself
            pa, pb = a * np.exp(EDGE_SHIFT * la), b * np.exp(-EDGE_SHIFT * lb)
            mid = np.sqrt(a * b)
            if pa < pb:
                pts.extend([pa, pb])
                # what intervals as wide as the neighbours' around pa and pb would reach
                if pa * np.exp(0.5 * la) < pb * np.exp(-0.5 * lb):
                    pts.append(mid)
                continue
            if not tried(mid):  # the shifted points would cross: the middle alone
                pts.append(mid)
                continue
        pts.append(a)
        if np.isfinite(b):
            pts.append(b)
            pts.append(np.sqrt(a * b) if a > 0 and b / a > 4 else 0.5 * (a + b))
        else:
            pts.extend([max(2.0 * a, 1e-3), max(10.0 * a, 1e-2)])
    pts = np.unique(np.clip(np.array(pts, dtype=float), 0.0, end if np.isfinite(end) else None))
    if known.size:
        dist = np.min(np.abs(pts[:, None] - known[None, :]), axis=1)
        pts = pts[dist > 1e-12 * np.maximum(pts, 1e-300)]
    return pts


def cover_axis(
    real: Realization,
    solve,
    seeds,
    *,
    floor: float = 0.0,
    slack: float = SLACK,
    performance_rows: int = 0,
    max_rounds: int = 40,
    progress=None,
    known=None,
    prior=None,
    lazy: bool = True,
    bands: bool = False,
) -> AxisCertificate:
    """Cover the frequency axis with intervals proved by D-G scalings.

    Parameters
    ----------
    real : Realization
        Realization of ``M`` (checked: no pole on the axis).
    solve : callable
        ``solve(omega) -> (optimal, level_min, scalings)`` for frequencies ``omega`` [rad/s]:
        the bound at each, the smallest level its scalings prove strictly (e.g.
        ``(1 + slack) optimal``) and a list of :class:`Scalings`.
    seeds : array_like
        First frequencies [rad/s] (e.g. the peaks of a grid sweep and 0).
    floor : float
        Lowest level to prove (e.g. ``(1 + slack)`` times a grid peak): a common level makes
        the intervals wide, and the guaranteed bound cannot be below the grid's anyway.
    slack : float
        Recorded in the result (``solve`` applies it).
    performance_rows : int
        See :class:`AxisCertificate`.
    max_rounds : int
        Rounds of gap filling before giving up (then ``covered`` is False and ``upper`` inf).
    progress : callable, optional
        Called with the number of points after each round.
    known : tuple, optional
        ``(omega, optimal, scalings)`` of points whose scalings are already known (e.g. a
        grid sweep's, :func:`scalings_at`): before solving new points in a gap, the cover
        tries the known points inside it (nearest to each edge first), no optimization. They
        never raise the level: a known point whose scalings do not prove the current level
        (a stalled optimizer) simply proves no interval, and the gap is solved. ``scalings``
        may be a callable ``rows -> (optimal, scalings)`` of the points ``omega[rows]``
        (e.g. :func:`scalings_at` of a sweep's parameters): then only the points the cover
        tries are evaluated, and ``optimal`` (e.g. the sweep's bounds) only chooses them.
    prior : tuple, optional
        ``(omega, scalings)`` tried first, all of them, before ``known`` and any optimization
        (e.g. the :meth:`AxisCertificate.essential` points of a neighbouring model's cover:
        neighbouring configurations are close problems). Like ``known`` they never raise the
        level; one that does not prove it here proves nothing. Their ``optimal`` is NaN (not
        solved for this ``M``).
    bands : bool
        Before solving points in a gap no wider than :data:`BAND_RATIO` (and not tried
        before), try one scaling chosen for the whole gap (``solve.band``, e.g.
        :meth:`_MuSolver.band`: :func:`band_scalings` on :data:`BAND_POINTS` frequencies from
        edge to edge), added as a point at the gap's middle when its bound over those
        frequencies is below the level; its interval is a :func:`dg_interval` like any
        other's (what it proves, wherever it reaches), and the gap is solved point by point
        as before where it proves nothing or leaves a gap. Default False: on the make-run
        mission study (``benchmarks/bench_guarantee_levels.py --bands``, 12 configurations)
        the band intervals are 5.8 % wide on average, but the optimizations cost more than
        the Hamiltonian tests they save (888 -> 859; the previous configuration's points'
        tests dominate): the guarantee's CPU 1.43 times the default's.
    lazy : bool
        Skip the interval test of a point that lies in no gap of the intervals proved so far
        (inside one, or where two meet): it is tested later only if a gap is left next to it
        (its interval is NaN otherwise). False tests every point (the reference of
        ``benchmarks/bench_guarantee_levels.py --eager``).

    Returns
    -------
    AxisCertificate
        ``covered`` False with a ``reason`` (and the ``gaps``) when the intervals do not close:
        a pole of ``M`` on the axis (never closed: ``M`` is unbounded there), a level that is
        infinite (mu unbounded at a frequency: ``I - M Delta`` singular for every size), or
        ``max_rounds`` rounds of added points without a proof of the level in a gap.

    Each round: test the points not tested yet (:meth:`_Cover.test_pending`); stop when the
    intervals close or only the gaps around poles on the axis are left; else, in this order,
    wake a lazily skipped point next to a gap, try the known points in the gaps, or solve new
    points in them (one round of ``max_rounds``; ``bands``: the band scalings of the narrow
    gaps first); before giving up, test every skipped point.
    """
    cover = _Cover(real, solve, seeds, floor, slack, performance_rows, known, prior, lazy)
    covered = False
    rounds = 0  # rounds that solved new points (the known points' rounds are free)
    while True:
        cover.test_pending()
        gaps = cover.gaps()
        if not gaps:
            covered = True
            break
        gaps = cover.away_from_poles(gaps)
        if not gaps:  # only the gaps around poles on the axis are left
            break
        if cover.wake(gaps):  # lazily skipped points next to a gap first: one test each
            continue
        if rounds >= max_rounds:
            if cover.test_deferred():  # before giving up: every skipped point
                continue
            break
        if cover.take_known(gaps):  # known scalings first: an interval test, no optimization
            continue
        if bands and cover.try_bands(gaps):  # one scaling chosen for a whole narrow gap
            continue
        new = cover.new_points(gaps, retry_prior=rounds == 0 and prior is not None)
        if new.size == 0:
            if cover.test_deferred():  # before giving up: every skipped point
                continue
            break
        rounds += 1
        cover.solve_points(new)
        if not np.isfinite(cover.level):
            break
        if progress is not None:
            progress(len(cover.omega))
    return cover.certificate(covered, rounds)


class _Cover:
    """The state of one :func:`cover_axis` and its steps.

    The points (seeds, then ``prior``, then known and solved ones as they are added), each
    with its bound ``opt``, the smallest level its scalings prove ``lmin``, its scalings and
    whether it was solved for the cover (``added``); the current ``level``; and ``proved``:
    point -> ``(level, interval)``. An interval proved at a lower level also proves any higher
    one (Phi only decreases), so each point keeps the interval of the level current when it
    was tested: no recomputation.

    Lazy tests: a point in no gap of the intervals proved already is not tested (its
    Hamiltonian eigenvalues are the cover's main cost: ``deferred``, interval NaN); it is
    tested later only where a gap is left next to it (once per gap edge, nearest point
    first: ``woken``), or at the end if the cover did not close. Skipping a test proves
    nothing: every interval kept is a :func:`dg_interval`.
    """

    def __init__(self, real, solve, seeds, floor, slack, performance_rows, known, prior, lazy):
        self.real, self.solve, self.slack = real, solve, slack
        self.performance_rows, self.lazy = performance_rows, lazy
        self.end = real.nyquist
        self.stuck = real.axis_poles()  # M unbounded there: the gaps around them never close
        omega = np.unique(np.clip(np.asarray(seeds, dtype=float), 0.0, self.end))
        opt, lmin, scs = solve(omega) if omega.size else ([], [], [])
        self.opt, self.lmin, self.scs = list(opt), list(lmin), list(scs)
        self.omega, self.added = list(omega), [False] * len(omega)
        self.level = max(float(floor), max(self.lmin, default=0.0))
        self.spare = _Spare(known, self.omega)
        self.first_prior = len(self.omega)
        self.n_prior = 0 if prior is None else len(prior[0])
        if prior is not None:
            for w, sc in zip(*prior, strict=True):
                self._append(float(np.clip(w, 0.0, self.end)), np.nan, 0.0, sc, False)
        self.proved = {}
        self.deferred = set()
        self.woken = set()  # gap edges that woke a deferred point already
        self.band_tried = []  # gaps (a, b) whose band scalings were tried

    def try_bands(self, gaps) -> bool:
        """For each gap ``(a, b)`` with ``b <= BAND_RATIO a`` not tried before: scalings chosen
        for its whole band (``solve.band``, :func:`band_scalings`) added as a point at its
        middle when their bound over the band is below the level (its interval is tested like
        any other's); True if any was added. Nothing without ``solve.band``."""
        band = getattr(self.solve, "band", None)
        if band is None:
            return False
        added = False
        for a, b in gaps:
            if not (a > 0 and np.isfinite(b) and b <= BAND_RATIO * a):
                continue
            if any(lo <= a and b <= hi for lo, hi in self.band_tried):
                continue
            self.band_tried.append((a, b))
            w = np.geomspace(a, b, BAND_POINTS)
            bound, sc = band(w, self.level)
            if sc is None or not bound < self.level:
                continue
            self._append(float(np.sqrt(a * b)), bound, bound, sc, True)
            added = True
        return added

    def _append(self, omega, optimal, level_min, scalings, added):
        self.omega.append(omega)
        self.opt.append(optimal)
        self.lmin.append(level_min)
        self.scs.append(scalings)
        self.added.append(added)

    def in_no_gap(self, w) -> bool:
        """True if ``w`` lies in no (closed) gap of the intervals proved so far."""
        spans = np.array([self.proved[j][1] for j in self.proved if j not in self.deferred])
        return not any(a <= w <= b for a, b in _gaps(spans.reshape(-1, 2), self.end))

    def test(self, i):
        """The interval of point ``i`` at the current level."""
        self.deferred.discard(i)
        interval = _interval_at(
            self.real, self.performance_rows, self.scs[i], self.level, self.omega[i]
        )
        self.proved[i] = (self.level, interval)

    def test_pending(self):
        """Test (or, lazily, skip) the points not tested yet, the prior points first (the
        neighbour's cover: wide intervals)."""
        pending = [i for i in range(len(self.omega)) if i not in self.proved]
        first, last = self.first_prior, self.first_prior + self.n_prior
        pending.sort(key=lambda i: (i < first or i >= last, i))
        for i in pending:
            if self.lazy and self.in_no_gap(self.omega[i]):
                self.deferred.add(i)
                self.proved[i] = (self.level, (np.nan, np.nan))
            else:
                self.test(i)

    def gaps(self) -> list:
        """The pieces of ``[0, end]`` the intervals proved so far leave uncovered."""
        spans = np.array([self.proved[i][1] for i in range(len(self.omega))])
        return _gaps(spans.reshape(-1, 2), self.end)

    def away_from_poles(self, gaps) -> list:
        """The gaps with no pole of ``M`` on the axis inside (the others never close)."""
        return [(a, b) for a, b in gaps if not np.any((self.stuck >= a) & (self.stuck <= b))]

    def wake(self, gaps) -> bool:
        """Test the deferred point nearest to each gap edge (each edge once); True if any."""
        rows = np.array(sorted(self.deferred), dtype=int)
        if not rows.size:
            return False
        w = np.asarray(self.omega, dtype=float)[rows]
        chosen = set()
        for a, b in gaps:
            for edge, side in ((a, w < a), (b, w > b)):
                if edge in self.woken or not np.any(side) or not np.isfinite(edge):
                    continue
                self.woken.add(edge)
                near = rows[side][np.argmin(np.abs(w[side] - edge))]
                chosen.add(int(near))
        for i in sorted(chosen):
            self.test(i)
        return bool(chosen)

    def test_deferred(self) -> bool:
        """Test every lazily skipped point (before giving up); True if there was one."""
        if not self.deferred:
            return False
        for i in sorted(self.deferred):
            self.test(i)
        return True

    def take_known(self, gaps) -> bool:
        """Add the known points in ``gaps`` that may prove the level (:meth:`_Spare.take`);
        True if any."""
        take = self.spare.take(gaps, self.level / (1.0 + self.slack))
        for w, o, sc in take:
            self._append(w, o, o * (1.0 + self.slack), sc, False)
        return bool(take)

    def new_points(self, gaps, retry_prior: bool) -> np.ndarray:
        """Frequencies to solve in ``gaps`` (:func:`_new_points`), not again where a point was
        solved or proved an interval (a known or prior point whose scalings proved nothing
        there does not stop a solve at its frequency).

        ``retry_prior`` (the first round of a cover with ``prior``): also the prior points in
        the gaps whose scalings prove nothing here (a band where mu is close to the level:
        they covered it on the neighbouring model), all together, instead of one gap edge per
        round."""
        tried = [
            w
            for i, w in enumerate(self.omega)
            if self.added[i] or i in self.deferred or np.isfinite(self.proved[i][1][0])
        ]
        new = _new_points(gaps, self.end, tried, self.edge_widths(gaps))
        if retry_prior:
            retry = np.array(
                [
                    self.omega[i]
                    for i in range(self.first_prior, self.first_prior + self.n_prior)
                    if i not in self.deferred
                    and not np.isfinite(self.proved[i][1][0])
                    and any(a <= self.omega[i] <= b for a, b in gaps)
                ]
            )
            new = np.union1d(new, retry)
        return new

    def edge_widths(self, gaps) -> list:
        """Per gap ``(a, b)``, the log-widths [-] of the widest proved intervals ending at
        ``a`` and starting at ``b`` (NaN where there is none, or it has an end at 0 or
        infinity)."""
        spans = np.array([self.proved[i][1] for i in self.proved]).reshape(-1, 2)
        spans = spans[np.all(np.isfinite(spans), axis=1) & (spans[:, 0] > 0)]
        out = []
        for a, b in gaps:
            left, right = spans[spans[:, 1] == a], spans[spans[:, 0] == b]
            la = float(np.max(np.log(left[:, 1] / left[:, 0]))) if left.size else np.nan
            lb = float(np.max(np.log(right[:, 1] / right[:, 0]))) if right.size else np.nan
            out.append((la, lb))
        return out

    def solve_points(self, new):
        """Solve the points ``new`` and add them; the level rises to what they need."""
        o2, l2, s2 = self.solve(new)
        self.omega.extend(new.tolist())
        self.opt.extend(list(o2))
        self.lmin.extend(list(l2))
        self.scs.extend(list(s2))
        self.added.extend([True] * new.size)
        self.level = max(self.level, max(l2))

    def certificate(self, covered: bool, rounds: int) -> AxisCertificate:
        """The :class:`AxisCertificate` of the points tested (by frequency); when the cover
        did not close, its gaps and why (what stopped the points inside them, once each)."""
        order = [i for i in np.argsort(self.omega, kind="stable") if i in self.proved]
        spans = np.array([self.proved[i][1] for i in order]).reshape(-1, 2)
        levels = np.array([self.proved[i][0] for i in order], dtype=float)
        left = () if covered else tuple((float(a), float(b)) for a, b in _gaps(spans, self.end))
        why = set()  # dg_interval's errors at the points inside the gaps
        for w, sc in zip(self.omega, self.scs, strict=True):
            if not covered and sc is not None and any(a <= w <= b for a, b in left):
                r, beta = _level_problem(self.real, self.performance_rows, self.level)
                try:
                    dg_interval(r, sc, beta, w)
                except ValueError as err:
                    why.add(str(err).replace("dg_interval: ", "").split(" at omega")[0])
        reason = ""
        if not covered:
            reason = _why_open(left, self.stuck, self.level, rounds, self.real, why)
        return AxisCertificate(
            upper=float(np.max(levels)) if covered else np.inf,
            omega=np.asarray(self.omega)[order],
            optimal=np.asarray(self.opt, dtype=float)[order],
            level=levels,
            interval=spans,
            added=np.asarray(self.added)[order],
            scalings=tuple(self.scs[i] for i in order),
            slack=self.slack,
            covered=covered,
            realization=self.real,
            performance_rows=self.performance_rows,
            reason=reason,
            gaps=left,
        )


def _why_open(gaps, stuck, level, rounds, real, why=()) -> str:
    """The ``reason`` of a cover that did not close (one line)."""
    where = ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in gaps[:4])
    where += " ..." if len(gaps) > 4 else ""
    if stuck.size:
        axis = "imaginary axis" if real.sample_time is None else "unit circle"
        poles = ", ".join(f"{w:.6g}" for w in stuck[:4])
        return (
            f"not proved on {where} rad/s: M has a pole on the {axis} at omega = {poles} "
            "rad/s (M unbounded there: the loop is not stable at nominal)"
        )
    if not np.isfinite(level):
        return (
            f"not proved on {where} rad/s: no finite level there (the bound is infinite: "
            "I - M Delta singular for every size, or an ill-posed LFR)"
        )
    detail = f" ({'; '.join(sorted(why))})" if why else ""
    return (
        f"not proved on {where} rad/s at level {level:.6g}: {rounds} rounds of added points "
        f"found no scalings that prove it there{detail}"
    )


class _Spare:
    """Known points of :func:`cover_axis` not used yet (``known``), sorted by frequency."""

    def __init__(self, known, used):
        if known is None:
            self.omega, self.optimal, self.scalings = np.zeros(0), np.zeros(0), []
            return
        w, o, sc = known
        w, o, used = (np.asarray(x, dtype=float).ravel() for x in (w, o, used))
        keep = np.isfinite(o)  # a point solved already (a seed) is not tried twice
        if used.size and w.size:
            dist = np.min(np.abs(w[:, None] - used[None, :]), axis=1)
            keep &= dist > 1e-12 * np.maximum(w, 1e-300)
        rows = np.flatnonzero(keep)[np.argsort(w[keep], kind="stable")]
        self.omega, self.optimal = w[rows], o[rows]
        # a callable gives the scalings (and their exact bound) of the points taken only
        self.source = sc if callable(sc) else None
        self.scalings = list(rows) if callable(sc) else [sc[i] for i in rows]

    def take(self, gaps, below: float) -> list:
        """``(omega, optimal, scalings)`` of the unused known points nearest to each edge of
        each gap (inside it) whose bound is at most ``below`` (the others cannot prove the
        level); removed from the spares."""
        chosen = set()
        for a, b in gaps:
            inside = np.flatnonzero((self.omega >= a) & (self.omega <= b) & (self.optimal <= below))
            if inside.size:
                chosen.update((int(inside[0]), int(inside[-1])))
        if not chosen:
            return []
        chosen = sorted(chosen)
        if self.source is None:
            out = [(float(self.omega[i]), float(self.optimal[i]), self.scalings[i]) for i in chosen]
        else:
            optimal, scalings = self.source(np.array([self.scalings[i] for i in chosen], int))
            out = [
                (float(self.omega[i]), float(o), sc)
                for i, o, sc in zip(chosen, optimal, scalings, strict=True)
            ]
        rest = np.setdiff1d(np.arange(self.omega.size), chosen)
        self.omega, self.optimal = self.omega[rest], self.optimal[rest]
        self.scalings = [self.scalings[i] for i in rest]
        return out


def scalings_at(real: Realization, blk, omega, params) -> tuple:
    """``(upper, scalings)`` of the raw D-G parameters ``params`` (``UpperBoundResult.params``
    of a sweep at the frequencies ``omega`` [rad/s]): the bound they give exactly at each
    frequency and the (conditioned) :class:`Scalings`, no optimization. For the ``known``
    points of :func:`cover_axis`."""
    omega = np.asarray(omega, dtype=float)
    if omega.size == 0:
        return np.zeros(0), []
    res = mu_upper_bound(real.response(omega), parse_blk(blk), max_iter=0, x0=np.asarray(params))
    scalings = [
        proving_scalings(
            real, Scalings(res.D_left[i], res.D_right[i], res.G[i]), res.upper[i] * (1 + SLACK), w
        )
        for i, w in enumerate(omega)
    ]
    return res.upper, scalings


def _interval_at(real, performance_rows, sc, level, omega0):
    """:func:`dg_interval` at ``level``; an empty (NaN) interval where it cannot be proved
    (e.g. ``Phi(inf)`` singular at exactly this level): the cover then adds points there."""
    if not np.isfinite(level) or sc is None:
        return (np.nan, np.nan)
    r, beta = _level_problem(real, performance_rows, level)
    try:
        return dg_interval(r, sc, beta, omega0)
    except ValueError:
        return (np.nan, np.nan)


#: Long runs of the upper bound for the points that would raise the level (their bound decides
#: the result). Converged settings: with the grid's budget (100 iterations, tol 2e-4) the
#: bound stops 10-40 % above the converged D-G value on the mission's total subset near its
#: peak, by different amounts on equal ``M`` in different channel bases (Drake vs TITOP);
#: these runs agree within 0.5 %.
POLISH_OPTIONS = dict(
    max_iter=2000, tol=1e-9, patience=5, temperatures=(30.0, 300.0, 3000.0, 30000.0)
)
#: The short first polish run of :func:`mu_solver` with ``lazy_polish`` (about a seventh of
#: the cost of :data:`POLISH_OPTIONS` on the paper's covers): enough for most points to drop
#: below the level; the others continue with the long run.
QUICK_POLISH_OPTIONS = dict(max_iter=150, tol=1e-6, patience=3, temperatures=(30.0, 300.0, 3000.0))
#: Restarts of the long run (:data:`POLISH_OPTIONS`) from the best scalings reached, for the
#: points that still raise a cover's level after every start of :func:`mu_solver` (their bound
#: IS the guaranteed level). The optimizer stalls in the non-smooth valleys of the D-G bound at
#: places that depend on the round-off of ``M`` (a relative 1e-15 change of ``M`` raised the
#: guaranteed level of the paper's total subset, 8 configurations, by 1.7 %); a restart
#: resets the L-BFGS memory and the smoothing, and usually goes on descending. The restarts
#: stop at the first that gains less than :data:`CONVERGE_GAIN` (relative).
CONVERGE_RESTARTS = 8
#: Relative decrease of a point's bound below which :data:`CONVERGE_RESTARTS` stop.
CONVERGE_GAIN = 1e-6


#: First run of a point of :func:`mu_solver` from the scalings of the nearest point solved
#: before (the continuation stage of a sweep's grid, ``mussv``'s iterations and tolerance).
WARM_OPTIONS = dict(
    max_iter=UPPER_ITERATIONS,
    tol=UPPER_TOL,
    temperatures=(CONTINUATION_TEMPERATURE,),
    patience=CONTINUATION_PATIENCE,
)


def mu_solver(
    real: Realization,
    blk,
    *,
    slack: float = SLACK,
    polish_above: float = 0.0,
    starts=None,
    lazy_polish: bool = True,
    converge: bool = True,
):
    """The ``solve`` of :func:`cover_axis` for ``mu(M(j omega))`` (D-G bound of ``mussv``).

    Points whose bound exceeds ``polish_above`` get long optimizer runs (:data:`POLISH_OPTIONS`)
    from their own scalings, then, for those still above, from those of the nearest point
    solved before or given in ``starts`` (the scalings of a neighbouring frequency are often a
    better start than a cold one, near lightly damped modes), and, for those still above, from
    the nearest point of the same batch; each keeps the lowest of its bounds (each exact at its
    scalings). A point at or below ``polish_above`` after a run gets no further run: it proves
    the level already.

    ``converge`` (default): the points still above ``polish_above`` after all of them raise the
    cover's level: their bound is the guaranteed level, so it is converged as far as the
    optimizer goes: a long run from a cold start (``mussv``'s bound from Osborne balancing)
    too, then long runs restarted from the best scalings reached (:data:`CONVERGE_RESTARTS`)
    until one gains less than :data:`CONVERGE_GAIN`. The lowest bound wins (each is exact at
    its scalings and proves its own level): the level no longer follows where the round-off of
    ``M`` made one run stall.
    It does not make the level reproducible to six digits: the optimizer's end points still
    differ by 1e-5 to 2e-3 (relative) on points of the paper's total subset where a relative
    1e-15 change of ``M`` moves them (``tests/robust/test_mu_converge.py``). False: the solver
    before this stage (the reference of ``benchmarks/bench_guarantee_levels.py --before``).

    ``starts`` : ``(omega, params)`` raw D-G parameters at frequencies [rad/s] (e.g. a grid
    sweep's ``UpperBoundResult.params``), extra warm starts only.

    The first run of each point starts from the scalings of the nearest point solved before
    or given in ``starts`` where they beat Osborne balancing (:data:`WARM_OPTIONS`; ``mussv``'s
    cold run when there is none): any scalings give an exact bound at their point, so the
    start changes the cost and the bound's value, never its validity.

    ``lazy_polish`` (default): the threshold is also the level already reached, over
    ``1 + slack``: the largest ``level_min`` this solver returned so far and, within a call,
    that of its highest point, polished first. A point at or below that threshold cannot raise
    the cover's level (its ``level_min`` is at most the level), and its scalings are tested at
    the level like any other's: polishing it would only make its interval wider, at the price
    of a long optimizer run. And the first polish run of each point is a short one
    (:data:`QUICK_POLISH_OPTIONS`): only the points still above the threshold after it get the
    long run, from where it stopped. False: the fixed ``polish_above`` and long runs only (the
    cost reference of ``benchmarks/bench_axis_guarantee.py``).

    The solver keeps the points it solved (its warm starts).
    """
    return _MuSolver(real, blk, slack, polish_above, starts, lazy_polish, converge)


class _MuSolver:
    """State of one :func:`mu_solver`: the problem and the points solved so far."""

    def __init__(self, real, blk, slack, polish_above, starts, lazy_polish=True, converge=True):
        self.real, self.structure = real, parse_blk(blk)
        self.converge = bool(converge)
        self.slack, self.polish_above = float(slack), float(polish_above)
        self.lazy_polish = bool(lazy_polish)
        self.reached = 0.0  # largest level_min returned so far (lazy_polish)
        self.solved_omega, self.solved_params = [], []  # for warm starts
        if starts is not None:
            self.solved_omega.extend(np.asarray(starts[0], dtype=float).tolist())
            self.solved_params.extend(list(np.asarray(starts[1])))

    def __call__(self, omega):
        """``(optimal, level_min, scalings)`` at the frequencies ``omega`` [rad/s] (see
        :func:`cover_axis`)."""
        omega = np.asarray(omega, dtype=float).reshape(-1)
        M = self.real.response(omega)
        if self.solved_omega:
            # from the scalings of the nearest point solved before or given (a gap's edge is
            # where a neighbour's scalings stop proving the level: its optimum is close), where
            # they start lower than the balancing: a continuation run, as along a sweep
            x0 = np.array([self._nearest_start(w) for w in omega])
            res = mu_upper_bound(M, self.structure, x0=x0, **WARM_OPTIONS)
        else:
            res = _upper_bound(M, self.structure, UPPER_ITERATIONS, UPPER_TOL)  # mussv's bound
        upper, params = res.upper.copy(), res.params.copy()
        Dl, Dr, G = res.D_left.copy(), res.D_right.copy(), res.G.copy()
        state = (M, omega, upper, params, Dl, Dr, G)
        above = self.polish_above
        if self.lazy_polish:
            above = max(above, self.reached / (1.0 + self.slack))
            redo = np.flatnonzero(upper > above)
            if redo.size > 1:  # the highest point first: a level the rest need not beat
                top = redo[np.argmax(upper[redo])]
                self._polish(state, np.array([top]), above)
                above = max(above, float(upper[top]))
                redo = redo[redo != top]
        else:
            redo = np.flatnonzero(upper > above)
        self._polish(state, redo, above)
        self.solved_omega.extend(omega.tolist())
        self.solved_params.extend(list(params))
        scalings = [
            proving_scalings(
                self.real, Scalings(Dl[i], Dr[i], G[i]), upper[i] * (1 + self.slack), w
            )
            for i, w in enumerate(omega)
        ]
        self.reached = max(self.reached, float(np.max(upper, initial=0.0)) * (1.0 + self.slack))
        return upper, upper * (1.0 + self.slack), scalings

    def _polish(self, state, redo, above):
        """Long optimizer runs for the rows ``redo`` whose bound is above ``above``: from their
        own scalings, then the nearest point solved before, then the nearest of the batch, then
        a cold start, then restarts from the best (:data:`CONVERGE_RESTARTS`); ``upper, params,
        Dl, Dr, G`` of ``state`` updated in place where a run is better."""
        M, omega, upper, params, Dl, Dr, G = state
        starts = ("own", "known", "batch", "cold") if self.converge else ("own", "known", "batch")
        for start in starts:
            # each further start only for the points still above: a point at or below
            # ``polish_above`` proves the level already, a lower bound there changes nothing
            redo = redo[upper[redo] > above]
            if start == "own":
                rows, x0 = redo, params[redo]
                if self.lazy_polish and rows.size:  # a short run first, the long one if needed
                    self._keep_better(state, rows, x0, QUICK_POLISH_OPTIONS)
                    rows = rows[upper[rows] > above]
                    x0 = params[rows]
            elif start == "known":  # the nearest point solved before
                rows = redo if self.solved_omega else redo[:0]
                x0 = [self._nearest_start(omega[i]) for i in rows]
            elif start == "batch":  # the nearest other point of the same call
                rows = redo if omega.size > 1 else redo[:0]
                dist = np.abs(np.log1p(omega[None, :]) - np.log1p(omega[rows, None]))
                dist[np.arange(omega.size) == rows[:, None]] = np.inf
                x0 = params[np.argmin(dist, axis=1)] if rows.size else []
            else:  # they would raise the level: from a cold start too (mussv's first run)
                rows = redo
                cold = _upper_bound(M[rows], self.structure, UPPER_ITERATIONS, UPPER_TOL)
                x0 = cold.params if rows.size else []
            if rows.size:
                self._keep_better(state, rows, x0, POLISH_OPTIONS)
        # still above: their bound is the level; restarts from the best scalings reached
        for _ in range(CONVERGE_RESTARTS if self.converge else 0):
            redo = redo[upper[redo] > above]
            if not redo.size:
                break
            before = upper[redo].copy()
            self._keep_better(state, redo, params[redo], POLISH_OPTIONS)
            redo = redo[upper[redo] < before * (1.0 - CONVERGE_GAIN)]

    def _keep_better(self, state, rows, x0, options):
        """One optimizer run (``options``) of the rows ``rows`` from ``x0``; each keeps its
        result where it is lower and proves its own level (``state`` updated in place)."""
        M, omega, upper, params, Dl, Dr, G = state
        more = mu_upper_bound(M[rows], self.structure, x0=np.asarray(x0), **options)
        # a point is only as good as the certificate the interval test accepts: converged
        # scalings can be too close to singular for a strict LMI at the level
        better = np.array(
            [
                more.upper[j] < upper[i]
                and _proves(self.real, Scalings(more.D_left[j], more.D_right[j], more.G[j]),
                            more.upper[j] * (1.0 + self.slack), omega[i])
                for j, i in enumerate(rows)
            ],
            dtype=bool,
        )  # fmt: skip
        rows = rows[better]
        upper[rows], params[rows] = more.upper[better], more.params[better]
        Dl[rows], Dr[rows], G[rows] = more.D_left[better], more.D_right[better], more.G[better]

    def band(self, omega, level):
        """``(bound, scalings)``: :func:`band_scalings` on the frequencies ``omega`` [rad/s]
        from the points solved before inside them and the nearest one, conditioned
        (:func:`proving_scalings`) at their middle and ``level``; ``(inf, None)`` without a
        point solved before."""
        if not self.solved_omega:
            return np.inf, None
        known = np.asarray(self.solved_omega, dtype=float)
        mid = float(np.sqrt(omega[0] * omega[-1]))
        rows = set(np.flatnonzero((known >= omega[0]) & (known <= omega[-1])).tolist())
        rows.add(int(np.argmin(np.abs(np.log1p(known) - np.log1p(mid)))))
        starts = [(known[i], self.solved_params[i]) for i in sorted(rows)]
        bound, sc, _ = band_scalings(self.real, self.structure, omega, starts)
        return bound, proving_scalings(self.real, sc, level, mid)

    def _nearest_start(self, omega: float) -> np.ndarray:
        """Parameters of the point nearest to ``omega`` (log scale) solved before."""
        known = np.asarray(self.solved_omega, dtype=float)
        return self.solved_params[int(np.argmin(np.abs(np.log1p(known) - np.log1p(omega))))]


def _proves(real: Realization, sc: Scalings, beta: float, omega: float) -> bool:
    """True if the conditioned scalings prove ``mu <= beta`` strictly at ``omega`` [rad/s]."""
    return _proves_as_is(real, proving_scalings(real, sc, beta, omega), beta, omega)


def _proves_as_is(real: Realization, sc: Scalings, beta: float, omega: float) -> bool:
    """True if the scalings, as they are, prove ``mu <= beta`` strictly at ``omega``."""
    if not np.isfinite(beta):
        return False
    try:
        mult = _Multiplier(real, sc, beta)
    except np.linalg.LinAlgError:
        return False
    return bool(mult.max_eig([float(real.to_nu(omega))])[0] < -STRICT)


def proving_scalings(real: Realization, sc: Scalings, beta: float, omega: float) -> Scalings:
    """``sc`` conditioned (:meth:`Scalings.conditioned`) with the first ``spread`` of
    :data:`SPREAD_FLOORS` whose scalings prove ``mu <= beta`` strictly at ``omega`` [rad/s] on
    ``real`` (with ``performance_rows`` already divided out: see :func:`_level_problem`); the
    first one if none does (the cover then proves no interval there and bisects).
    """
    first = sc.conditioned(spread=SPREAD_FLOORS[0])
    if _proves_as_is(real, first, beta, omega):  # the usual case: one evaluation of Phi
        return first
    for spread in SPREAD_FLOORS[1:]:
        out = sc.conditioned(spread=spread)
        if _proves_as_is(real, out, beta, omega):
            return out
    return first


#: Frequencies of a band of :func:`band_scalings` chosen by the cover (``cover_axis(bands=
#: True)``), from edge to edge of a gap (log-spaced).
BAND_POINTS = 3
#: Widest gap ``(a, b)``, ``b / a``, on which ``cover_axis(bands=True)`` tries scalings chosen
#: for the whole gap (:func:`band_scalings`) before solving points in it. One D-G scaling
#: proves little beyond a single frequency's interval here: on the make-run mission's total
#: subset the bound of fixed scalings rises about 1 % per 1 % of frequency near 0.8 Hz, and the
#: best common scalings of 0.78-0.86 Hz give 0.3987 at the band's ends against a level of
#: 0.3845 (those optimal at 0.82 Hz: 0.381 there).
BAND_RATIO = 1.03
#: Smoothing temperatures of :func:`band_scalings`, relative to the band's ``lambda_max``.
BAND_TEMPERATURES = (300.0, 3000.0)
#: L-BFGS iterations per temperature stage of :func:`band_scalings`.
BAND_ITERATIONS = 20


def band_scalings(real: Realization, blk, omega, starts) -> tuple:
    r"""One D-G scaling for several frequencies: ``min max_k beta(M(j omega_k))`` over common
    scalings.

    The bound of fixed scalings at one frequency is ``beta_k^2 = lambda_max(H_k)``, ``H_k =
    T_r^{-*} [M_k^* D_l M_k + j (G M_k - M_k^* G^*)] T_r^{-1}`` (:mod:`~oos_drake.robust.
    mu_upper`); for common ``(T, G)`` the largest over the band is ``lambda_max`` of the block
    diagonal of the ``H_k``, which is minimized as the single-frequency bound is: the
    log-sum-exp of all the eigenvalues of all the ``H_k`` (one temperature, raised in stages,
    :data:`BAND_TEMPERATURES`), by L-BFGS, from the best of ``starts`` (scalings of single
    frequencies, e.g. the points solved nearby). The ``M_k`` are divided by one common size (the
    largest ``||M_k||_F``) so that their eigenvalues compare.

    Nothing here is a proof: the scalings are a candidate for :func:`dg_interval`, whose
    Hamiltonian test decides on which frequencies they prove a level (in a band where mu stays
    close to the level, one candidate may prove an interval several times wider than the
    scalings optimal at any single frequency).

    Parameters
    ----------
    real : Realization
        Realization of ``M``.
    blk : array_like or BlockStructure
        Block structure (``mussv``'s BLK).
    omega : array_like
        ``(K,)`` frequencies of the band [rad/s].
    starts : sequence of tuple
        ``(omega_i, params_i)``: raw D-G parameters found at ``omega_i`` [rad/s]
        (``UpperBoundResult.params``), starting candidates; at least one.

    Returns
    -------
    tuple
        ``(bound, scalings, upper)``: ``bound`` the largest of ``upper``, ``(K,)`` the bound the
        scalings give at each frequency (evaluated, not certified), and the
        (unconditioned) :class:`Scalings`.
    """
    from scipy.optimize import minimize

    from oos_drake.robust.mu_upper import _finish, _layout, _Objective

    omega = np.asarray(omega, dtype=float).reshape(-1)
    structure = parse_blk(blk) if not hasattr(blk, "blocks") else blk
    M = real.response(omega)
    size = float(np.max(np.linalg.norm(M, axis=(1, 2)))) + 1e-300
    layout = _layout(structure)
    obj = _Objective(M / size, structure, layout)
    rows, K = np.arange(omega.size), omega.size
    g = layout.g_par
    # each start's G is in units of its own ||M(j omega_i)||_F: to the common size
    candidates = []
    for w, p in starts:
        x = np.array(p, dtype=float)
        x[g] *= float(np.linalg.norm(real.response([w])[0])) / size
        candidates.append(x)
    lam = [float(np.max(obj(np.tile(x, (K, 1)), rows, np.ones(K), False)[2])) for x in candidates]
    x = candidates[int(np.argmin(lam))]
    best_x, best = x, float(np.min(lam))

    def band(x, t):
        f, grad, lmax, _ = obj(np.tile(x, (K, 1)), rows, np.full(K, t))
        top = float(np.max(f))
        w = np.exp(t * (f - top))
        return top + np.log(np.sum(w)) / t, (w / np.sum(w)) @ grad, float(np.max(lmax))

    for temp in BAND_TEMPERATURES:
        t = temp / max(best, 1e-300)
        seen = {}

        def fun(x, t=t, seen=seen):
            value, grad, top = band(x, t)
            if top < seen.get("best", np.inf):
                seen["best"], seen["x"] = top, x.copy()
            return value, grad

        minimize(fun, x, jac=True, method="L-BFGS-B", options=dict(maxiter=BAND_ITERATIONS))
        if seen.get("best", np.inf) < best:
            best, best_x = seen["best"], seen["x"]
        x = best_x
    upper, Dl, Dr, G, _, _ = _finish(obj, np.tile(best_x, (K, 1)), rows, np.full(K, size))
    return float(np.max(upper)), Scalings(Dl[0], Dr[0], G[0]), upper
