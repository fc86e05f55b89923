"""Write the analysis' critical regions as ``worst_cases.parquet`` (schema of the campaign).

The schema is :mod:`oos_drake.campaign.worst_cases`. Each certified peak becomes a region; its
perturbation is the destabilizing one scaled onto the modeled uncertainty set (``||delta|| = 1``,
i.e. ``delta * mu_lower``): the worst case INSIDE the ranges the campaign can sample, in
physical units (``ureal``: the parameter value; ``ultidyn``: the norm of the block, the scalar
that scales the stable realization of its worst direction).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from oos_drake.campaign.simulator import Parameter, ParameterKind
from oos_drake.campaign.worst_cases import WorstCaseRegion, write_worst_cases


@dataclass(frozen=True)
class Region:
    """A critical region: where and how the loop is closest to instability."""

    configuration: str
    time: float
    frequency_hz: float
    mu_upper: float
    mu_lower: float
    subset: str
    normalized: dict  # block -> normalized destabilizing value (float or complex matrix)
    #: campaign metric -> (lower, upper) worst-case performance gain (analysis.performance)
    gains: dict = field(default_factory=dict)


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
    """Block -> physical value of ``scale * normalized`` (ureal values clipped to the range)."""
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


def write_regions(regions, sys, path) -> Path:
    """Write ``regions`` (list of :class:`Region`) for the blocks of ``sys`` to ``path``."""

    params = block_parameters(sys)
    out = []
    for i, r in enumerate(regions):
        scale = r.mu_lower if r.mu_lower > 0 else 0.0
        values = physical_values(sys, r.normalized, scale) if scale > 0 else {}
        out.append(
            WorstCaseRegion(
                i,
                r.configuration,
                float(max(r.time, 0.0)),
                float(r.frequency_hz),
                float(r.mu_upper),
                float(min(r.mu_lower, r.mu_upper)),
                r.subset,
                values,
                dict(r.gains),
            )
        )
    return write_worst_cases(out, params, Path(path))
