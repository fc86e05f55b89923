"""Named parameters of the TITOP blocks and their naming convention.

Block names become column names in campaign tables, so they are stable and descriptive:

==================  =====================================================  ===================
name                meaning                                                physical range
==================  =====================================================  ===================
``m_<body>``        mass of a rigid body                                   nominal +- percent
``Jxx_<body>``      diagonal inertia entries at the center of mass         nominal +- percent
``Jyy_<body>``
``Jzz_<body>``
``w1_<array>``      first cantilevered mode frequency of an appendage      nominal +- percent
                    [rad/s]
``tau_theta<i>``    ``tan(theta_i / 4)``, solar-array tilt angle theta_i   [-1, 1]
``tau_alpha<i>``    ``tan(alpha_i / 4)``, arm joint angle alpha_i          [-1, 1]
``delta_C<i>``      connection switch (0 open, 1 docked)                   [0, 1]
``k_shear_<SM>``    shear stiffness of a spring-damper [N/m]               see ``spring_damper``
``k_tors_<SM>``     torsional stiffness [N m/rad]
``d_shear_<SM>``    shear damping [N s/m]
``d_tors_<SM>``     torsional damping [N m s/rad]
==================  =====================================================  ===================

Scheduled parameters (``tau_*``, ``delta_C*``) are ordinary ``ureal`` blocks: they are
substituted with :func:`oos_drake.lfr.usubs`, not analyzed.
"""

from __future__ import annotations

import re

from oos_drake.lfr import ureal

__all__ = [
    "angle_parameter",
    "connection_parameter",
    "relative_parameter",
    "mass_name",
    "inertia_names",
    "mode_frequency_name",
    "check_name",
    "spring_damper_values",
]

_NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def check_name(name: str, what: str = "block name") -> str:
    """Return ``name`` if it is a valid block name (identifier-like), else raise ``ValueError``."""
    if not isinstance(name, str) or not _NAME_PATTERN.match(name):
        raise ValueError(f"{what}: {name!r} is not a valid name (letters, digits, underscores)")
    return name


def angle_parameter(name: str):
    """Scheduled angle parameter ``tau = tan(angle / 4)`` in ``[-1, 1]`` (nominal 0, angle 0).

    Parameters
    ----------
    name : str
        Block name, e.g. ``"tau_theta1"`` or ``"tau_alpha3"``.

    Returns
    -------
    LFR
        ``ureal`` of quantity ``"angle"``, unit ``"-"`` (its value is ``tan(angle / 4)``).
    """
    return ureal(check_name(name), 0.0, range=(-1.0, 1.0), unit="-", quantity="angle")


def connection_parameter(name: str):
    """Connection switch ``delta_C`` in ``[0, 1]`` (nominal 0.5, affine), e.g. ``"delta_C1"``."""
    return ureal(check_name(name), 0.5, range=(0.0, 1.0), unit="-", quantity="switch")


def relative_parameter(
    name: str, nominal: float, percent: float | None, *, unit: str = "", quantity: str = ""
):
    """Return ``ureal(name, nominal, percent=percent)`` (a plain float if ``percent`` is None).

    Parameters
    ----------
    name : str
        Block name.
    nominal : float
        Nominal value [unit].
    percent : float or None
        Relative uncertainty [%] (``value = nominal (1 + percent/100 delta)``, ``|delta| <= 1``).
    unit, quantity : str
        Physical unit and what the parameter is (see :func:`oos_drake.lfr.ureal`).
    """
    if percent is None:
        return float(nominal)
    if percent < 0:
        raise ValueError(f"{name}: uncertainty percent must be >= 0, got {percent}")
    return ureal(
        check_name(name), float(nominal), percent=float(percent), unit=unit, quantity=quantity
    )


def mass_name(body: str) -> str:
    """Block name of a body's mass: ``m_<body>``."""
    return f"m_{body}"


def inertia_names(body: str) -> tuple[str, str, str]:
    """Block names of a body's diagonal inertias: ``(Jxx_<body>, Jyy_<body>, Jzz_<body>)``."""
    return (f"Jxx_{body}", f"Jyy_{body}", f"Jzz_{body}")


def mode_frequency_name(appendage: str, mode: int = 1) -> str:
    """Block name of an appendage mode frequency: ``w<mode>_<appendage>``."""
    return f"w{mode}_{appendage}"


def spring_damper_values(name: str, stiffness, damping) -> dict:
    """Values of the four blocks of spring-damper ``name`` (``k_shear_<name>``, ``k_tors_<name>``,
    ``d_shear_<name>``, ``d_tors_<name>``) with one ``stiffness`` [N/m = N m/rad] and one
    ``damping`` [N s/m = N m s/rad] for shear and torsion."""
    return {
        f"k_shear_{name}": stiffness,
        f"k_tors_{name}": stiffness,
        f"d_shear_{name}": damping,
        f"d_tors_{name}": damping,
    }
