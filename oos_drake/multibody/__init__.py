"""oos_drake.multibody: the Drake twin of the scenario (everything that imports pydrake).

- :mod:`~oos_drake.multibody.modal_realization` (numpy only): exact rigid-body realization of a
  flexible appendage's ``M_P(s)`` by mode bodies on spring-damped revolute joints.
- :mod:`~oos_drake.multibody.scenario_sdf`: SDF files (``sdf/``, package data ``multibody/sdf/``)
  generated from the scenario data (``oos sdf generate``);
  :mod:`~oos_drake.multibody.sdf_validation`: checks before parsing.
- :mod:`~oos_drake.multibody.scenario_plant`: ``build_scenario_diagram(connection)``: plant from
  the SDF files + modal residuals, floating joints, welds or docking bushings (Context
  parameters).
- :mod:`~oos_drake.multibody.operating_point`: place the twin at a configuration and
  linearize it (``linearize_at``) into a
  ``control.StateSpace`` from the wrench at G1 to ``[a; wdot; w; rpy]``.
- :mod:`~oos_drake.multibody.cross_check`: Drake vs TITOP (``oos validate``).
- :mod:`~oos_drake.multibody.uncertain_linearization`: ``ulinearize(system, context, parameters,
  inputs, outputs)``: uncertain LFR of any Drake model with declared physical parameters
  (``oos ulinearize``); :mod:`~oos_drake.multibody.mission_lfr`: the twin's LFRs at the mission's
  configurations.

Submodules are imported on demand (pydrake import takes ~1 s).
"""

_LAZY = {
    "ulinearize": "oos_drake.multibody.uncertain_linearization",
    "PhysicalParameter": "oos_drake.multibody.uncertain_linearization",
    "load_parameters": "oos_drake.multibody.uncertain_linearization",
}


def __getattr__(name):
    """``oos_drake.multibody.ulinearize`` & co. without importing pydrake at package import."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'oos_drake.multibody' has no attribute {name!r}")
