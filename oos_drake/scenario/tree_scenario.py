"""A schema-2 tree as the scenario of ``oos synth``, ``oos analyze``, ``oos margins``, ``oos run``.

The stages of the pipeline read a scenario through a few entry points only:

- its uncertain plant and the values of its scheduled blocks along the mission:
  :func:`oos_drake.scenario.model.build_mission_model` and
  :func:`~oos_drake.scenario.model.mission_values` (both dispatch to
  :meth:`TreeScenario.mission_model` and :meth:`TreeScenario.mission_values` for a tree);
- the mission interval ``scenario.mission.t_start``, ``t_end`` (the analysis and synthesis
  grids ``linspace(t_start, t_end, N)``), ``scenario.mission.first_docking_time`` (where the
  baseline PD is tuned) and ``scenario.mission.docking_phases`` (the docking studies);
- the named instants of :func:`oos_drake.scenario.timeline.mission_timeline` (``moments``, for
  labels and the open-loop figure);
- ``scenario.control`` (schema 1's ``[control]``, read by the same reader), ``name``,
  ``description``, ``source``, ``overrides`` (:func:`oos_drake.scenario.data.scenario_record`).

:class:`TreeScenario` provides exactly those over a :class:`~oos_drake.scenario.tree.SpacecraftTree`
and its :class:`~oos_drake.scenario.tree_mission.Timeline`:
``load_scenario`` returns one for a ``schema_version = 2`` file. So every stage runs on a tree
unchanged: the plant is :func:`~oos_drake.scenario.tree_model.build_tree_model` (its blocks
``w<i>_<body>``, ``m_<body>``, ``J.._<body>``: the analysis subsets follow from each block's
quantity), the scheduled blocks ``tau_<body> = tan(angle / 4)`` of the timeline's joint angles.

What a tree does not provide (yet) is refused by name: the schema-1 data of the paper's
topology (``hubs``, ``arrays``, ``arm``, ``ports``, ``docking``, ...: the Drake mission twin
of the confirmation and the campaign's Drake simulator read them) raise :class:`NotForTrees`,
a ``ValueError`` with a one-line message. A mission whose phases capture or dock a target has
one model over all its phases (switch blocks ``delta_<PORT>``,
:func:`~oos_drake.scenario.tree_model.build_mission_tree_model`); a mission with tip-pose
waypoints has no timeline here (their inverse kinematics is the Drake twin's, a layer above):
``oos run`` solves them into a joint-space copy of the file
(:func:`oos_drake.app.tree.joint_space_scenario`) and runs the stages on it.

Examples
--------
>>> from oos_drake.scenario.data import load_scenario
>>> scenario = load_scenario("flexible_satellite")
>>> scenario.mission.t_end
1600.0
>>> sorted(scenario.mission_values([0.0, 800.0]))
['tau_SA1', 'tau_SA2']
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from oos_drake.scenario.data import ControlRequirements, ScenarioError
from oos_drake.scenario.tree import SpacecraftTree, parse_tree
from oos_drake.scenario.tree_mission import Timeline

__all__ = [
    "NotForTrees",
    "TreeMissionSpan",
    "TreeMoment",
    "TreeScenario",
    "is_tree",
    "tree_scenario",
]

#: Schema-1 fields of :class:`~oos_drake.scenario.data.Scenario` a tree has no counterpart for.
SCHEMA1_ONLY = ("hubs", "array_models", "arrays", "arm", "ports", "docking")


class NotForTrees(AttributeError, ValueError):
    """A command or stage needs schema-1 data (the paper's topology) a tree does not have.

    A ``ValueError`` (the ``oos`` commands print it as one line, exit status 2) and an
    ``AttributeError`` (``hasattr(scenario, "arm")`` is False for a tree)."""


@dataclass(frozen=True)
class TreeMissionSpan:
    """What the stages read of a mission (schema 1's ``scenario.mission``), for a tree.

    Attributes
    ----------
    t_start, t_end : float
        Mission interval [s]: ``0`` and the timeline's duration.
    first_docking_time : float
        Where the baseline PD is tuned [s] (schema 1: the first docking): the start of the
        first phase that captures or docks a target, else ``0``.
    docking_phases : tuple
        The docking studies of ``oos analyze`` (none for a tree yet).
    """

    t_start: float
    t_end: float
    first_docking_time: float
    docking_phases: tuple = ()


@dataclass(frozen=True)
class TreeMoment:
    """A named instant of a tree's mission (the paper's "moments"): a phase boundary.

    Attributes
    ----------
    name : str
        ``"1"`` (the start), ``"2"`` (the end of the first phase), ...
    description : str
        ``"start"`` or ``"end of <phase>"``.
    time : float
        Mission time [s].
    """

    name: str
    description: str
    time: float


@dataclass(frozen=True)
class TreeMoments:
    """:func:`oos_drake.scenario.timeline.mission_timeline` of a tree: its named instants.

    Attributes
    ----------
    moments : Mapping[str, TreeMoment]
        Phase boundaries ``"1"`` .. ``"K+1"``.
    docking_phases : Mapping
        Empty (no docking studies on a tree yet).
    """

    moments: Mapping[str, TreeMoment]
    docking_phases: Mapping = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True, eq=False)
class TreeScenario:
    """A schema-2 tree with its timeline, as the pipeline's stages read a scenario.

    Attributes
    ----------
    tree : SpacecraftTree
        The validated tree.
    timeline : Timeline or None
        Its mission's timeline; None when the mission has tip-pose waypoints (their inverse
        kinematics is the Drake twin's, a layer above the scenario's: ``oos tree solve`` and
        ``oos run`` write the joint-space file whose timeline this is).
    mission : TreeMissionSpan
        The mission interval.
    source : Path
        The file.
    overrides : tuple
        Always empty (parameter studies of a tree are not supported).
    """

    tree: SpacecraftTree
    timeline: Timeline | None
    mission: TreeMissionSpan
    source: Path
    overrides: tuple = ()

    @property
    def name(self) -> str:
        """Scenario name."""
        return self.tree.name

    @property
    def description(self) -> str:
        """Free text."""
        return self.tree.description

    @property
    def control(self) -> ControlRequirements:
        """The ``[control]`` requirements and design data (schema 1's reader)."""
        return self.tree.control.requirements

    @property
    def controlled_body(self) -> str:
        """The attitude-controlled body (the root)."""
        return self.tree.control.controlled_body

    def __getattr__(self, name: str) -> Any:
        if name in SCHEMA1_ONLY:
            raise NotForTrees(
                f"scenario {self.tree.name} ({self.source.name}) is a schema-2 tree: this "
                f"command needs the paper's topology (schema-1 `{name}`), not available for "
                "trees yet"
            )
        raise AttributeError(f"{type(self).__name__!s} has no attribute {name!r}")

    def __reduce__(self):
        # a worker receives the same file's tree (checked by its hash), not a pickled copy of
        # the read-only mappings
        digest = hashlib.sha256(self.source.read_bytes()).hexdigest()
        return _unpickle, (str(self.source), digest)

    def mission_model(self):
        """The uncertain plant ``[F; T]_G -> [a; wdot]_G`` of the controlled body over the
        whole mission (:func:`~oos_drake.scenario.tree_model.build_mission_tree_model`:
        scheduled blocks ``tau_<body>`` and, when the mission captures or docks a target, the
        switch blocks ``delta_<PORT>``)."""
        from oos_drake.scenario.tree_model import build_mission_tree_model

        return build_mission_tree_model(self.tree)

    def mission_values(self, times) -> dict[str, np.ndarray]:
        """Scheduled block values at mission ``times`` [s]: ``tau_<body> = tan(angle / 4)`` of
        the timeline's joint angles and each switch ``delta_<PORT>`` (``1`` in the phases that
        capture or dock a target at ``PORT``, else ``0``; at a boundary: the phase ending there);
        the revolute joints of a mated target at their file angles.

        Raises
        ------
        ValueError
            The mission has tip-pose waypoints (no timeline: their inverse kinematics is the
            Drake twin's; ``oos tree solve`` writes the joint-space file, ``oos run`` does it
            itself).
        """
        from oos_drake.scenario.tree_model import mission_connections, switch_block_name
        from oos_drake.titop.spatial import angle_to_tau

        times = np.atleast_1d(np.asarray(times, dtype=float))
        timeline = self.timeline
        if timeline is None:
            tips = [p.name for p in self.tree.mission.phases if p.tip is not None]
            raise ValueError(
                f"scenario {self.name}: mission phases {', '.join(tips)} place a port by "
                "inverse kinematics (the Drake twin's): solve them first with "
                f"`oos tree solve {self.source} OUT.toml` and use OUT.toml (oos run does it)"
            )
        angles = [timeline.angles(t) for t in times]
        values = {
            self.tree.angle_block(body): np.array([float(angle_to_tau(a[body])) for a in angles])
            for body in timeline.joint_names
        }
        mated = []
        for t in times:
            docked = timeline.docked_at(t)
            mated.append(timeline.captured_at(t) if docked is None else docked.connection)
        targets = {}
        for port, target_port in mission_connections(self.tree):
            values[switch_block_name(self.tree, port)] = np.array(
                [1.0 if pair == (port, target_port) else 0.0 for pair in mated]
            )
            owner = next(t for t in self.tree.targets.values() if target_port in t.ports)
            targets[owner.name] = owner
        for target in targets.values():  # a target's own drives hold their file angles
            for body, angle in target.operating_angles().items():
                values[target.angle_block(body)] = np.full(times.size, float(angle_to_tau(angle)))
        return values

    @property
    def docked_phases(self) -> tuple[str, ...]:
        """Names of the mission phases that hold a target by a spring-damper (``docked``)."""
        phases = () if self.tree.mission is None else self.tree.mission.phases
        return tuple(p.name for p in phases if p.docked is not None)

    def docking_model(self, phase: str):
        """The uncertain plant of docked phase ``phase``: the target held by its spring-damper
        (:func:`~oos_drake.scenario.tree.docked_tree`, blocks ``k_shear_<PORT>``,
        ``k_tors_<PORT>``, ``d_shear_<PORT>``, ``d_tors_<PORT>`` over their declared ranges),
        where the mission model (:meth:`mission_model`) welds it rigid. Substitute
        :meth:`docking_values`. The docked phase's subset of its own, for the analysis.

        Raises
        ------
        ValueError
            ``phase`` is not a docked phase (one line naming them).
        """
        from oos_drake.scenario.tree import docked_tree
        from oos_drake.scenario.tree_model import build_tree_model

        return build_tree_model(docked_tree(self.tree, self._docking(phase)))

    def docking_values(self, phase: str, times) -> dict[str, np.ndarray]:
        """Scheduled block values ``tau_<body>`` of :meth:`docking_model` at mission ``times``
        [s] within docked phase ``phase`` (the timeline's angles; the target's drives at their
        file angles).

        Raises
        ------
        ValueError
            ``phase`` is not a docked phase, or a time outside it.
        """
        from oos_drake.scenario.tree import docked_tree
        from oos_drake.scenario.tree_model import tree_values

        docked = docked_tree(self.tree, self._docking(phase))
        times = np.atleast_1d(np.asarray(times, dtype=float))
        rows = []
        for t in times:
            if self.timeline.phase_at(t) != phase:
                raise ValueError(f"docking_values: t = {t:g} s is not in phase {phase!r}")
            rows.append(tree_values(docked, self.timeline.angles(t)))
        return {name: np.array([row[name] for row in rows]) for name in rows[0]}

    def _docking(self, phase: str):
        phases = () if self.tree.mission is None else self.tree.mission.phases
        found = next((p.docked for p in phases if p.name == phase and p.docked), None)
        if found is None:
            raise ValueError(
                f"scenario {self.name}: {phase!r} is not a docked phase (docked phases: "
                f"{', '.join(self.docked_phases) or 'none'})"
            )
        return found

    def bodies_table(self):
        """One row per body of the tree (and of each target): ``body``, ``kind``,
        ``description``, ``mass [kg]``, ``Jxx [kg m^2]`` .. ``Jzz [kg m^2]`` (rigid: at the
        centre of mass; flexible: at S), ``mass uncertainty [%]``, ``first mode [Hz]``."""
        import pandas as pd

        rows = []
        trees = [self.tree, *self.tree.targets.values()]
        for tree in trees:
            for body in tree.bodies:
                jxx, jyy, jzz = (float(x) for x in np.diagonal(body.inertia))
                flexible = body.kind == "flexible"
                on = f" on {body.parent}" if body.parent else (
                    " (free target)" if tree is not self.tree else " (controlled body)"
                )  # fmt: skip
                rows.append(
                    {
                        "body": body.name,
                        "kind": (
                            f"flexible ({len(body.frequencies_hz)} modes){on}"
                            if flexible
                            else f"rigid{on}"
                        ),
                        "description": body.description,
                        "mass [kg]": float(body.mass),
                        "Jxx [kg m^2]": jxx,
                        "Jyy [kg m^2]": jyy,
                        "Jzz [kg m^2]": jzz,
                        "mass uncertainty [%]": (
                            np.nan if flexible else float(body.mass_uncertainty_percent)
                        ),
                        "first mode [Hz]": float(body.frequencies_hz[0]) if flexible else np.nan,
                    }
                )
        return pd.DataFrame(rows)

    def named_instants(self) -> TreeMoments:
        """The phase boundaries as numbered moments (``"1"``: the start)."""
        phases = () if self.tree.mission is None else self.tree.mission.phases
        ends = np.cumsum([p.duration for p in phases])
        moments = {"1": TreeMoment("1", "start", 0.0)}
        names = [p.name for p in phases]
        for k, (phase, end) in enumerate(zip(names, ends, strict=True), start=2):
            moments[str(k)] = TreeMoment(str(k), f"end of {phase}", float(end))
        return TreeMoments(MappingProxyType(moments))


def _unpickle(path: str, digest: str) -> TreeScenario:
    from oos_drake.scenario.data import load_scenario

    if hashlib.sha256(Path(path).read_bytes()).hexdigest() != digest:
        raise ValueError(f"scenario {path}: the file changed while it was in use")
    return load_scenario(path)


def is_tree(scenario: Any) -> bool:
    """Whether a loaded scenario is a schema-2 tree (:class:`TreeScenario`)."""
    return isinstance(scenario, TreeScenario)


def tree_scenario(document: Mapping[str, Any], source: Path) -> TreeScenario:
    """A :class:`TreeScenario` from a parsed schema-2 document (``load_scenario``'s route).

    A mission with tip-pose waypoints gets no timeline (their inverse kinematics is the Drake
    twin's, :func:`oos_drake.multibody.tree_ik.mission_timeline`, a layer above this one).

    Raises
    ------
    ScenarioError
        Invalid tree (one line naming the body and the field).
    """
    from oos_drake.scenario.tree_mission import build_timeline

    tree = parse_tree(document, source)
    phases = () if tree.mission is None else tree.mission.phases
    timeline = None if any(p.tip is not None for p in phases) else build_timeline(tree)
    starts = np.concatenate([[0.0], np.cumsum([p.duration for p in phases])])
    first_hold = next(
        (
            float(t0)
            for t0, p in zip(starts[:-1], phases, strict=True)
            if p.captured is not None or p.docked is not None
        ),
        0.0,
    )
    span = TreeMissionSpan(0.0, float(starts[-1]), first_hold)
    if tree.control is None:  # parse_tree requires [control]; defensive for the type checker
        raise ScenarioError(source.name, "[control] is required")
    return TreeScenario(tree, timeline, span, Path(source))


def unsupported_stages(scenario_file: str | Path) -> dict[str, str]:
    """The parts of ``oos run`` a scenario file cannot run yet, each with its one-line reason.

    Parameters
    ----------
    scenario_file : path-like
        A scenario file (schema 1 or 2).

    Returns
    -------
    dict
        ``{}`` for a schema-1 file; for a schema-2 tree: ``"model figures"`` (the paper's
        section-2 figures). A mission that captures or docks a target runs every other stage on
        its switched model (:func:`~oos_drake.scenario.tree_model.build_mission_tree_model`)
        and its twin with the target welded where the model welds it
        (:mod:`oos_drake.multibody.tree_twin`), tip-pose waypoints once ``oos run`` has solved
        them (:func:`oos_drake.app.tree.joint_space_scenario`).
    """
    import tomllib

    with Path(scenario_file).open("rb") as stream:
        document = tomllib.load(stream)
    if document.get("schema_version") != 2:
        return {}
    return {
        "model figures": "the paper's section-2 figures (moments, docking sweeps, arm) need "
        "its topology; a tree has its block table only",
    }
