r"""Uncertain linearization of a Drake system (MATLAB ``ulinearize`` for MultibodyPlant models).

:func:`ulinearize` turns a Drake system (a ``MultibodyPlant`` or a ``Diagram`` holding one), a
Context at an operating point and a list of declared physical parameters into an
:class:`oos_drake.lfr.LFR` whose ``ureal`` blocks are those parameters. Nothing about the
model's equations is assumed beyond what Drake itself computes:

1. **Descriptor form.** At a point where the plant's generalized accelerations vanish (an
   equilibrium: no gravity in orbit, zero velocity, zero inputs), Drake's linearization
   ``x' = A x + B u``, ``y = C x + D u`` (``FirstOrderTaylorApproximation``) satisfies

   .. math::  E(p)\, x' = \tilde A(p)\, x + \tilde B(p)\, u, \qquad
              E = \mathrm{blkdiag}(I, M(q_0, p), I), \quad \tilde A = E A, \quad \tilde B = E B,

   with ``M`` the mass matrix of the free (unlocked) velocities (``CalcMassMatrix``); the term
   ``dM^{-1}/dq f`` vanishes because ``f = M v' = 0``. ``M`` is linear in each body's mass (its
   centre of mass and its inertia about it kept) and in each diagonal moment of inertia;
   ``\tilde A`` is linear in spring and bushing stiffnesses and in damping constants. Outputs
   that read accelerations are written ``y = C_x(p) x + D_u(p) u + C_d x'`` with a constant
   ``C_d`` measured exactly by probing: unit forces and torques on each body (the plant's
   ``applied_spatial_force`` input) change ``v'`` and, through it only, ``y``.
2. **Coefficients from evaluations.** All of ``[E, -\tilde A, -\tilde B; -C_d, I, -C_x, -D_u]``
   (the implicit relation ``R(p) [x'; y; x; u] = 0``) is evaluated at the nominal point and at
   ``nominal +- h`` for each parameter (``h`` its half range), which gives the exact
   coefficients of a polynomial of degree <= 2 in the deviation ``d = p - nominal``; the fit is
   checked at a third point per parameter (a parameter whose dependence is not polynomial of
   degree <= 2 is refused, naming it) and the sum of the per-parameter terms at random joint
   points (cross terms are refused).
3. **Minimal repetitions.** Each parameter's coefficients are factored by SVD: affine
   ``d R_1 = U d V^T`` takes ``rank R_1`` occurrences; quadratic ``d R_1 + d^2 R_2`` takes
   ``rank [R_1, R_2] + rank R_2`` (or ``rank [R_1; R_2] + rank R_2``, whichever is smaller).
   A modal frequency ``omega`` (quantity ``"frequency"``) scales its joint's spring as
   ``k = k_0 (omega / omega_0)^2 = J omega^2`` and its damping as ``d = d_0 omega / omega_0 =
   2 xi J omega`` (``J = k_0 / omega_0^2``, ``xi`` kept): both terms sit in the joint's row of
   ``\tilde A``, so ``omega`` occurs twice (``omega I_2``, as in TITOP's modal block).
4. **Normalization and assembly.** Each deviation ``d = p - nominal`` is written in the
   normalized ``delta`` of MATLAB's ``ureal`` (affine for a centred range, MATLAB's bilinear
   map otherwise) and the implicit relation is solved for ``[x'; y]`` around the nominal
   (the algebraic loop through ``E``'s uncertain part stays inside the LFR). States that
   structurally cannot reach an output or be reached from an input (through any uncertain
   channel) are removed, and so are such channels. The result is checked against Drake's own
   linearization at random parameter values inside and outside the ranges. Finally each
   block's channels are put in a canonical, balanced basis (an exact change of coordinates
   that depends on the model's input-output maps only, and helps the mu optimizers:
   :func:`_balance_channels`).

A modal frequency would enter Drake's coordinates as ``omega^2`` (two cascaded channels of
very different weight, on which the D-G mu upper bound's optimizer stalls); by default the
joint's angle is scaled by ``omega / omega_0`` in the state, which makes ``omega`` affine
(TITOP's modal form, :class:`_ModalStates`).

Parameters are declared with :class:`PhysicalParameter` (or a TOML file, :func:`load_parameters`).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import BodyIndex, LinearBushingRollPitchYaw
from pydrake.systems.framework import PortDataType
from pydrake.systems.primitives import FirstOrderTaylorApproximation
from scipy.linalg import block_diag

from oos_drake.lfr import LFR, usubs
from oos_drake.lfr.blocks import UReal, make_ureal_spec
from oos_drake.lfr.core import BlockEntry
from oos_drake.multibody.linearization import structural_keep
from oos_drake.multibody.plant_parts import (
    central_inertia,
    force_elements,
    revolute_spring,
    set_central_inertia,
    set_mode_frequency,
    spatial_inertia_from_central,
)

__all__ = [
    "BODY_QUANTITIES",
    "JOINT_QUANTITIES",
    "BUSHING_QUANTITIES",
    "ExtractionOptions",
    "PhysicalParameter",
    "load_parameters",
    "parse_port",
    "sdf_plant",
    "ulinearize",
]

BODY_QUANTITIES = ("mass", "Ixx", "Iyy", "Izz")
JOINT_QUANTITIES = ("stiffness", "damping", "frequency")
_BUSHING_KINDS = ("force_stiffness", "torque_stiffness", "force_damping", "torque_damping")
BUSHING_QUANTITIES = tuple(
    f"{kind}{axis}" for kind in _BUSHING_KINDS for axis in ("", "_x", "_y", "_z")
)
#: Drake quantity -> (its unit, the block's ``quantity``: :data:`oos_drake.lfr.blocks.QUANTITIES`).
_QUANTITIES = {
    "mass": ("kg", "mass"),
    "Ixx": ("kg m^2", "inertia"),
    "Iyy": ("kg m^2", "inertia"),
    "Izz": ("kg m^2", "inertia"),
    "stiffness": ("N m/rad", "stiffness"),
    "damping": ("N m s/rad", "damping"),
    "frequency": ("rad/s", "modal frequency"),
    "force_stiffness": ("N/m", "stiffness"),
    "torque_stiffness": ("N m/rad", "stiffness"),
    "force_damping": ("N s/m", "damping"),
    "torque_damping": ("N m s/rad", "damping"),
}


@dataclass(frozen=True)
class PhysicalParameter:
    """One uncertain physical parameter of a Drake model (becomes a ``ureal`` block).

    Attributes
    ----------
    name : str
        Block name in the LFR (e.g. ``"m_hub"``).
    element : str
        What it belongs to: a body or joint name (``"hub"``, optionally scoped
        ``"model::hub"``), or a bushing as ``"frameA/frameC"`` (its two frames' names).
    quantity : str
        Body: ``"mass"`` [kg] (centre of mass and inertia about it kept), ``"Ixx"``, ``"Iyy"``,
        ``"Izz"`` [kg m^2] (inertia about the centre of mass, body axes). Revolute joint:
        ``"stiffness"`` [N m/rad] (its ``RevoluteSpring``), ``"damping"`` [N m s/rad],
        ``"frequency"`` [rad/s] (modal frequency: spring ``k0 (w/w0)^2``, damping ``d0 w/w0``
        with ``k0, d0`` the context's values at the nominal ``w0``). Bushing:
        ``"force_stiffness"`` [N/m], ``"torque_stiffness"`` [N m/rad], ``"force_damping"``
        [N s/m], ``"torque_damping"`` [N m s/rad], all three axes, or one axis with a suffix
        ``_x``, ``_y``, ``_z``.
    nominal : float
        Nominal value (unit of the quantity).
    lower, upper : float
        Range, ``lower < nominal < upper`` (an off-centre range uses MATLAB's bilinear map).
    """

    name: str
    element: str
    quantity: str
    nominal: float
    lower: float
    upper: float

    def __post_init__(self):
        known = BODY_QUANTITIES + JOINT_QUANTITIES + BUSHING_QUANTITIES
        if self.quantity not in known:
            raise ValueError(
                f"parameter {self.name!r}: unknown quantity {self.quantity!r}; known: {known}"
            )
        _ = self.spec  # validates name and range (one-line ValueError)
        positive = "damping" not in self.quantity
        if self.lower < 0 or (positive and self.lower == 0):
            sign = "non-positive" if positive else "negative"
            raise ValueError(
                f"parameter {self.name!r}: range [{self.lower:g}, {self.upper:g}] makes the "
                f"{self.quantity} of {self.element!r} {sign}"
            )

    @property
    def spec(self) -> UReal:
        """The ``ureal`` block spec (MATLAB normalization) with its unit and block quantity."""
        return UReal(
            self.name, self.nominal, self.lower, self.upper,
            unit=self.unit, quantity=_QUANTITIES[self._base_quantity][1],
        )  # fmt: skip

    @property
    def _base_quantity(self) -> str:
        return self.quantity.removesuffix("_x").removesuffix("_y").removesuffix("_z")

    @property
    def unit(self) -> str:
        """Physical unit of the quantity."""
        return _QUANTITIES[self._base_quantity][0]

    @property
    def kind(self) -> str:
        """``"body"``, ``"joint"`` or ``"bushing"``."""
        if self.quantity in BODY_QUANTITIES:
            return "body"
        return "joint" if self.quantity in JOINT_QUANTITIES else "bushing"


def load_parameters(path) -> tuple[PhysicalParameter, ...]:
    """Read parameter declarations from a TOML file.

    Format: one table per parameter, named by its block name::

        [m_hub]
        element = "hub"
        quantity = "mass"
        nominal = 100.0        # kg
        range = [90.0, 110.0]  # or percent = 10, or plusminus = 10.0

    Raises
    ------
    ValueError
        Unreadable file, missing field, bad range (the message names the parameter).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"{path}: cannot read parameter file ({error})") from None
    parameters = []
    for name, table in data.items():
        if not isinstance(table, dict):
            raise ValueError(f"{path}: {name!r} must be a table [{name}]")
        missing = [key for key in ("element", "quantity", "nominal") if key not in table]
        if missing:
            raise ValueError(f"{path}: parameter {name!r} misses {missing}")
        extra = set(table) - {"element", "quantity", "nominal", "range", "percent", "plusminus"}
        if extra:
            raise ValueError(f"{path}: parameter {name!r} has unknown keys {sorted(extra)}")
        ranges = {k: table[k] for k in ("range", "percent", "plusminus") if k in table}
        if len(ranges) != 1:
            raise ValueError(
                f"{path}: parameter {name!r} needs exactly one of range, percent, plusminus"
            )
        spec = make_ureal_spec(name, float(table["nominal"]), **ranges)
        parameters.append(
            PhysicalParameter(
                name, str(table["element"]), str(table["quantity"]),
                spec.nominal, spec.lower, spec.upper,
            )
        )  # fmt: skip
    if not parameters:
        raise ValueError(f"{path}: no parameters declared")
    return tuple(parameters)


# ----------------------------------------------------------------------------- Drake binding
def _scoped(plant, name: str, has, get, kind: str):
    if "::" in name:
        model, local = name.rsplit("::", 1)
        if not plant.HasModelInstanceNamed(model):
            raise ValueError(f"no model instance {model!r} for {kind} {name!r}")
        instance = plant.GetModelInstanceByName(model)
        if not has(local, instance):
            raise ValueError(f"no {kind} named {name!r} in the model")
        return get(local, instance)
    if not has(name):
        raise ValueError(f"no {kind} named {name!r} in the model")
    try:
        return get(name)
    except RuntimeError:
        raise ValueError(
            f"{kind} name {name!r} is ambiguous; scope it as 'model::{name}'"
        ) from None


class _Binding:
    """A parameter bound to its Drake element, with the base context's values it scales."""

    def __init__(self, parameter: PhysicalParameter, plant, plant_context):
        self.parameter = parameter
        self.plant = plant
        self.position_row = None  # diagram state index of a free joint's angle (_problem)
        kind, element, quantity = parameter.kind, parameter.element, parameter.quantity
        label = f"parameter {parameter.name!r}"
        if kind == "body":
            self.body = _scoped(plant, element, plant.HasBodyNamed, plant.GetBodyByName, "body")
            if parameter.quantity != "mass":
                self._check_inertia(plant_context)
        elif kind == "joint":
            joint = _scoped(plant, element, plant.HasJointNamed, plant.GetJointByName, "joint")
            if joint.num_velocities() != 1 or joint.type_name() != "revolute":
                raise ValueError(f"{label}: joint {element!r} is not a revolute joint")
            self.joint = joint
            self.spring = revolute_spring(plant, joint)
            if quantity in ("stiffness", "frequency") and self.spring is None:
                raise ValueError(f"{label}: joint {element!r} has no spring (RevoluteSpring)")
            self.k0 = self.spring.GetStiffness(plant_context) if self.spring else 0.0
            self.d0 = float(joint.GetDampingVector(plant_context)[0])
        else:
            frames = element.split("/")
            if len(frames) != 2:
                raise ValueError(f"{label}: a bushing is named 'frameA/frameC', got {element!r}")
            matches = [
                f for f in force_elements(plant, LinearBushingRollPitchYaw)
                if (f.frameA().name(), f.frameC().name()) == tuple(frames)
            ]  # fmt: skip
            if len(matches) != 1:
                raise ValueError(
                    f"{label}: {'no' if not matches else 'more than one'} bushing between "
                    f"frames {frames[0]!r} and {frames[1]!r}"
                )
            self.bushing = matches[0]
            axis = quantity[-1] if quantity[-2:] in ("_x", "_y", "_z") else ""
            self.bushing_kind = quantity[:-2] if axis else quantity
            self.axes = [{"x": 0, "y": 1, "z": 2}[axis]] if axis else [0, 1, 2]

    def _check_inertia(self, plant_context):
        for value in (self.parameter.lower, self.parameter.upper):
            M = self.body.CalcSpatialInertiaInBodyFrame(plant_context)
            mass, com, inertia = central_inertia(M)
            axis = BODY_QUANTITIES.index(self.parameter.quantity) - 1
            inertia[axis, axis] = value
            if (
                not spatial_inertia_from_central(mass, com, inertia).IsPhysicallyValid()
                or np.linalg.eigvalsh(inertia).min() <= 0
            ):
                raise ValueError(
                    f"parameter {self.parameter.name!r}: {self.parameter.quantity} = {value:g} "
                    f"makes the inertia of body {self.parameter.element!r} non-physical "
                    "(triangle inequality or non-positive moment)"
                )

    def apply(self, plant_context, value: float) -> None:
        """Write ``value`` (physical) into ``plant_context``."""
        quantity = self.parameter.quantity
        if self.parameter.kind == "body":
            if quantity == "mass":
                set_central_inertia(self.body, plant_context, mass=value)
            else:
                axis = BODY_QUANTITIES.index(quantity) - 1
                set_central_inertia(self.body, plant_context, moments={axis: value})
        elif self.parameter.kind == "joint":
            if quantity == "stiffness":
                self.spring.SetStiffness(plant_context, value)
            elif quantity == "damping":
                self.joint.SetDampingVector(plant_context, [value])
            else:
                ratio = value / self.parameter.nominal
                set_mode_frequency(
                    self.spring, self.joint, plant_context, ratio, (self.k0, self.d0)
                )
        else:
            getter = getattr(self.bushing, f"Get{_camel(self.bushing_kind)}Constants")
            setter = getattr(self.bushing, f"Set{_camel(self.bushing_kind)}Constants")
            constants = np.array(getter(plant_context), dtype=float)
            constants[self.axes] = value
            setter(plant_context, constants)


def _camel(kind: str) -> str:
    return "".join(part.capitalize() for part in kind.split("_"))


_PORT = re.compile(r"^\s*([^\[\]]+?)\s*(?:\[([0-9,:\s]*)\])?\s*$")


def parse_port(text: str) -> tuple[str, slice | list[int] | None]:
    """Split ``"name"``, ``"name[0:6]"`` or ``"name[2,9]"`` into a port name and a row selection."""
    match = _PORT.match(str(text))
    if not match:
        raise ValueError(f"bad port specification {text!r} (use NAME, NAME[i,j] or NAME[a:b])")
    name, selection = match.group(1), match.group(2)
    if selection is None:
        return name, None
    selection = selection.replace(" ", "")
    try:
        if ":" in selection:
            start, stop = (int(v) if v else None for v in selection.split(":"))
            return name, slice(start, stop)
        return name, [int(v) for v in selection.split(",") if v]
    except ValueError:
        raise ValueError(f"bad port specification {text!r}") from None


def _port(system, text: str, direction: str):
    name, selection = parse_port(text)
    has = system.HasInputPort if direction == "input" else system.HasOutputPort
    get = system.GetInputPort if direction == "input" else system.GetOutputPort
    if not has(name):
        count = system.num_input_ports() if direction == "input" else system.num_output_ports()
        port = system.get_input_port if direction == "input" else system.get_output_port
        names = [port(i).get_name() for i in range(count)]
        owner = system.get_name() or type(system).__name__
        raise ValueError(f"no {direction} port {name!r} on {owner!r}; ports: {names}")
    port = get(name)
    if port.get_data_type() != PortDataType.kVectorValued:
        raise ValueError(f"{direction} port {name!r} is not vector-valued")
    rows = np.arange(port.size())
    if selection is not None:
        try:
            rows = rows[selection]
        except IndexError:
            raise ValueError(
                f"{direction} port {text!r}: selection outside its {port.size()} entries"
            ) from None
        if rows.size == 0:
            raise ValueError(f"{direction} port {text!r}: empty selection")
    return port, rows, name


def _find_plant(system):
    if isinstance(system, MultibodyPlant):
        return system
    plants = [s for s in system.GetSystems() if isinstance(s, MultibodyPlant)]
    if len(plants) != 1:
        raise ValueError(
            f"ulinearize: {system.get_name()!r} holds {len(plants)} MultibodyPlants (need one)"
        )
    return plants[0]


@dataclass(frozen=True)
class _Problem:
    system: object
    plant: object
    context: object
    bindings: tuple
    inputs: tuple  # (port, rows, name)
    outputs: tuple
    velocity_rows: np.ndarray  # diagram continuous-state indices of the free velocities
    free_velocities: np.ndarray  # plant velocity indices that are not locked

    @property
    def nominal(self) -> np.ndarray:
        return np.array([b.parameter.nominal for b in self.bindings])

    def context_at(self, values):
        """A clone of the context (and its plant context) with the parameters at physical
        ``values`` (one per binding) and every unset input port at zero."""
        context = self.context.Clone()
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        for binding, value in zip(self.bindings, values, strict=True):
            binding.apply(plant_context, float(value))
        for port, _, _ in self.inputs:
            if not port.HasValue(context):
                port.FixValue(context, np.zeros(port.size()))
        return context, plant_context

    def linearize(self, values) -> dict:
        """Drake's Taylor linearization and mass matrix at physical ``values`` (one per binding)."""
        context, plant_context = self.context_at(values)
        B, C, D = [], [], []
        A = None
        for k, (out_port, out_rows, _) in enumerate(self.outputs):
            row_C, row_D = None, []
            for in_port, in_rows, _ in self.inputs:
                affine = FirstOrderTaylorApproximation(
                    self.system, context,
                    input_port_index=in_port.get_index(), output_port_index=out_port.get_index(),
                )  # fmt: skip
                if A is None:
                    A = affine.A()
                if k == 0:
                    B.append(affine.B()[:, in_rows])
                row_C = affine.C()[out_rows, :]
                row_D.append(affine.D()[np.ix_(out_rows, in_rows)])
            C.append(row_C)
            D.append(np.hstack(row_D))
        M = self.plant.CalcMassMatrix(plant_context)[
            np.ix_(self.free_velocities, self.free_velocities)
        ]
        xdot = self.system.EvalTimeDerivatives(context).CopyToVector()
        return {
            "A": A,
            "B": np.hstack(B),
            "C": np.vstack(C),
            "D": np.vstack(D),
            "M": M,
            "xdot": xdot,
        }

    def acceleration_map(self) -> np.ndarray | None:
        """``C_d`` such that the outputs are ``y = X [x; u] + C_d x'`` (``None``: no ``x'``).

        Probes: a unit force and a unit torque along each world axis on each body (the plant's
        ``applied_spatial_force`` input) change the generalized accelerations ``v'`` and,
        through them only, the outputs: ``dy = C_d dv'`` for every probe, exact (linear).
        """
        context, plant_context = self.context_at(self.nominal)
        plant = self.plant
        force_port = plant.get_applied_spatial_force_input_port()
        acceleration = plant.get_generalized_acceleration_output_port()

        def outputs():
            return np.concatenate([p.Eval(context)[rows] for p, rows, _ in self.outputs])

        def probe(forces):
            force_port.FixValue(plant_context, forces)
            return outputs(), acceleration.Eval(plant_context)[self.free_velocities]

        try:
            y0, a0 = probe([])
        except RuntimeError as error:
            raise ValueError(
                f"ulinearize: cannot probe the plant's accelerations ({str(error).splitlines()[0]})"
            ) from None
        dY, dV = [], []
        for index in range(1, plant.num_bodies()):  # body 0 is the world
            body = plant.get_body(BodyIndex(index))
            for wrench in np.eye(6):  # [torque; force] at the body origin, world axes
                applied = ExternallyAppliedSpatialForce()
                applied.body_index = body.index()
                applied.p_BoBq_B = np.zeros(3)
                applied.F_Bq_W = SpatialForce(wrench[:3], wrench[3:])
                y, a = probe([applied])
                dY.append(y - y0)
                dV.append(a - a0)
        dY, dV = np.array(dY).T, np.array(dV).T
        if np.abs(dY).max(initial=0.0) <= 1e-12 * max(np.abs(y0).max(initial=0.0), 1.0):
            return None
        Cd_v, *_ = np.linalg.lstsq(dV.T, dY.T, rcond=None)
        Cd = np.zeros((dY.shape[0], context.get_continuous_state_vector().size()))
        Cd[:, self.velocity_rows] = Cd_v.T
        return Cd


def _problem(system, context, parameters, inputs, outputs) -> _Problem:
    plant = _find_plant(system)
    if isinstance(inputs, str):
        inputs = [inputs]
    if isinstance(outputs, str):
        outputs = [outputs]
    if not inputs or not outputs:
        raise ValueError("ulinearize: give at least one input and one output port")
    parameters = tuple(parameters)
    if not parameters:
        raise ValueError("ulinearize: no parameters declared")
    names = [p.name for p in parameters]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"ulinearize: parameter names declared twice: {duplicates}")
    if not plant.is_finalized():
        raise ValueError("ulinearize: the MultibodyPlant is not finalized")
    if plant.time_step() != 0:
        raise ValueError("ulinearize: the MultibodyPlant must be continuous (time_step = 0)")
    plant_context = plant.GetMyContextFromRoot(context)
    bindings = tuple(_Binding(p, plant, plant_context) for p in parameters)
    in_ports = tuple(_port(system, name, "input") for name in inputs)
    out_ports = tuple(_port(system, name, "output") for name in outputs)
    # where the plant's velocities sit in the system's continuous state: write markers
    marked = context.Clone()
    state = marked.get_mutable_continuous_state_vector()
    state.SetFromVector(np.arange(state.size(), dtype=float))
    plant_state = plant.GetMyContextFromRoot(marked).get_continuous_state_vector().CopyToVector()
    nq = plant.num_positions()
    locked = np.zeros(plant.num_velocities(), dtype=bool)
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.is_locked(plant_context):
            locked[joint.velocity_start() : joint.velocity_start() + joint.num_velocities()] = True
    free = np.flatnonzero(~locked)
    velocity_rows = plant_state[nq:][free].astype(int)
    for binding in bindings:
        if binding.parameter.quantity == "frequency" and not binding.joint.is_locked(plant_context):
            binding.position_row = int(plant_state[binding.joint.position_start()])
    return _Problem(system, plant, context, bindings, in_ports, out_ports, velocity_rows, free)


# ----------------------------------------------------------------------------- algebra
def _implicit(problem: _Problem, lin: dict, Cd: np.ndarray | None):
    """Rows ``R`` of the implicit relation ``R [x'; y; x; u] = 0`` (module docstring, step 2)."""
    A, B, C, D = lin["A"], lin["B"], lin["C"], lin["D"]
    n, ny = A.shape[0], C.shape[0]
    E = np.eye(n)
    rows = problem.velocity_rows
    E[np.ix_(rows, rows)] = lin["M"]
    At, Bt = E @ A, E @ B
    top = np.hstack([E, np.zeros((n, ny)), -At, -Bt])
    Cd = np.zeros((ny, n)) if Cd is None else Cd
    bottom = np.hstack([-Cd, np.eye(ny), -(C - Cd @ A), -(D - Cd @ B)])
    return np.vstack([top, bottom])


def _fit_axes(problem: _Problem, evaluate, h: np.ndarray):
    """``R0`` and per-parameter coefficients ``(R1, R2)`` of ``R0 + d R1 + d^2 R2`` (exact)."""
    nominal = problem.nominal
    R0 = evaluate(nominal)
    coefficients = []
    for i in range(nominal.size):
        step = np.zeros_like(nominal)
        step[i] = h[i]
        plus, minus = evaluate(nominal + step), evaluate(nominal - step)
        R1 = (plus - minus) / (2 * h[i])
        R2 = (plus + minus - 2 * R0) / (2 * h[i] ** 2)
        coefficients.append((R1, R2))
    return R0, coefficients


def _scales(R0, coefficients, h):
    """Column scale for the tolerance checks (largest entry a column can reach in the range).

    Floored at ``1e-10`` times the largest column: a column whose entries are round-off of an
    exact zero (``E A`` with an ill-conditioned ``E``) must not be scaled up to size 1.
    """
    total = np.abs(R0).copy()
    for (R1, R2), hi in zip(coefficients, h, strict=True):
        total += np.abs(R1) * hi + np.abs(R2) * hi**2
    column = total.max(axis=0)
    return np.maximum(column, 1e-10 * max(column.max(initial=0.0), 1e-300))


def _model(R0, coefficients, nominal, values):
    d = np.asarray(values) - nominal
    R = R0.copy()
    for (R1, R2), di in zip(coefficients, d, strict=True):
        R = R + di * R1 + di**2 * R2
    return R


def _factor(R, tol):
    """``R = U V^T`` with ``rank(R)`` columns (singular values above ``tol``), balanced."""
    rows, cols = np.flatnonzero(np.any(R, axis=1)), np.flatnonzero(np.any(R, axis=0))
    U_full, V_full = np.zeros((R.shape[0], 0)), np.zeros((R.shape[1], 0))
    if rows.size == 0:
        return U_full, V_full
    U, s, Vt = np.linalg.svd(R[np.ix_(rows, cols)], full_matrices=False)  # nonzero part only
    r = int(np.sum(s > tol))
    root = np.sqrt(s[:r])
    U_full, V_full = np.zeros((R.shape[0], r)), np.zeros((R.shape[1], r))
    U_full[rows] = U[:, :r] * root
    V_full[cols] = Vt[:r].T * root
    return U_full, V_full


def _channels(R1, R2, h, scale, rtol):
    """Occurrence structure of ``d R1 + d^2 R2`` (see module docstring, step 3).

    Returns ``(U, V, W)``: with ``w = d z``, the term is ``U w`` and ``z = V^T xi + W w``.
    Factored in ``e = d / h`` on column-scaled matrices (``scale``: each column's largest entry
    over the ranges), so that a singular value below ``rtol`` changes no entry by more than
    ``rtol`` relative to what its column reaches.
    """
    S1, S2 = R1 * h / scale, R2 * h**2 / scale
    tol = rtol  # columns scaled to what they reach over the ranges: entries <= 1
    m = S1.shape[1]
    if not np.any(np.abs(S2) > tol):
        U, V = _factor(S1, tol)
        return U / h, V * scale[:, None], np.zeros((U.shape[1], U.shape[1]))
    # horizontal: U e (V1^T + P e Q^T)   vs   vertical: (U1 + P e Q^T) e V^T
    Uh, Vh = _factor(np.hstack([S1, S2]), tol)
    P, Q = _factor(Vh[m:].T, tol)
    Uv, Vv = _factor(np.vstack([S1, S2]), tol)
    Pv, Qv = _factor(Uv[S1.shape[0] :], tol)
    if Uh.shape[1] + P.shape[1] <= Uv.shape[1] + Pv.shape[1]:
        ra, rb = Uh.shape[1], P.shape[1]
        U = np.hstack([Uh / h, np.zeros((Uh.shape[0], rb))])
        V = np.hstack([Vh[:m], Q])  # z1 = V1^T xi + P w2, z2 = Q^T xi
        W = np.zeros((ra + rb, ra + rb))
        W[:ra, ra:] = P / h
    else:
        ra, rb = Uv.shape[1], Pv.shape[1]
        U = np.hstack([Uv[: S1.shape[0]] / h, Pv / h**2])  # U1 w1 + P w2
        V = np.hstack([Vv, np.zeros((m, rb))])  # z1 = V^T xi, z2 = Q^T w1
        W = np.zeros((ra + rb, ra + rb))
        W[ra:, :ra] = Qv.T
    return U, V * scale[:, None], W


def _assemble(problem, R0, coefficients, h, scale, n, nu, ny, rtol, names):
    """Solve ``R(delta) [x'; y; x; u] = 0`` for ``[x'; y]`` as an upper LFT (normalized)."""
    order = np.argsort([b.parameter.name for b in problem.bindings], kind="stable")
    Us, Vs, Ws, gains, betas, entries = [], [], [], [], [], []
    for i in order:
        spec = problem.bindings[i].parameter.spec
        U, V, W = _channels(*coefficients[i], h[i], scale, rtol)
        if U.shape[1] == 0:
            continue  # not in the model at all (refused or dropped by the caller)
        Us.append(U)
        Vs.append(V)
        Ws.append(W)
        g = spec.alpha - spec.nominal * spec.beta  # deviation = g delta / (1 + beta delta)
        gains.append(np.full(U.shape[1], math.sqrt(g)))
        betas.append(np.full(U.shape[1], spec.beta))
        entries.append(BlockEntry(spec, U.shape[1]))
    width = R0.shape[1]
    U = np.hstack([np.zeros((R0.shape[0], 0)), *Us])
    V = np.hstack([np.zeros((width, 0)), *Vs])
    W = block_diag(*Ws) if Ws else np.zeros((0, 0))
    S, beta = np.concatenate([np.zeros(0), *gains]), np.concatenate([np.zeros(0), *betas])
    m = n + ny  # unknowns eta = [x'; y]
    Ra, Rb = R0[:, :m], R0[:, m:]
    T = -np.linalg.inv(Ra)
    G_zeta = T @ Rb
    G_w = T @ U * S[None, :]
    Va, Vb = V[:m].T, V[m:].T
    Z_zeta = S[:, None] * (Va @ G_zeta + Vb)
    Z_w = S[:, None] * (Va @ G_w + W * S[None, :]) - np.diag(beta)
    xs, ys, xc, uc = slice(0, n), slice(n, m), slice(0, n), slice(n, n + nu)
    return LFR.from_parts(
        G_zeta[xs, xc], G_w[xs], G_zeta[xs, uc],
        Z_zeta[:, xc], G_zeta[ys, xc],
        Z_w, Z_zeta[:, uc], G_w[ys], G_zeta[ys, uc],
        [(e.spec, e.reps) for e in entries],
        input_names=names[0], output_names=names[1],
    )  # fmt: skip


def _prune(sys: LFR, rtol: float = 1e-13) -> LFR:
    """Drop states and uncertain channels that cannot reach ``y`` or be reached from ``u``.

    Structural (exact): a graph over states, ``z`` and ``w`` channels (edges from the nonzero
    entries of ``M`` and ``z_k -> w_k`` through ``Delta``, every block here being a scalar
    occurrence); a block that loses all its channels disappears.
    """
    n, nz, nw = sys.nstates, sys.nz, sys.nw
    M = np.abs(np.asarray(sys.M))
    rows, cols = M.shape
    big = max(M.max(initial=0.0), 1e-300)
    nonzero = M > rtol * big
    size = n + nz  # nodes: states, z channels, then w channels
    edges = np.zeros((size + nw, size + nw), dtype=bool)
    edges[:size, :n] = nonzero[:size, :n]
    edges[:size, size:] = nonzero[:size, n : n + nw]
    edges[size:, n:size] = np.eye(nw, nz, dtype=bool)
    sources = np.zeros(size + nw, dtype=bool)
    sources[:size] = nonzero[:size, n + nw :].any(axis=1)
    sinks = np.zeros(size + nw, dtype=bool)
    sinks[:n] = nonzero[size:, :n].any(axis=0)
    sinks[size:] = nonzero[size:, n : n + nw].any(axis=0)
    keep = structural_keep(edges, sources, sinks)
    states, channels = np.flatnonzero(keep[:n]), np.flatnonzero(keep[n:size])
    if states.size == n and channels.size == nz:
        return sys
    entries, start = [], 0
    for entry in sys.block_entries:
        reps = int(np.count_nonzero((channels >= start) & (channels < start + entry.reps)))
        if reps:
            entries.append(BlockEntry(entry.spec, reps))
        start += entry.reps
    rows_keep = np.concatenate([states, n + channels, np.arange(size, rows)])
    cols_keep = np.concatenate([states, n + channels, np.arange(n + nw, cols)])
    return LFR(
        np.asarray(sys.M)[np.ix_(rows_keep, cols_keep)],
        states.size,
        entries,
        input_names=sys.input_names,
        output_names=sys.output_names,
    )


def _balancing_frequencies(A: np.ndarray, per_decade: int = 10) -> np.ndarray:
    """Log grid [rad/s] over the model's own time scales: a decade below its slowest nonzero
    pole to a decade above its fastest (``0.1 .. 10`` rad/s when every pole is at zero).
    Poles below ``1e-6`` times the fastest count as zero (rigid-body poles, whose round-off
    depends on the state coordinates)."""
    size = np.abs(np.linalg.eigvals(A)) if A.size else np.zeros(0)
    size = size[size > 1e-6 * max(size.max(initial=0.0), 1e-300)]
    low, high = (size.min() / 10, size.max() * 10) if size.size else (0.1, 10.0)
    count = max(int(np.ceil(per_decade * np.log10(high / low))) + 1, 3)
    return np.geomspace(low, high, count)


def _balance_channels(sys: LFR) -> LFR:
    r"""Put each block's channels in a canonical basis: ``z -> T z``, ``w -> T w`` (exact,
    since ``delta I`` commutes with ``T``), with ``T`` making two Gram matrices of the block
    equal and diagonal (balanced): how its ``z`` is driven by the inputs and how its ``w``
    reaches the outputs, over a log frequency grid of the model's time scales
    (:func:`_balancing_frequencies`),

    .. math::  P = \sum_f \mathrm{Re}\, H_{z u}(j\omega_f) H_{z u}^*, \qquad
               Q = \sum_f \mathrm{Re}\, H_{y w}^* H_{y w}(j\omega_f),

    ``T = S^(1/2) U^T L^-1`` with ``P = L L^T``, ``L^T Q L = U S^2 U^T``. Both depend on the
    model's input-output maps only: two LFRs that differ by a change of state coordinates and
    of each block's channel basis (the twin's and TITOP's) get the same channels (each
    channel's sign is fixed by its driven response, so that neighbouring configurations of a
    model array get neighbouring channels). The mu bounds are invariant
    under ``T``, but their optimizers start from diagonal scalings, and the D-G optimizer is
    sensitive to how a repeated block's channels are scaled and mixed (a ``diag(e^3, e^-3)``
    on a TITOP modal block doubled its converged bound on the mission). Measured on the
    mission twin (4 configurations, the analysis grid of the total subset, its converged
    passes): the bounds in this basis are within -18 %/+13 % of those on the TITOP LFR point
    by point, the peaks 0.5 % to 0.8 % lower; before (Gram matrices of the rows and columns
    of ``M``, which depend on the state coordinates, and ``omega^2`` cascades) up to 2.45
    times higher.
    """
    n, nz = sys.nstates, sys.nz
    M = np.array(sys.M, dtype=float)
    A, B, C, D = M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]
    omega = _balancing_frequencies(A)
    if n:
        resolvent = np.linalg.solve(1j * omega[:, None, None] * np.eye(n) - A, B)
        H = D + C @ resolvent  # (F, nz + ny, nw + nu)
    else:
        H = np.broadcast_to(D.astype(complex), (omega.size,) + D.shape)
    start = 0
    for entry in sys.block_entries:
        k = slice(start, start + entry.reps)
        start += entry.reps
        driven, reaching = H[:, k, nz:], H[:, nz:, k]
        P = np.einsum("fim,fjm->ij", driven, driven.conj()).real
        Q = np.einsum("fmi,fmj->ij", reaching.conj(), reaching).real
        try:
            L = np.linalg.cholesky(P)
            U, s2, _ = np.linalg.svd(L.T @ Q @ L)
        except np.linalg.LinAlgError:
            continue  # a channel driven by nothing: leave the block as it is
        if s2.min(initial=1.0) <= 1e-300:
            continue
        root = s2**0.25  # S^(1/2), S = sqrt(s2)
        T = root[:, None] * np.linalg.solve(L.T, U).T  # S^(1/2) U^T L^-1
        T_inv = L @ U / root[None, :]  # L U S^(-1/2)
        # signs: each channel's largest driven response entry positive (the SVD's signs are
        # arbitrary; a flip between neighbouring configurations breaks the analysis'
        # model-to-model continuation)
        response = np.einsum("ij,fjm->ifm", T, driven).reshape(T.shape[0], -1)
        stacked = np.concatenate([response.real, response.imag], axis=1)
        sign = np.sign(stacked[np.arange(T.shape[0]), np.abs(stacked).argmax(axis=1)])
        sign[sign == 0] = 1.0
        T, T_inv = sign[:, None] * T, T_inv * sign[None, :]
        rows = slice(n + k.start, n + k.stop)
        M[rows] = T @ M[rows]
        M[:, rows] = M[:, rows] @ T_inv
    return LFR(M, n, sys.block_entries, input_names=sys.input_names, output_names=sys.output_names)


@dataclass(frozen=True)
class _ModalStates:
    r"""The angles of modal-frequency joints, scaled by ``omega / omega_0`` in the state.

    With the joint's spring ``k = J omega^2`` and damper ``d = 2 xi J omega``, Drake's
    coordinates make ``omega`` enter quadratically (``omega^2`` on the angle ``q``): two
    channels, the second one reading the first (``delta (delta ...)``), about
    ``2 omega_0 / (omega - omega_0)`` times weaker. With the state ``q~ = (omega / omega_0) q``
    (and the angle's kinematic row ``q' = v`` multiplied by ``omega / omega_0``) it enters
    affinely: ``q~' = (omega / omega_0) v``, ``k q = J omega_0 omega q~``, ``d v = 2 xi J omega
    v``, the form of TITOP's modal block (``omega I_2``, two channels of equal weight). Same
    input-output map and repetitions; the D-G mu upper bound is the same infimum on both
    realizations, but its optimizer converges on this one (measured on the mission twin: the
    grid bounds of the total subset up to 2.45 times TITOP's before, docs/DESIGN.md). Only
    where exact: a joint whose angle is read by anything but its own spring (an output, a
    bushing) keeps Drake's coordinates (the fit is checked).

    Attributes
    ----------
    parameters : numpy.ndarray
        Binding indices of the frequency parameters whose joint angle is scaled.
    rows : numpy.ndarray
        Their angles' indices in the system's continuous state.
    nominal : numpy.ndarray
        Their nominal frequencies ``omega_0`` [rad/s].
    """

    parameters: np.ndarray
    rows: np.ndarray
    nominal: np.ndarray

    @classmethod
    def none(cls) -> _ModalStates:
        return cls(np.zeros(0, int), np.zeros(0, int), np.zeros(0))

    @classmethod
    def of(cls, problem) -> _ModalStates:
        """Every frequency parameter of ``problem`` whose joint is free (a candidate)."""
        chosen = [
            (i, b.position_row, b.parameter.nominal)
            for i, b in enumerate(problem.bindings)
            if b.parameter.quantity == "frequency" and b.position_row is not None
        ]
        if not chosen:
            return cls.none()
        index, rows, nominal = (np.array(c) for c in zip(*chosen, strict=True))
        return cls(index.astype(int), rows.astype(int), nominal.astype(float))

    def _ratios(self, values) -> np.ndarray:
        return np.asarray(values, dtype=float)[self.parameters] / self.nominal

    def implicit(self, R: np.ndarray, values, n: int, ny: int) -> np.ndarray:
        """``R [x'; y; x; u] = 0`` in the scaled states (columns ``x'``, ``x`` of each angle
        divided by ``omega / omega_0``, its kinematic row multiplied)."""
        if not self.rows.size:
            return R
        ratio = self._ratios(values)
        R = R.copy()
        R[:, self.rows] /= ratio
        R[:, n + ny + self.rows] /= ratio
        R[self.rows] *= ratio[:, None]
        return R

    def state_space(self, ABCD: np.ndarray, values) -> np.ndarray:
        """``[A B; C D]`` of Drake's states in the scaled ones (``x = S x~``)."""
        if not self.rows.size:
            return ABCD
        ratio = self._ratios(values)
        ABCD = ABCD.copy()
        ABCD[self.rows] *= ratio[:, None]
        ABCD[:, self.rows] /= ratio
        return ABCD

    def where_affine(self, evaluate, nominal, R0, coefficients, h, scale, tolerance):
        """The candidates along whose axis the scaled relation is affine (a
        :class:`_ModalStates`): the linear model matches an evaluation at ``nominal + h / 2``
        within ``tolerance`` (column-scaled)."""
        keep = []
        for k, i in enumerate(self.parameters):
            values = np.array(nominal, dtype=float)
            values[i] += 0.5 * h[i]
            linear = R0 + 0.5 * h[i] * coefficients[i][0]
            if np.max(np.abs(evaluate(values) - linear) / scale) <= tolerance:
                keep.append(k)
        keep = np.array(keep, dtype=int)
        return _ModalStates(self.parameters[keep], self.rows[keep], self.nominal[keep])


def _relative(a, b) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@dataclass(frozen=True)
class ExtractionOptions:
    """Options of the LFR extraction (the keyword arguments of :func:`ulinearize`).

    Attributes
    ----------
    rtol : float
        Rank tolerance of the coefficient factorizations, relative to what each column of the
        implicit relation reaches over the ranges. Round-off of ``E A`` grows with the
        conditioning of the mass matrix and the stiffness: up to 4e-7 for the mission twin with
        1e5 N/m docking springs (mass matrix condition number ~1e7), where the smallest true
        singular value is 1e-2 (:func:`oos_drake.multibody.mission_lfr.twin_lfr` uses 1e-5).
    check_points : int
        Random parameter points (half inside the ranges, half up to half a range outside,
        kept positive) at which the LFR is checked against Drake's linearization.
    check_tolerance : float
        Largest relative error of ``[A B; C D]`` allowed at those points (and of the
        degree-2 and no-cross-term checks).
    prune : bool
        Remove states that structurally cannot reach an output or be reached from an input.
    unused : str
        ``"error"`` (default): a parameter that does not change the linearization is refused;
        ``"drop"``: it is left out of the LFR (zero repetitions, e.g. the target's inertia
        while the target floats free).
    scale_modal_states : bool
        True (default): the angle of a joint whose modal frequency ``omega`` is a parameter is
        the state ``(omega / omega_0) q``, which makes ``omega`` enter affinely (TITOP's modal
        form, where the mu upper bound's optimizer converges; :class:`_ModalStates`), where
        that is exact (the angle read only by its spring); False: Drake's ``q`` (``omega``
        enters as ``omega^2``, two cascaded channels). Same repetitions and input-output map.
    """

    rtol: float = 1e-6
    check_points: int = 4
    check_tolerance: float = 1e-6
    prune: bool = True
    unused: str = "error"
    scale_modal_states: bool = True

    def __post_init__(self):
        if self.unused not in ("error", "drop"):
            raise ValueError(f"ulinearize: unused must be 'error' or 'drop', got {self.unused!r}")


def ulinearize(
    system,
    context,
    parameters: Sequence[PhysicalParameter],
    inputs: str | Sequence[str],
    outputs: str | Sequence[str],
    *,
    rng: np.random.Generator | None = None,
    **options,
) -> LFR:
    r"""Linearize a Drake system into an uncertain LFR with named physical parameters.

    Parameters
    ----------
    system : MultibodyPlant or Diagram
        Continuous system holding exactly one finalized ``MultibodyPlant``.
    context : Context
        Root context at the operating point: an equilibrium (generalized accelerations zero
        with zero inputs); locked joints are motion-driven (their states are dropped as
        unreachable). Not modified.
    parameters : sequence of PhysicalParameter
        Declared uncertain parameters (see :class:`PhysicalParameter`); the context's own
        values are replaced by the declared nominal values at the nominal point.
    inputs, outputs : str or sequence of str
        Port names of ``system``, optionally with a row selection ``"y_G1[0:6]"`` or
        ``"state[2,9]"``. Input ports not listed keep their context values (fixed).
    rng : numpy.random.Generator, optional
        For the check points (default: ``numpy.random.default_rng(0)``).
    **options
        The fields of :class:`ExtractionOptions` (``rtol``, ``check_points``,
        ``check_tolerance``, ``prune``, ``unused``, ``scale_modal_states``), as keywords.

    Returns
    -------
    LFR
        Upper LFT in the states of Drake's linearization (``[q; v]`` order, pruned; modal
        angles scaled, see ``scale_modal_states``), inputs and outputs named ``port[i]``; one
        ``ureal`` block per parameter with the minimal number of repetitions.

    Raises
    ------
    ValueError
        Unknown body/joint/bushing/port, a range making a mass or stiffness non-positive,
        a non-equilibrium context, a parameter that is not polynomial of degree <= 2 or
        that does not enter the model, cross terms between parameters, or a failed check.

    Examples
    --------
    >>> plant, context = sdf_plant("examples/servicer/servicer.sdf")  # no gravity, at rest
    >>> G = ulinearize(plant, context,
    ...                load_parameters("examples/servicer/servicer_parameters.toml"),
    ...                "servicer_actuation", "servicer_state[0,1,2,7,8,9]")
    >>> G.occurrences["w_panel"]                                   # k ~ w^2, d ~ w: w I2
    2
    """
    options = ExtractionOptions(**options)
    problem = _problem(system, context, parameters, inputs, outputs)
    return _extract(problem, options, rng)


def _extract(problem, options: ExtractionOptions, rng=None) -> LFR:
    """Steps 1-4 of the module docstring on a bound problem (anything with ``linearize``)."""
    rtol, check_tolerance = options.rtol, options.check_tolerance
    rng = np.random.default_rng(0) if rng is None else rng
    nominal = problem.nominal
    h = np.array([0.5 * (b.parameter.upper - b.parameter.lower) for b in problem.bindings])
    cache: dict = {}

    def linearize(values):
        key = np.asarray(values, dtype=float).tobytes()
        if key not in cache:
            cache[key] = problem.linearize(values)
        return cache[key]

    lin0 = linearize(nominal)
    n, nu, ny = lin0["A"].shape[0], lin0["B"].shape[1], lin0["C"].shape[0]
    vdot = lin0["xdot"][problem.velocity_rows]
    if np.abs(vdot).max(initial=0.0) > 1e-9 * max(1.0, np.abs(lin0["xdot"]).max(initial=0.0)):
        raise ValueError(
            f"ulinearize: the context is not an equilibrium (max |v'| = {np.abs(vdot).max():.3g})"
        )
    Cd = problem.acceleration_map()
    modal = _ModalStates.of(problem) if options.scale_modal_states else _ModalStates.none()

    def evaluate(values):
        return modal.implicit(_implicit(problem, linearize(values), Cd), values, n, ny)

    R0, coefficients = _fit_axes(problem, evaluate, h)
    scale = _scales(R0, coefficients, h)
    if modal.parameters.size:  # keep the scaled angles that make omega affine, refit
        modal = modal.where_affine(evaluate, nominal, R0, coefficients, h, scale, check_tolerance)
        R0, coefficients = _fit_axes(problem, evaluate, h)
        for i in modal.parameters:  # exactly affine (checked): no round-off second channel
            coefficients[i] = (coefficients[i][0], np.zeros_like(R0))
        scale = _scales(R0, coefficients, h)
    for i, binding in enumerate(problem.bindings):  # degree <= 2 along each axis
        point = nominal.copy()
        point[i] = nominal[i] + 0.5 * h[i]
        error = np.abs(evaluate(point) - _model(R0, coefficients, nominal, point)) / scale
        if error.max() > check_tolerance:
            raise ValueError(
                f"parameter {binding.parameter.name!r}: the linearization is not polynomial of "
                f"degree <= 2 in it (fit error {error.max():.2e})"
            )
    names = [f"{name}[{k}]" for _, rows, name in problem.inputs for k in rows]
    out_names = [f"{name}[{k}]" for _, rows, name in problem.outputs for k in rows]
    lfr = _assemble(problem, R0, coefficients, h, scale, n, nu, ny, rtol, (names, out_names))
    _check(problem, lfr, linearize, h, options.check_points, check_tolerance, rng, modal)
    lfr = _balance_channels(_prune(lfr) if options.prune else lfr)
    missing = [
        b.parameter.name for b in problem.bindings if b.parameter.name not in lfr.uncertainty
    ]
    if missing and options.unused == "error":
        raise ValueError(
            f"parameter {missing[0]!r} does not change the linearization from "
            f"{[p[2] for p in problem.inputs]} to {[p[2] for p in problem.outputs]}"
        )
    return lfr


def _check(problem, lfr, linearize, h, count, tolerance, rng, modal):
    """Compare the LFR with Drake's linearization at random points (inside and outside), in
    the LFR's states (``modal``: the scaled angles)."""
    specs = [b.parameter for b in problem.bindings]
    for k in range(count):
        spread = 1.0 if k % 2 == 0 else 2.0  # half the points up to half a range outside
        values = np.array(
            [p.nominal + rng.uniform(-spread, spread) * hi for p, hi in zip(specs, h, strict=True)]
        )
        values = np.maximum(values, np.array([0.05 * p.nominal for p in specs]))
        lin = linearize(values)
        deltas = {
            p.name: float(p.spec.to_normalized(v, check=False))
            for p, v in zip(specs, values, strict=True)
            if p.name in lfr.uncertainty
        }
        model = usubs(lfr, deltas, normalized=True).nominal
        reference = modal.state_space(
            np.block([[lin["A"], lin["B"]], [lin["C"], lin["D"]]]), values
        )
        error = _relative(np.asarray(model.M), reference)
        if not error <= tolerance:
            worst = ", ".join(f"{p.name}={v:.6g}" for p, v in zip(specs, values, strict=True))
            raise ValueError(
                f"ulinearize: LFR differs from Drake's linearization by {error:.2e} (relative) at "
                f"{worst}; cross terms between parameters?"
            )


def sdf_plant(path):
    """Parse an SDF/URDF file into a finalized continuous ``MultibodyPlant`` without gravity.

    Returns
    -------
    (MultibodyPlant, Context)
        The plant and a default context (all positions and velocities zero).

    Raises
    ------
    ValueError
        Missing file or a file Drake's parser refuses (first line of its message).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such model file")
    plant = MultibodyPlant(time_step=0.0)
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    try:
        Parser(plant).AddModels(str(path))
    except RuntimeError as error:
        first = str(error).strip().splitlines()[0] if str(error).strip() else "parse error"
        raise ValueError(f"{path}: {first}") from None
    plant.Finalize()
    return plant, plant.CreateDefaultContext()
