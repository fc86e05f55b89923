"""Generate the scenario's SDF files from the scenario data file (the single source of truth).

Files (``sdf/``, shipped as package data ``oos_drake/multibody/sdf/``, :data:`SDF_DIRECTORY`)::

    hub_RH1.sdf           chaser hub: link RH1 (frame R_RH1 at G1), frames P1, P2, J0, D1
    hub_RH2.sdf           target hub: link RH2 (R_RH2 at G2), frames P3, P4, D2, D3
    arm_ur5.sdf           UR5-like arm: links L0..L6 (R_Li at J_i), revolute joints
                          alpha_1..alpha_6, frame J7 (arm tip / tool flange) on L6
    array_SA1_2.sdf       chaser solar array (mode bodies, see oos_drake.multibody.appendage_sdf)
    array_SA3_4.sdf       target solar array
    oos_scenario.sdf      assembly: includes RH1, RH2, arm, SA1..SA4; revolute drive joints
                          theta_SA1..theta_SA4 (axis y_P), fixed joint arm_mount (RH1 at J0 - L0);
                          the target's default pose is its docked pose (D3 = D1).

Not in SDF (Drake-specific, added by :mod:`oos_drake.multibody.scenario_plant`): the modal
residual bodies, the hubs' floating joints, the docking bushings SM1 (J7 - D2) and SM2 (D1 - D3).
Regenerate with ``oos sdf generate``; ``tests/multibody/test_sdf_files.py`` fails when the
committed files are stale.
"""

from __future__ import annotations

import hashlib
import json
import re
import tempfile
import weakref
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from oos_drake.multibody.appendage_sdf import appendage_model
from oos_drake.multibody.sdf_writer import (
    Frame,
    Include,
    Inertial,
    Joint,
    Link,
    Model,
    Pose,
    pose_from_matrix,
    to_sdf_text,
)
from oos_drake.resources import package_path

__all__ = [
    "SDF_DIRECTORY",
    "SDF_PACKAGE",
    "ASSEMBLY_FILE",
    "ARM_MODEL",
    "generate_sdf_texts",
    "write_sdf",
    "stale_sdf_files",
    "scenario_sdf_directory",
    "drive_joint_name",
    "arm_joint_name",
]

#: The generated SDF files (``sdf/``), shipped as package data (``oos_drake/multibody/sdf/``).
SDF_DIRECTORY = package_path("oos_drake.multibody", "sdf")
ASSEMBLY_FILE = "oos_scenario.sdf"
ASSEMBLY_MODEL = "oos_scenario"
ARM_MODEL = "arm"
ARM_TIP_FRAME = "J7"
#: Package name under which ``sdf/`` is registered in Drake's PackageMap (includes use
#: ``package://oos_sdf/<file>``; a relative URI would resolve against the working directory).
SDF_PACKAGE = "oos_sdf"


def _uri(file_name: str) -> str:
    return f"package://{SDF_PACKAGE}/{file_name}"


def drive_joint_name(array: str) -> str:
    """Name of the drive joint of array ``array`` (``theta_SA1``)."""
    return f"theta_{array}"


def arm_joint_name(index: int) -> str:
    """Name of arm joint ``index`` (1..6): ``alpha_1``."""
    return f"alpha_{index}"


def _hub_model(scenario, hub_name: str) -> Model:
    hub = scenario.hubs[hub_name]
    frames = []
    for name, mount in scenario.arrays.items():
        if mount.parent == hub_name:
            frames.append(
                Frame(f"P{name[2:]}", hub_name, pose_from_matrix(mount.R_G_P0, mount.p_G_P))
            )
    if scenario.arm.parent == hub_name:
        frames.append(
            Frame("J0", hub_name, pose_from_matrix(scenario.arm.R_G_L0, scenario.arm.p_G_J0))
        )
    for name, port in scenario.ports.items():
        if port.body == hub_name:
            frames.append(Frame(name, hub_name, pose_from_matrix(port.R_G_D, port.p_G_D)))
    comment = (
        f"Rigid hub {hub_name}: {hub.description}.",
        f"Link frame = R_{hub_name} at the centre of mass G{hub_name[2:]}; port and mount frames",
        "(P: array attachment R_SA0, J0: arm base R_L0, D: docking ports) are fixed in it.",
    )
    return Model(
        name=f"hub_{hub_name}",
        comment=comment,
        links=(Link(hub_name, Inertial(hub.mass, hub.inertia)),),
        frames=tuple(frames),
        canonical_link=hub_name,
    )


def _arm_model(scenario) -> Model:
    links, joints = [], []
    previous = None
    for index, link in enumerate(scenario.arm.links):
        pose = (
            Pose()
            if previous is None
            else Pose(tuple(previous.p_J_Jnext), relative_to=previous.name)
        )
        links.append(
            Link(link.name, Inertial(link.mass, link.inertia, Pose(tuple(link.p_J_G))), pose)
        )
        if previous is not None:
            joints.append(
                Joint(
                    arm_joint_name(index),
                    "revolute",
                    previous.name,
                    link.name,
                    axis=tuple(float(v) for v in link.joint_axis),
                )
            )
        previous = link
    last = scenario.arm.links[-1]
    frames = (Frame(ARM_TIP_FRAME, last.name, Pose(tuple(last.p_J_Jnext))),)
    comment = (
        "UR5-like arm (ros-industrial ur5.urdf.xacro masses/inertias as printed in the paper).",
        "Link frame R_Li at joint J_i; all link frames parallel at alpha = 0; joint alpha_i turns",
        "R_Li about its axis relative to R_L(i-1). Frame J7 = arm tip (tool flange), axes of R_L6.",
    )
    return Model(
        name="arm_ur5",
        comment=comment,
        links=tuple(links),
        frames=frames,
        joints=tuple(joints),
        canonical_link=scenario.arm.links[0].name,
    )


def _array_models(scenario) -> dict[str, Model]:
    out = {}
    for name, model in scenario.array_models.items():
        out[name] = appendage_model(
            f"array_{name}",
            model.mass,
            model.p_P_S,
            model.inertia,
            model.omega,
            model.damping_ratios,
            model.participation,
        )
    return out


def _docked_target_pose(scenario) -> tuple[np.ndarray, np.ndarray]:
    """``(R_RH1_RH2, p_G1_G2)`` with D3 on D1 (frames coincide)."""
    d1, d3 = scenario.ports["D1"], scenario.ports["D3"]
    R = d1.R_G_D @ d3.R_G_D.T
    p = d1.p_G_D - R @ d3.p_G_D
    return R, p


def _assembly_model(scenario, array_files: dict[str, str]) -> Model:
    chaser = scenario.arm.parent
    includes = [Include(_uri(f"hub_{chaser}.sdf"), chaser)]
    others = [name for name in scenario.hubs if name != chaser]
    for hub_name in others:
        R, p = _docked_target_pose(scenario)
        includes.append(
            Include(_uri(f"hub_{hub_name}.sdf"), hub_name, pose_from_matrix(R, p, chaser))
        )
    includes.append(Include(_uri("arm_ur5.sdf"), ARM_MODEL, Pose(relative_to=f"{chaser}::J0")))
    joints = [Joint("arm_mount", "fixed", f"{chaser}::{chaser}", f"{ARM_MODEL}::L0")]
    for name, mount in scenario.arrays.items():
        frame = f"{mount.parent}::P{name[2:]}"
        includes.append(Include(_uri(array_files[mount.model.name]), name, Pose(relative_to=frame)))
        joints.append(
            Joint(
                drive_joint_name(name),
                "revolute",
                f"{mount.parent}::{mount.parent}",
                f"{name}::root",
                axis=tuple(float(v) for v in mount.axis),
            )
        )
    comment = (
        f"Scenario '{scenario.name}': {scenario.description}.",
        "Drive joints theta_SA* (arrays) and the arm joints are motion-driven in the mission;",
        "hubs are free-floating (floating joints, modal residuals and docking bushings SM1 J7-D2,",
        "SM2 D1-D3 are added by oos_drake.multibody.scenario_plant). Target default pose: docked.",
    )
    return Model(
        name=ASSEMBLY_MODEL,
        comment=comment,
        includes=tuple(includes),
        joints=tuple(joints),
    )


def generate_sdf_texts(scenario) -> dict[str, str]:
    """Return ``{file name: SDF text}`` for every scenario SDF file.

    Parameters
    ----------
    scenario : oos_drake.scenario.data.Scenario
    """
    texts = {}
    for hub_name in scenario.hubs:
        texts[f"hub_{hub_name}.sdf"] = to_sdf_text(_hub_model(scenario, hub_name))
    texts["arm_ur5.sdf"] = to_sdf_text(_arm_model(scenario))
    array_files = {}
    for name, model in _array_models(scenario).items():
        array_files[name] = f"array_{name}.sdf"
        texts[array_files[name]] = to_sdf_text(model)
    texts[ASSEMBLY_FILE] = to_sdf_text(_assembly_model(scenario, array_files))
    return texts


def write_sdf(directory: str | Path, scenario) -> list[Path]:
    """Write the SDF files of ``scenario`` into ``directory``; return the paths written."""
    return _write_texts(Path(directory), generate_sdf_texts(scenario))


def _write_texts(directory: Path, texts: Mapping[str, str]) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, text in texts.items():
        path = directory / name
        path.write_text(text)
        paths.append(path)
    return paths


#: Relative tolerance on the numbers of a committed SDF file: the generated values come out of
#: eigen-decompositions and products whose last digits depend on the BLAS/LAPACK build.
SDF_RTOL = 1e-9
#: Absolute floor of that comparison [SI units]: values that are zero up to round-off.
SDF_ATOL = 1e-13

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def same_sdf_text(committed: str, generated: str, rtol: float = SDF_RTOL) -> bool:
    """True if the texts are equal but for numbers that agree to ``rtol`` (relative, with an
    absolute floor of :data:`SDF_ATOL` for values that are zero up to round-off)."""
    parts_a, parts_b = _NUMBER.split(committed), _NUMBER.split(generated)
    if parts_a != parts_b:
        return False
    a = np.array([float(v) for v in _NUMBER.findall(committed)])
    b = np.array([float(v) for v in _NUMBER.findall(generated)])
    return bool(np.all(np.abs(a - b) <= rtol * np.abs(b) + SDF_ATOL))


def stale_sdf_files(directory: str | Path, scenario) -> list[str]:
    """Names of files in ``directory`` that are missing or differ from the SDF text generated
    from ``scenario`` (numbers compared to :data:`SDF_RTOL`: see :func:`same_sdf_text`)."""
    return _stale(Path(directory), generate_sdf_texts(scenario))


def _stale(directory: Path, texts: Mapping[str, str]) -> list[str]:
    stale = []
    for name, text in texts.items():
        path = directory / name
        if not path.is_file() or not same_sdf_text(path.read_text(), text):
            stale.append(name)
    return stale


#: SDF folders generated in this process, by the SHA-256 of their texts (one folder per
#: distinct scenario twin, kept until the process ends: the diagram caches key on the folder).
_GENERATED: dict[str, tempfile.TemporaryDirectory] = {}
#: ``scenario_sdf_directory`` per scenario object (generating and comparing the texts takes
#: ~0.1 s; a scenario is immutable, so its answer is too).
_BY_SCENARIO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def scenario_sdf_directory(scenario) -> tuple[Path, object]:
    """The SDF folder of the Drake twin of ``scenario``: the package's when its files match
    the scenario, else a temporary folder the files are generated into.

    The one place where a twin is chosen for a scenario (``oos validate``, the analysis and
    synthesis on the twin, ``oos confirm``, the campaign's simulator). A generated folder is
    reused for the same texts within the process (the diagram caches key on the folder), so a
    worker that receives the same scenario for every task writes its files once.

    Parameters
    ----------
    scenario : oos_drake.scenario.data.Scenario

    Returns
    -------
    directory : Path
        Folder holding ``oos_scenario.sdf`` for the scenario.
    keeper : tempfile.TemporaryDirectory or None
        The generated folder's owner (None: the package's folder); the folder lives as long as
        the process.
    """
    known = _BY_SCENARIO.get(scenario)
    if known is not None:
        return known
    texts = generate_sdf_texts(scenario)
    if not _stale(Path(SDF_DIRECTORY), texts):
        found = Path(SDF_DIRECTORY), None
    else:
        key = hashlib.sha256(json.dumps(texts, sort_keys=True).encode()).hexdigest()
        keeper = _GENERATED.get(key)
        if keeper is None:
            keeper = tempfile.TemporaryDirectory(prefix="oos-sdf-")
            _write_texts(Path(keeper.name), texts)
            _GENERATED[key] = keeper
        found = Path(keeper.name), keeper
    _BY_SCENARIO[scenario] = found
    return found
