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

Each docking event of the mission (a docked phase that starts a docking) is a docking study of
``oos analyze``, as schema 1's phases 7 and 8: :attr:`TreeMissionSpan.docking_phases`,
:meth:`TreeScenario.docking_plant` (the stiffness swept at the event's configuration, a
spring-damper still holding the target kept: a closed loop).

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

import dataclasses
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
    "TreeDockingPhase",
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
    docking_phases : tuple of TreeDockingPhase
        The docking events (``oos analyze``'s docking studies, schema 1's phases 7 and 8): the
        start of each docked phase whose previous phase does not hold the target at the same
        ports.
    """

    t_start: float
    t_end: float
    first_docking_time: float
    docking_phases: tuple = ()


@dataclass(frozen=True)
class TreeDockingPhase:
    """A docking event of a tree's mission: the docking study of ``oos analyze``.

    Attributes
    ----------
    name : str
        The docked phase (the study ``docking-<name>``).
    time : float
        Its start [s]: the configuration the study freezes.
    spring_dampers : tuple of str
        Names of the spring-dampers holding the target then (their blocks'
        ``k_shear_<name>``, ...): the phase's own (swept by the study) first, then the previous
        phase's if it holds the same target by a spring-damper at other ports (a closed loop,
        as schema 1's phase 8).
    description : str
        What the study models, one line.
    """

    name: str
    time: float
    spring_dampers: tuple
    description: str = ""


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
        Empty: a tree's docking studies are ``scenario.mission.docking_phases``
        (:class:`TreeDockingPhase`, their plants :meth:`TreeScenario.docking_plant`), not
        schema 1's named configurations.
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
        angles = timeline.angle_table(times)
        values = {
            self.tree.angle_block(body): angle_to_tau(angles[:, k])
            for k, body in enumerate(timeline.joint_names)
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
        file angles) and the spring-damper's known coefficients (those without a declared
        range: blocks over ``[0, 2 x nominal]`` in the model, for the docking study's sweep).

        Raises
        ------
        ValueError
            ``phase`` is not a docked phase, or a time outside it.
        """
        from oos_drake.scenario.tree import docked_tree
        from oos_drake.scenario.tree_model import tree_values

        docking = self._docking(phase)
        docked = docked_tree(self.tree, docking)
        times = np.atleast_1d(np.asarray(times, dtype=float))
        rows = []
        for t in times:
            if self.timeline.phase_at(t) != phase:
                raise ValueError(f"docking_values: t = {t:g} s is not in phase {phase!r}")
            rows.append(tree_values(docked, self.timeline.angles(t)))
        values = {name: np.array([row[name] for row in rows]) for name in rows[0]}
        values.update(_exact_coefficients(docking, times.size))
        return values

    def docking_event(self, phase: str):
        """``(docking, held)``: the spring-damper docked phase ``phase`` starts with and the
        previous phase's spring-damper still holding the same target at other ports (a tuple,
        empty or one :class:`~oos_drake.scenario.tree_mission.Docking`): the plant of the
        docking study (:meth:`docking_plant`). A previous phase that holds the target welded
        (``captured``) is released at the docking instant in that plant (a weld inside a loop
        is not modelled: declare that hold ``docked`` to keep it).

        Raises
        ------
        ValueError
            ``phase`` is not a docked phase.
        """
        docking = self._docking(phase)
        phases = self.tree.mission.phases
        index = next(i for i, p in enumerate(phases) if p.name == phase)
        previous = phases[index - 1].docked if index > 0 else None
        if previous is None or previous.connection == docking.connection:
            return docking, ()
        same = _same_target(self.tree, previous.target_port, docking.target_port)
        return docking, ((previous,) if same else ())

    def docking_plant(self, phase: str, stiffness, *, damping=None):
        """The uncertain plants of the docking study of phase ``phase`` (``docking-<phase>``,
        schema 1's :func:`oos_drake.analysis.models.docking_plant`): the configuration frozen
        at the phase's start, the target held by the phase's spring-damper, whose stiffness
        (shear [N/m] and torsion [N m/rad] alike) takes each value of ``stiffness``, and by the
        previous phase's spring-damper at other ports if it still holds it
        (:meth:`docking_event`, at its file values: schema 1's phase 8).

        Parameters
        ----------
        phase : str
            A docking event (``mission.docking_phases``).
        stiffness : array_like
            Swept stiffness values [N/m = N m/rad], >= 0.
        damping : float, optional
            Damping of the swept spring-damper [N s/m = N m s/rad], shear and torsion; default:
            the file's (its blocks stay uncertain when the file declares them so).

        Returns
        -------
        LFR
            Model array ``(len(stiffness),)`` ``[F; T]_G -> [a; wdot]_G``; blocks: the tree's
            and the target's uncertain ones, the declared-uncertain spring-damper ones.
        """
        from oos_drake.lfr import usubs
        from oos_drake.scenario.tree import docked_tree
        from oos_drake.scenario.tree_model import (
            build_tree_model,
            docking_block_names,
            tree_values,
        )

        if phase not in [p.name for p in self.mission.docking_phases]:
            raise ValueError(
                f"scenario {self.name}: {phase!r} is not a docking event (docking phases: "
                f"{', '.join(p.name for p in self.mission.docking_phases) or 'none'})"
            )
        stiffness = np.atleast_1d(np.asarray(stiffness, dtype=float))
        if np.any(stiffness < 0) or not np.all(np.isfinite(stiffness)):
            raise ValueError("docking: stiffness values must be finite and >= 0")
        docking, held = self.docking_event(phase)
        # the swept coefficients are values, not uncertain: their blocks must span the sweep
        # (a known one's block spans [0, 2 x nominal], schema 1's; the nominal is not used)
        top = float(stiffness.max())
        if docking.stiffness_percent > 0 or 2.0 * min(docking.k_shear, docking.k_tors) < top:
            docking = dataclasses.replace(
                docking,
                stiffness_percent=0.0,
                k_shear=max(docking.k_shear, top),
                k_tors=max(docking.k_tors, top),
            )
        if damping is not None and (
            docking.damping_percent > 0 or 2.0 * min(docking.d_shear, docking.d_tors) < damping
        ):
            docking = dataclasses.replace(
                docking,
                damping_percent=0.0,
                d_shear=max(docking.d_shear, float(damping)),
                d_tors=max(docking.d_tors, float(damping)),
            )
        tree = docked_tree(self.tree, docking, held)
        event = next(p for p in self.mission.docking_phases if p.name == phase)
        n = stiffness.size
        values = {
            k: np.full(n, v) for k, v in tree_values(tree, self.timeline.angles(event.time)).items()
        }
        names = docking_block_names(docking)
        values[names["k_shear"]] = values[names["k_tors"]] = stiffness
        if damping is not None:
            values[names["d_shear"]] = values[names["d_tors"]] = np.full(n, float(damping))
        elif docking.damping_percent == 0:
            values.update(
                {names[k]: np.full(n, getattr(docking, k)) for k in ("d_shear", "d_tors")}
            )
        for spring in held:
            values.update(_exact_coefficients(spring, n))
        return usubs(build_tree_model(tree), values)

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
    span = TreeMissionSpan(
        0.0, float(starts[-1]), first_hold, _docking_events(tree, phases, starts)
    )
    if tree.control is None:  # parse_tree requires [control]; defensive for the type checker
        raise ScenarioError(source.name, "[control] is required")
    return TreeScenario(tree, timeline, span, Path(source))


def _same_target(tree: SpacecraftTree, port: str, other: str) -> bool:
    """Whether two target ports are on one target."""
    return any(port in t.ports and other in t.ports for t in tree.targets.values())


def _docking_events(tree, phases, starts) -> tuple[TreeDockingPhase, ...]:
    """The docking events of a mission's phases (:attr:`TreeMissionSpan.docking_phases`)."""
    events = []
    for index, phase in enumerate(phases):
        docking = phase.docked
        previous = phases[index - 1] if index > 0 else None
        if docking is None or (
            previous is not None
            and previous.docked is not None
            and previous.docked.connection == docking.connection
        ):
            continue
        names = [docking.label]
        line = f"{docking.port}-{docking.target_port} docks through {docking.label}"
        spring = None if previous is None else previous.docked
        weld = None if previous is None else previous.captured
        if spring is not None and _same_target(tree, spring.target_port, docking.target_port):
            names.append(spring.label)
            line += f" while {spring.label} still holds it (closed loop)"
        elif weld is not None and _same_target(tree, weld[1], docking.target_port):
            line += f" (the capture {weld[0]}-{weld[1]} released at this instant)"
        events.append(TreeDockingPhase(phase.name, float(starts[index]), tuple(names), line))
    return tuple(events)


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


def _exact_coefficients(spring, n: int) -> dict[str, np.ndarray]:
    """Block values of the coefficients of ``spring`` (a docking spring-damper) that the file
    gives without a range (its block spans ``[0, 2 x nominal]`` in the model): each at its file
    value [N/m, N m/rad, N s/m, N m s/rad], ``n`` times."""
    from oos_drake.scenario.tree_model import docking_block_names

    names = docking_block_names(spring)
    percent = {
        "k_shear": spring.stiffness_percent,
        "k_tors": spring.stiffness_percent,
        "d_shear": spring.damping_percent,
        "d_tors": spring.damping_percent,
    }
    return {names[k]: np.full(n, getattr(spring, k)) for k, p in percent.items() if p == 0}
