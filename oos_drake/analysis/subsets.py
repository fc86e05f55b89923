"""Named uncertainty subsets of ``Delta_tot`` and the physical units of the blocks.

``Delta_tot = diag(Delta_real, Delta_add, Delta_mul)`` with ``Delta_real = diag(Delta_mec,
Delta_mod)`` (paper section 4): ``Delta_mec`` are the target hub's mass and inertias (and, in the
docking models, the spring-damper coefficients), ``Delta_mod`` the first modal frequencies of the
four arrays.
"""

from __future__ import annotations

from oos_drake.analysis.loop import ADDITIVE_BLOCK, MULTIPLICATIVE_BLOCKS

#: Subset names in the order of the figures.
SUBSET_ORDER = ("total", "real", "modal", "mechanical", "additive", "multiplicative")


def block_unit(name: str) -> str:
    """Physical unit of a block's value (used in ``wc:<block> [<unit>]`` columns)."""
    if name.startswith("w1_"):
        return "rad/s"
    if name.startswith("m_"):
        return "kg"
    if name.startswith("J"):
        return "kg m^2"
    if name.startswith("k_shear"):
        return "N/m"
    if name.startswith("k_tors"):
        return "N m/rad"
    if name.startswith("d_shear"):
        return "N s/m"
    if name.startswith("d_tors"):
        return "N m s/rad"
    return "-"


def is_modal(name: str) -> bool:
    """Modal block (first frequency of an array)."""
    return name.startswith("w1_")


def is_lti(name: str) -> bool:
    """``Delta_add`` or one of the ``Delta_mul`` scalars."""
    return name == ADDITIVE_BLOCK or name in MULTIPLICATIVE_BLOCKS


def uncertainty_subsets(block_names) -> dict[str, list[str]]:
    """The paper's subsets of the blocks present in a model.

    Parameters
    ----------
    block_names : iterable of str
        Uncertain blocks left in the closed loop (after the configuration was substituted).

    Returns
    -------
    dict
        ``total``, ``real``, ``modal``, ``mechanical``, ``additive``, ``multiplicative`` ->
        block names (empty subsets are left out).
    """
    names = sorted(block_names)
    real = [n for n in names if not is_lti(n)]
    subsets = {
        "total": names,
        "real": real,
        "modal": [n for n in real if is_modal(n)],
        "mechanical": [n for n in real if not is_modal(n)],
        "additive": [n for n in names if n == ADDITIVE_BLOCK],
        "multiplicative": [n for n in names if n in MULTIPLICATIVE_BLOCKS],
    }
    return {k: v for k, v in subsets.items() if v}
