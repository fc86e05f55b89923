"""Named uncertainty subsets of ``Delta_tot``, read from what each block is.

``Delta_tot = diag(Delta_real, Delta_add, Delta_mul)`` with ``Delta_real = diag(Delta_mec,
Delta_mod)`` (paper section 4): ``Delta_mec`` are the target hub's mass and inertias (and, in the
docking models, the spring-damper coefficients), ``Delta_mod`` the first modal frequencies of the
four arrays. A block's subset follows from its ``quantity`` (set where the block is created,
:data:`oos_drake.lfr.blocks.QUANTITIES`), never from its name.
"""

from __future__ import annotations

from collections.abc import Mapping

#: Subset names in the order of the figures.
SUBSET_ORDER = ("total", "real", "modal", "mechanical", "additive", "multiplicative")

#: Quantities of the ``Delta_mec`` blocks.
MECHANICAL_QUANTITIES = ("mass", "inertia", "length", "stiffness", "damping")


def block_group(spec) -> str:
    """``"modal"``, ``"mechanical"``, ``"additive"``, ``"multiplicative"`` or ``"other"``.

    Parameters
    ----------
    spec : oos_drake.lfr.blocks.Block
        Block spec (``sys.uncertainty[name]``).
    """
    if spec.quantity == "modal frequency":
        return "modal"
    if spec.quantity in MECHANICAL_QUANTITIES:
        return "mechanical"
    if spec.quantity == "additive dynamics":
        return "additive"
    if spec.quantity == "multiplicative dynamics":
        return "multiplicative"
    return "other"


def uncertainty_subsets(blocks: Mapping) -> dict[str, list[str]]:
    """The paper's subsets of the blocks present in a model.

    Parameters
    ----------
    blocks : Mapping
        Block name -> spec of the uncertain blocks left in the closed loop (``sys.uncertainty``,
        after the configuration was substituted).

    Returns
    -------
    dict
        ``total``, ``real``, ``modal``, ``mechanical``, ``additive``, ``multiplicative`` ->
        block names (empty subsets are left out). ``real`` holds every ``ureal`` block.
    """
    names = sorted(blocks)
    group = {name: block_group(blocks[name]) for name in names}
    subsets = {
        "total": names,
        "real": [n for n in names if blocks[n].kind == "ureal"],
        "modal": [n for n in names if group[n] == "modal"],
        "mechanical": [n for n in names if group[n] == "mechanical"],
        "additive": [n for n in names if group[n] == "additive"],
        "multiplicative": [n for n in names if group[n] == "multiplicative"],
    }
    return {k: v for k, v in subsets.items() if v}
