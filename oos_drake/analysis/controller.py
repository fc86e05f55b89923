"""The controller under analysis: the JSON written by ``oos synth``, or the labeled baseline.

The analysis closes the loop with the static 3x6 gain ``K = [K_p, K_d]`` (``u_K = K y``,
``y = [-(SST phi + n); -(GYRO w + n)]``, then the roll-off ``F_ro``) and the design
specification (weights, sensors, actuators) stored with it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from oos_drake.control.components import DesignSpecification


@dataclass(frozen=True)
class Controller:
    """A static attitude controller and the design data it was tuned with.

    Attributes
    ----------
    K : numpy.ndarray, shape (3, 6)
        ``[K_p, K_d]``: ``K_p`` [N m/rad], ``K_d`` [N m s/rad].
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
    """

    K: np.ndarray
    spec: DesignSpecification
    label: str
    source: str
    gamma: float = float("nan")
    status: str = "ok"

    def __post_init__(self):
        K = np.array(self.K, dtype=float)
        if K.shape != (3, 6) or not np.all(np.isfinite(K)):
            raise ValueError(
                f"controller {self.source}: K must be a finite 3x6 gain, got shape {K.shape}"
            )
        K.setflags(write=False)
        object.__setattr__(self, "K", K)


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
    path = Path(path)
    if path.is_dir():
        path = path / "controller.json"
    if not path.is_file():
        raise ValueError(f"controller file {path} not found")
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"controller file {path}: not JSON ({exc})") from exc
    structure = record.get("structure", "static")
    if structure != "static":
        raise ValueError(
            f"controller file {path}: structure {structure!r} is not supported by this stage "
            "(only the static gain 'static' runs downstream)"
        )
    try:
        gains = record["controller"]
        K_p = np.asarray(gains["K_p"]["value"], dtype=float)
        K_d = np.asarray(gains["K_d"]["value"], dtype=float)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"controller file {path}: missing field controller.K_p/K_d.value") from exc
    if K_p.shape != (3, 3) or K_d.shape != (3, 3):
        raise ValueError(
            f"controller file {path}: K_p and K_d must be 3x3, got {K_p.shape} and {K_d.shape}"
        )
    gamma = record.get("gamma")
    gamma = float(gamma) if isinstance(gamma, (int, float)) else float("nan")
    spec = _spec_from_record(record.get("design_specification"))
    status = record.get("status", "ok")
    if status not in ("ok", "infeasible"):
        raise ValueError(f"controller file {path}: status must be ok or infeasible, got {status!r}")
    return Controller(np.hstack([K_p, K_d]), spec, "synthesized", str(path), gamma, status)


def baseline_controller(plant_rotational, spec: DesignSpecification | None = None) -> Controller:
    """The paper's baseline PD (section 3.1) tuned on the inertia of a plant ``T -> wdot``.

    Parameters
    ----------
    plant_rotational : LFR
        Nominal, certain 3x3 plant ``T_ext,G1 -> wdot`` at the tuning configuration (the first
        docking, t = 255 s); its static gain is ``J_tot^-1``.
    spec : DesignSpecification, optional
        Paper values by default.
    """
    from oos_drake.control.baseline import (
        OMEGA_ATT,
        TUNING_TIME_S,
        XI_ATT,
        baseline_gains,
        inertia_from_plant,
    )
    from oos_drake.control.interconnection import plant_statespace

    n = plant_rotational.nstates
    M = np.asarray(plant_rotational.M, dtype=float)
    sys = plant_statespace(M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:])
    J = inertia_from_plant(sys)
    K = baseline_gains(J, OMEGA_ATT, XI_ATT)
    return Controller(
        K,
        spec or DesignSpecification(),
        "baseline",
        f"baseline PD (omega_att = 0.01 Hz, xi_att = 1) tuned at t = "
        f"{TUNING_TIME_S:g} s; NOT a synthesized controller",
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
    from oos_drake.control.analysis_model import rotational_channels
    from oos_drake.lfr import usubs
    from oos_drake.scenario.model import build_mission_model, mission_values

    tuning_time = scenario.mission.first_docking_time
    plant = usubs(build_mission_model(scenario), mission_values([tuning_time], scenario)).model(0)
    return baseline_controller(rotational_channels(plant).nominal, spec)
