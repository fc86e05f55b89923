"""The controller under analysis: the JSON written by ``oos synth``, or the labeled baseline.

The analysis closes the loop with the controller ``u_K = C(s) y``
(``y = [-(SST phi + n); -(GYRO w + n)]``, then the roll-off ``F_ro``) and the design
specification (weights, sensors, actuators) stored with it. Every structure ``oos synth``
tunes is read here, in one place, into one type
(:class:`~oos_drake.control.interconnection.ControllerSystem`): the static 3x6 gain
``K = [K_p, K_d]`` of the paper (a controller without states), a PID per axis, a fixed-order
state space, continuous or discrete at the flight software's rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import (
    STRUCTURES,
    ControllerSystem,
    as_controller,
    read_controller,
)


@dataclass(frozen=True)
class Controller:
    """An attitude controller and the design data it was tuned with.

    Attributes
    ----------
    system : ControllerSystem
        The controller ``y -> u_K`` (a 3x6 gain ``[K_p, K_d]`` given here becomes the static
        controller).
    spec : DesignSpecification
        Sensors, actuators, roll-off and weights (paper values unless the JSON says otherwise).
    label : str
        ``"synthesized"`` (from a controller JSON) or ``"baseline"`` (the paper's section 3.1
        PD tuned at the first docking; NOT the synthesized controller).
    source : str
        File the gains come from, or a description of how they were computed.
    gamma : float
        Synthesis performance level stored in the JSON (NaN for the baseline).
    status : str
        ``"ok"``, or ``"infeasible"``: tuned to ``[control]`` hard goals it does NOT meet.
    structure : str
        ``"static"``, ``"pid"`` or ``"state-space"`` (:data:`STRUCTURES`).
    """

    system: ControllerSystem
    spec: DesignSpecification
    label: str
    source: str
    gamma: float = float("nan")
    status: str = "ok"
    structure: str = "static"

    def __post_init__(self):
        try:
            system = as_controller(self.system)
        except ValueError as exc:
            raise ValueError(f"controller {self.source}: {exc}") from exc
        object.__setattr__(self, "system", system)
        if self.structure not in STRUCTURES:
            raise ValueError(
                f"controller {self.source}: unknown structure {self.structure!r} "
                f"(one of {', '.join(STRUCTURES)})"
            )

    @property
    def K(self) -> np.ndarray:
        """The static gain ``[K_p, K_d]`` (3x6) [N m/rad, N m s/rad].

        Raises
        ------
        ValueError
            A dynamic controller (it has no static gain: use :attr:`system`).
        """
        try:
            return self.system.K
        except ValueError as exc:
            raise ValueError(f"controller {self.source} ({self.structure}): {exc}") from exc

    @property
    def is_static(self) -> bool:
        """Whether the controller is the static gain ``[K_p, K_d]``."""
        return self.system.is_static


def _spec_from_record(record: dict | None) -> DesignSpecification:
    if not record:
        return DesignSpecification()
    fields = DesignSpecification.__dataclass_fields__
    kwargs = {}
    for key, value in record.items():
        if key in fields and key != "extra":
            kwargs[key] = tuple(value) if isinstance(value, list) else value
    return DesignSpecification(**kwargs)


def load_controller(path) -> Controller:
    """Read a controller JSON written by ``oos synth`` (``controller.json``).

    Parameters
    ----------
    path : str or Path
        The JSON file, or a directory holding ``controller.json``.

    Raises
    ------
    ValueError
        Missing file or gains (the message names the file and the field).
    """
    record, system = read_controller(path)
    path = Path(path)
    if path.is_dir():
        path = path / "controller.json"
    structure = record.get("structure", "static")
    gamma = record.get("gamma")
    gamma = float(gamma) if isinstance(gamma, (int, float)) else float("nan")
    spec = _spec_from_record(record.get("design_specification"))
    status = record.get("status", "ok")
    if status not in ("ok", "infeasible"):
        raise ValueError(f"controller file {path}: status must be ok or infeasible, got {status!r}")
    return Controller(system, spec, "synthesized", str(path), gamma, status, structure)


def recorded_controller(record: dict, default: ControllerSystem) -> ControllerSystem:
    """The controller an analysis recorded (``summary.json``'s ``controller``).

    ``record["state_space"]`` (:meth:`ControllerSystem.record`), else the static gain
    ``record["K"]`` (summaries written before dynamic controllers), else ``default``.

    Raises
    ------
    ValueError
        A malformed record.
    """
    ss = record.get("state_space")
    if isinstance(ss, dict):
        return ControllerSystem.from_named(
            *(np.asarray(ss[k], dtype=float) for k in "ABCD"),
            ss["inputs"],
            ss["outputs"],
            float(ss.get("sampling_time_s", 0.0) or 0.0),
        )
    if "K" in record:
        return ControllerSystem.static(record["K"])
    return default


def baseline_controller(scenario, spec: DesignSpecification | None = None) -> Controller:
    """The paper's baseline PD (section 3.1) on ``scenario``, labeled ``"baseline"``.

    The gain is :func:`oos_drake.control.baseline.scenario_baseline_gains` (the one derivation,
    shared with the Drake mission's :func:`~oos_drake.multibody.mission.mission_controller`).

    Parameters
    ----------
    scenario : Scenario
        Loaded scenario; the baseline is tuned at its first docking.
    spec : DesignSpecification, optional
        Paper values by default.
    """
    from oos_drake.control.baseline import scenario_baseline_gains

    tuning_time = float(scenario.mission.first_docking_time)
    return Controller(
        ControllerSystem.static(scenario_baseline_gains(scenario)),
        spec or DesignSpecification(),
        "baseline",
        f"baseline PD (omega_att = 0.01 Hz, xi_att = 1) tuned at t = "
        f"{tuning_time:g} s; NOT a synthesized controller",
    )


def scenario_controller(path, scenario) -> Controller:
    """The controller to analyze on ``scenario``, with the scenario's ``[control]`` design data.

    ``path``: a ``controller.json`` of ``oos synth``, or None for the BASELINE PD tuned on the
    scenario at its first docking; ``scenario``: a loaded scenario.
    The sensors, actuators and weights of the analysis are the scenario's (they belong to the
    spacecraft and its requirements); a controller tuned with other design data is analyzed
    with the scenario's, and a warning says so.
    """
    import dataclasses

    spec = DesignSpecification.from_requirements(scenario.control)
    if path:
        controller = load_controller(path)
        if controller.status != "ok":
            print(
                f"WARNING: {controller.source} has status {controller.status!r}: the hard goals "
                "it was tuned for are NOT met"
            )
        if controller.spec.design_data() != spec.design_data():
            changed = sorted(
                k for k, v in spec.design_data().items() if controller.spec.to_dict()[k] != v
            )
            print(
                f"WARNING: {controller.source} was tuned with other design data "
                f"({', '.join(changed)}); analyzing it with scenario {scenario.name}'s [control]"
            )
        return dataclasses.replace(controller, spec=spec)
    return baseline_controller(scenario, spec)
