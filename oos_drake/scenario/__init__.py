"""The paper's on-orbit-servicing scenario: data, timeline, kinematics, full LFR model, figures.

Modules: ``data`` (``paper.toml`` -> validated dataclasses), ``timeline`` (configurations over the
mission), ``kinematics`` (independent rigid reference), ``model`` (the TITOP LFR of the whole
system and the docking-phase LFRs), ``figures`` (paper section-2 figures), ``cli``
(``oos model info|figures``). Heavy modules are imported lazily.
"""

from __future__ import annotations

import importlib

_LAZY = {
    "load_scenario": "oos_drake.scenario.data",
    "ScenarioError": "oos_drake.scenario.data",
    "mission_timeline": "oos_drake.scenario.timeline",
    "build_mission_model": "oos_drake.scenario.model",
    "build_docking_model": "oos_drake.scenario.model",
    "attitude_model": "oos_drake.scenario.model",
    "mission_values": "oos_drake.scenario.model",
    "configuration_values": "oos_drake.scenario.model",
    "delta_block_table": "oos_drake.scenario.model",
    "PAPER_OCCURRENCES": "oos_drake.scenario.model",
    "make_figures": "oos_drake.scenario.figures",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'oos_drake.scenario' has no attribute {name!r}")
