"""Exact rigid-body realization of a cantilevered flexible appendage (no pydrake needed).

Drake has no modal flexible body. A one-port appendage with rigid spatial inertia ``D_P`` at its
root point ``P`` and modes ``(w_i, xi_i, l_i)`` has the effective-mass transfer (TITOP one-port)

.. math::

    M_P(s) = D_{P0} + \\sum_i l_i l_i^T
             \\frac{2 \\xi_i w_i s + w_i^2}{s^2 + 2 \\xi_i w_i s + w_i^2},
    \\qquad D_{P0} = D_P - \\sum_i l_i l_i^T .

It is realized *exactly* (in the linear sense) by rigid bodies:

- one **mode body** per mode, on a revolute joint hinged to the appendage's root body, with a
  torsional spring ``k_i^2 w_i^2`` and a joint damping ``2 xi_i w_i k_i^2``; its spatial inertia
  about ``P`` ``M_i`` and its joint twist at ``P`` ``H_i`` satisfy ``M_i H_i = k_i l_i`` and
  ``H_i^T M_i H_i = k_i^2`` (so the modal coordinate is ``eta_i = k_i q_i``);
- the **root body** carries the rest, ``D_P - sum_i M_i``, so that the whole appendage has
  exactly the rigid inertia ``D_P``.

Derivation: the mode body obeys ``H^T M (xdd_P + H qdd) = -k^2 w^2 q - 2 xi w k^2 qd``, i.e.
``eta'' + 2 xi w eta' + w^2 eta = -l^T xdd_P``, and pushes on the root with
``-(M xdd_P + l eta'')``; eliminating ``eta`` gives ``W = -M_P(s) xdd_P``. The linearized mass
matrix in coordinates ``(x_P, q)`` is ``[[D_P, K L], [L^T K, K^2]]`` whose Schur complement is
``D_P0``: it is positive definite exactly when ``D_P0`` is, whatever mode bodies are chosen.

The catch (MODELING-NOTES section 5): a mode body with translational participation ``a_i``
needs a mass above ``|a_i|^2``; for the paper's chaser arrays ``sum |a_i|^2 ~ 146 kg > 88.93 kg``,
so the root's inertia ``D_P - sum M_i`` is not a physical rigid-body inertia. The realization
keeps it anyway (Drake needs ``skip_validity_check=True``) and the assembled mass matrix is
checked to stay positive definite. Construction of a mode body (``l = [a; b]``):

- axis ``n`` unit, ``n . a = 0``; centre of mass ``r`` chosen so that ``b_e = b - r x a`` has a
  component along ``n`` (``r = 0`` unless ``b`` is almost parallel to ``a``);
- mass ``m = max(mass_factor |a|^2, minimum_mass)``; scale ``k = (n . b_e) / (1 - |a|^2 / m)``;
- axis through ``c = r + (k / m) n x a`` (so the translational part of ``M H`` is ``k a``);
- central inertia ``J = g g^T / (n . g) + alpha (I - n n^T)``, ``g = k b_e``, with ``alpha``
  large enough for the triangle inequalities.

All vectors are in the appendage frame ``R_SA`` (origin ``P``); 6-vectors are
``[translation; rotation]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.titop.spatial import rigid_spatial_inertia, skew

__all__ = [
    "ModeBody",
    "ModalRealization",
    "realize_appendage",
    "realize_mode",
    "is_physical_spatial_inertia",
]


@dataclass(frozen=True)
class ModeBody:
    """A rigid body on a revolute joint that realizes one flexible mode.

    Attributes
    ----------
    mass : float
        Mass [kg].
    p_PScm : numpy.ndarray, shape (3,)
        Centre of mass from ``P`` in ``R_SA`` [m].
    I_Scm : numpy.ndarray, shape (3, 3)
        Central inertia in ``R_SA`` axes [kg m^2] (a valid rigid-body inertia).
    p_PA : numpy.ndarray, shape (3,)
        A point of the joint axis from ``P`` in ``R_SA`` [m].
    axis : numpy.ndarray, shape (3,)
        Unit joint axis in ``R_SA``.
    scale : float
        ``k``: modal coordinate ``eta = k q`` [sqrt(kg) m per rad].
    stiffness : float
        Joint spring ``k^2 w^2`` [N m/rad].
    damping : float
        Joint damping ``2 xi w k^2`` [N m s/rad].
    frequency : float
        Cantilever natural frequency ``w`` [rad/s].
    damping_ratio : float
        ``xi`` [-].
    participation : numpy.ndarray, shape (6,)
        ``l`` [sqrt(kg), sqrt(kg) m].
    """

    mass: float
    p_PScm: np.ndarray
    I_Scm: np.ndarray
    p_PA: np.ndarray
    axis: np.ndarray
    scale: float
    stiffness: float
    damping: float
    frequency: float
    damping_ratio: float
    participation: np.ndarray

    @property
    def spatial_inertia(self) -> np.ndarray:
        """``M_i``: 6x6 spatial inertia about ``P`` [kg, kg m, kg m^2]."""
        return rigid_spatial_inertia(self.mass, self.I_Scm, self.p_PScm)

    @property
    def twist(self) -> np.ndarray:
        """``H_i``: joint twist at ``P`` per unit joint rate, ``[c x n; n]``."""
        return np.concatenate([np.cross(self.p_PA, self.axis), self.axis])


@dataclass(frozen=True)
class ModalRealization:
    """Rigid-body realization of one appendage.

    Attributes
    ----------
    D_P : numpy.ndarray, shape (6, 6)
        Rigid spatial inertia of the whole appendage at ``P`` (``M_P(0)``).
    modes : tuple of ModeBody
        One body per flexible mode.
    residual_inertia : numpy.ndarray, shape (6, 6)
        ``D_P - sum M_i``: what the root body must carry (may be non-physical).
    """

    D_P: np.ndarray
    modes: tuple[ModeBody, ...]
    residual_inertia: np.ndarray

    @property
    def residual_is_physical(self) -> bool:
        """True if ``residual_inertia`` is a valid rigid-body spatial inertia."""
        return is_physical_spatial_inertia(self.residual_inertia)


def is_physical_spatial_inertia(inertia: np.ndarray, tol: float = 1e-12) -> bool:
    """Return True if a 6x6 ``[trans; rot]`` spatial inertia is that of a real rigid body.

    Checks mass > 0, the ``m I3`` structure, and the central inertia's principal moments
    (non-negative, triangle inequalities), with relative tolerance ``tol``.
    """
    inertia = np.asarray(inertia, dtype=float)
    mass = inertia[0, 0]
    if not mass > 0:
        return False
    if not np.allclose(inertia[:3, :3], mass * np.eye(3), atol=tol * mass):
        return False
    r = inertia[3:, :3] / mass  # m [r]x / m
    p = np.array([r[2, 1], r[0, 2], r[1, 0]])
    central = inertia[3:, 3:] + mass * skew(p) @ skew(p)
    moments = np.linalg.eigvalsh(0.5 * (central + central.T))
    scale = max(abs(moments).max(), 1.0) * tol
    if moments.min() < -scale:
        return False
    a, b, c = np.sort(moments)
    return a + b >= c - scale


def _unit_perpendicular(vector: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``vector`` (any, deterministic)."""
    trial = np.eye(3)[int(np.argmin(abs(vector)))]
    out = np.cross(vector, trial)
    return out / np.linalg.norm(out)


def realize_mode(
    participation: np.ndarray,
    frequency: float,
    damping_ratio: float,
    *,
    mass_factor: float = 1.5,
    minimum_mass: float = 0.01,
    name: str = "mode",
) -> ModeBody:
    """Build the mode body of one flexible mode (see the module docstring).

    Parameters
    ----------
    participation : array_like, shape (6,)
        ``l_i = [a; b]`` [sqrt(kg), sqrt(kg) m].
    frequency : float
        ``w_i`` [rad/s], > 0.
    damping_ratio : float
        ``xi_i`` [-], >= 0.
    mass_factor : float
        Mode-body mass in units of ``|a|^2`` (> 1).
    minimum_mass : float
        Mass floor [kg] for modes with little translational participation.
    name : str
        Used in error messages.
    """
    l = np.asarray(participation, dtype=float).reshape(6)
    if not np.all(np.isfinite(l)) or np.linalg.norm(l) == 0.0:
        raise ValueError(f"{name}: participation vector must be finite and nonzero, got {l}")
    if not frequency > 0:
        raise ValueError(f"{name}: frequency must be > 0 rad/s, got {frequency}")
    if not damping_ratio >= 0:
        raise ValueError(f"{name}: damping ratio must be >= 0, got {damping_ratio}")
    if not mass_factor > 1:
        raise ValueError(f"{name}: mass_factor must be > 1, got {mass_factor}")
    a, b = l[:3], l[3:]
    a2 = float(a @ a)
    norm_l = float(np.linalg.norm(l))
    if a2 > 0:
        a_hat = a / np.sqrt(a2)
        b_perp = b - (b @ a_hat) * a_hat
    else:
        a_hat = None
        b_perp = b.copy()
    r = np.zeros(3)
    if np.linalg.norm(b_perp) > 1e-3 * norm_l:
        n = b_perp / np.linalg.norm(b_perp)
        b_eff = b
    else:
        # b (almost) parallel to a: move the centre of mass so that b - r x a gains a
        # component beta n perpendicular to a.
        n = _unit_perpendicular(a)
        beta = norm_l
        r = np.cross(a, b_perp - beta * n) / a2
        b_eff = b - np.cross(r, a)
    mass = max(mass_factor * a2, minimum_mass)
    projection = float(n @ b_eff)
    scale = projection / (1.0 - a2 / mass)
    p_PA = r + (scale / mass) * np.cross(n, a)
    g = scale * b_eff
    rank_one = np.outer(g, g) / float(n @ g)
    alpha = float(g @ g) / float(n @ g)
    for _ in range(60):
        I_Scm = rank_one + alpha * (np.eye(3) - np.outer(n, n))
        if is_physical_spatial_inertia(rigid_spatial_inertia(mass, I_Scm)):
            break
        alpha *= 2.0
    else:  # pragma: no cover - the loop always succeeds for alpha large enough
        raise ValueError(f"{name}: could not build a valid mode-body inertia")
    return ModeBody(
        mass=float(mass),
        p_PScm=r,
        I_Scm=I_Scm,
        p_PA=p_PA,
        axis=n,
        scale=float(scale),
        stiffness=float(scale**2 * frequency**2),
        damping=float(2.0 * damping_ratio * frequency * scale**2),
        frequency=float(frequency),
        damping_ratio=float(damping_ratio),
        participation=l,
    )


def realize_appendage(
    D_P: np.ndarray,
    frequencies: np.ndarray,
    damping_ratios: np.ndarray,
    participations: np.ndarray,
    *,
    name: str = "appendage",
    mass_factor: float = 1.5,
) -> ModalRealization:
    """Realize a cantilevered flexible appendage by a root body and one body per mode.

    Parameters
    ----------
    D_P : array_like, shape (6, 6)
        Rigid spatial inertia of the appendage at ``P`` in ``R_SA`` [kg, kg m, kg m^2].
    frequencies : array_like, shape (N,)
        Cantilever natural frequencies ``w_i`` [rad/s].
    damping_ratios : array_like, shape (N,)
        ``xi_i`` [-].
    participations : array_like, shape (N, 6)
        Participation vectors, **rows = modes**, columns ``[Tx Ty Tz Rx Ry Rz]``.
    name : str
        Appendage name for error messages.

    Returns
    -------
    ModalRealization

    Raises
    ------
    ValueError
        If ``D_P0 = D_P - L L^T`` is not positive semi-definite (the modes carry more inertia
        than the appendage has), or a mode is invalid.
    """
    D_P = np.asarray(D_P, dtype=float)
    L = np.atleast_2d(np.asarray(participations, dtype=float))
    frequencies = np.atleast_1d(np.asarray(frequencies, dtype=float))
    damping_ratios = np.broadcast_to(np.asarray(damping_ratios, dtype=float), frequencies.shape)
    if D_P.shape != (6, 6) or L.shape != (frequencies.size, 6):
        raise ValueError(
            f"{name}: need D_P 6x6 and participations N x 6 (rows = modes), "
            f"got {D_P.shape} and {L.shape}"
        )
    D_P0 = D_P - L.T @ L
    min_eig = float(np.linalg.eigvalsh(0.5 * (D_P0 + D_P0.T)).min())
    if min_eig < -1e-9 * float(np.abs(D_P).max()):
        raise ValueError(
            f"{name}: residual mass D_P - L L^T is not positive semi-definite "
            f"(min eigenvalue {min_eig:.4g}); are the participation rows the modes?"
        )
    modes = tuple(
        realize_mode(
            L[i],
            frequencies[i],
            damping_ratios[i],
            mass_factor=mass_factor,
            name=f"{name} mode {i + 1}",
        )
        for i in range(frequencies.size)
    )
    residual = D_P - sum((mode.spatial_inertia for mode in modes), np.zeros((6, 6)))
    return ModalRealization(D_P=D_P, modes=modes, residual_inertia=residual)
