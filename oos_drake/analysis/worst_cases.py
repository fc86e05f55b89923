"""The analysis' critical regions in the campaign's terms (``worst_cases.parquet``).

The schema is :mod:`oos_drake.campaign.worst_cases`, the blocks are its parameters
(:func:`block_parameters`). Each certified peak becomes a region
(:func:`oos_drake.analysis.run.run_analysis`); its perturbation is the destabilizing one scaled
onto the modeled uncertainty set (``||delta|| = 1``, i.e. ``delta * mu_lower``,
:func:`physical_values`): the worst case INSIDE the ranges the campaign can sample, in
physical units (``ureal``: the parameter value; ``ultidyn``: the norm of the block, the scalar
that scales the stable realization of its worst direction).
"""

from __future__ import annotations

import numpy as np

from oos_drake.campaign.simulator import Parameter, ParameterKind


def block_parameters(sys):
    """Campaign :class:`~oos_drake.campaign.simulator.Parameter` of every block of ``sys``.

    Unit and kind come from the blocks (their ``unit`` and ``quantity``).
    """
    params = []
    for name, spec in sys.uncertainty.items():
        kind = ParameterKind.of_quantity(spec.quantity)
        if spec.kind == "ureal":
            lo, hi = spec.range
            params.append(
                Parameter(
                    name,
                    spec.unit,
                    float(spec.nominal),
                    float(lo),
                    float(hi),
                    kind,
                    f"uncertain block {name}",
                )
            )
        else:
            params.append(
                Parameter(
                    name,
                    spec.unit,
                    0.0,
                    0.0,
                    float(spec.bound),
                    ParameterKind.LTI,
                    f"LTI block {name}: norm of the worst-case realization",
                )
            )
    return params


def physical_values(sys, normalized: dict, scale: float) -> dict:
    """Block -> physical value of ``scale * normalized`` (ureal values clipped to the range);
    with ``scale = mu_lower`` the worst case inside the set (empty when ``scale <= 0``)."""
    if not scale > 0:  # (NaN included)
        return {}
    out = {}
    specs = sys.uncertainty
    for name, value in normalized.items():
        spec = specs[name]
        if spec.kind == "ureal":
            d = float(np.clip(np.real(value) * scale, -1.0, 1.0))
            lo, hi = spec.range
            out[name] = float(np.clip(spec.to_physical(d), lo, hi))
        else:
            norm = float(np.linalg.norm(np.atleast_2d(np.asarray(value)), ord=2)) * scale
            out[name] = float(min(norm, 1.0) * spec.bound)
    return out
