"""Linearize a plant from the external wrench at the hub's centre of mass to the hub's motion.

The diagram built by :func:`add_hub_io` around a (finalized, continuous) MultibodyPlant has

- input port ``W_ext_G1`` (6): the external wrench ``[F; T]`` on the hub at ``G1`` in ``R_RH1``
  (hub body axes) [N, N m], mapped to the generalized forces of the hub's roll-pitch-yaw floating
  joint by :class:`HubWrenchToGeneralizedForce` (exact at any attitude, so the same diagram runs
  nonlinear simulations; templated so that ``FirstOrderTaylorApproximation`` differentiates it);
- output port ``y_G1`` (12): ``[a_G1; wdot; w; rpy]`` -- acceleration twist at ``G1``
  [m/s^2, rad/s^2], angular rate [rad/s], attitude angles [rad]; the vectors are expressed in the
  joint's parent frame, which is ``R_RH1`` at the operating point (linearization).

The hub's floating joint has its zero at the operating pose (see
:func:`oos_drake.multibody.plant_parts.add_floating_joint`), so at the linearization point its
velocities are body-frame quantities and the generalized-force map is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
from pydrake.math import RollPitchYaw_
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import FirstOrderTaylorApproximation, MatrixGain, Multiplexer
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = [
    "HUB_OUTPUT_NAMES",
    "HUB_INPUT_NAMES",
    "add_hub_io",
    "linearize_hub",
    "HubPorts",
    "structural_keep",
    "structural_prune",
    "HubWrenchToGeneralizedForce",
    "HubWrenchToGeneralizedForce_",
]

HUB_INPUT_NAMES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
HUB_OUTPUT_NAMES = (
    "ax", "ay", "az", "wdot_x", "wdot_y", "wdot_z",
    "wx", "wy", "wz", "roll", "pitch", "yaw",
)  # fmt: skip


@dataclass(frozen=True)
class HubPorts:
    """Names of the exported ports of a hub-I/O diagram."""

    wrench_input: str = "W_ext_G1"
    hub_output: str = "y_G1"


@TemplateSystem.define("HubWrenchToGeneralizedForce_")
def HubWrenchToGeneralizedForce_(T):
    """Map a body-frame wrench on the hub to the generalized forces of its floating joint.

    Inputs: ``W_B`` (6) ``[F; T]`` at the hub frame origin, hub axes [N, N m]; ``state``
    (``nq + nv``) the plant state. Output: ``tau`` (``nv``) with
    ``tau[w_FM] = R_FB T_B`` and ``tau[v_FM] = R_FB F_B`` (the joint's velocities are the angular
    velocity and the origin's velocity in the parent frame F; ``R_FB`` from its roll-pitch-yaw).
    """

    class Impl(LeafSystem_[T]):
        def _construct(self, nq, nv, position_start, velocity_start, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._args = (nq, nv, position_start, velocity_start)
            self.DeclareVectorInputPort("W_B", 6)
            self.DeclareVectorInputPort("state", nq + nv)
            self.DeclareVectorOutputPort("generalized_force", nv, self._calc)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        def _calc(self, context, output):
            nq, nv, qs, vs = self._args
            wrench = self.get_input_port(0).Eval(context)
            state = self.get_input_port(1).Eval(context)
            R = RollPitchYaw_[T](state[qs : qs + 3]).ToRotationMatrix().matrix()
            tau = np.zeros(nv, dtype=wrench.dtype) if T is float else np.array([T(0.0)] * nv)
            # written out: works for AutoDiffXd objects and avoids BLAS on 3x3 blocks
            for i in range(3):
                tau[vs + i] = R[i, 0] * wrench[3] + R[i, 1] * wrench[4] + R[i, 2] * wrench[5]
                tau[vs + 3 + i] = R[i, 0] * wrench[0] + R[i, 1] * wrench[1] + R[i, 2] * wrench[2]
            output.SetFromVector(tau)

    return Impl


HubWrenchToGeneralizedForce = HubWrenchToGeneralizedForce_[None]


def add_hub_io(builder: DiagramBuilder, plant: MultibodyPlant, hub_joint) -> HubPorts:
    """Add the wrench-input and hub-output maps around a finalized plant and export them.

    Parameters
    ----------
    builder : DiagramBuilder
        Builder that holds ``plant`` (added with ``AddNamedSystem``).
    plant : MultibodyPlant
        Finalized continuous plant.
    hub_joint : RpyFloatingJoint
        The hub's floating joint (child frame = hub frame with origin ``G1``).
    """
    nq, nv = plant.num_positions(), plant.num_velocities()
    qs, vs = hub_joint.position_start(), hub_joint.velocity_start()
    # RpyFloatingJoint: q = [rpy; p_FM], v = [w_FM; v_FM]; body wrench [F; T] -> tau = R [T; F].
    wrench_map = builder.AddNamedSystem(
        "wrench_G1_to_generalized_force", HubWrenchToGeneralizedForce(nq, nv, qs, vs)
    )
    builder.Connect(wrench_map.get_output_port(), plant.get_applied_generalized_force_input_port())
    builder.Connect(plant.get_state_output_port(), wrench_map.get_input_port(1))
    ports = HubPorts()
    builder.ExportInput(wrench_map.get_input_port(0), ports.wrench_input)

    mux = builder.AddNamedSystem("state_and_acceleration", Multiplexer([nq + nv, nv]))
    builder.Connect(plant.get_state_output_port(), mux.get_input_port(0))
    builder.Connect(plant.get_generalized_acceleration_output_port(), mux.get_input_port(1))
    C = np.zeros((12, 2 * nv + nq))
    vdot0 = nq + nv
    C[0:3, vdot0 + vs + 3 : vdot0 + vs + 6] = np.eye(3)  # a_G1
    C[3:6, vdot0 + vs : vdot0 + vs + 3] = np.eye(3)  # wdot
    C[6:9, nq + vs : nq + vs + 3] = np.eye(3)  # w
    C[9:12, qs : qs + 3] = np.eye(3)  # rpy
    selector = builder.AddNamedSystem("hub_output_selector", MatrixGain(C))
    builder.Connect(mux.get_output_port(), selector.get_input_port())
    builder.ExportOutput(selector.get_output_port(), ports.hub_output)
    return ports


def linearize_hub(diagram: Diagram, context, ports: HubPorts = HubPorts()) -> control.StateSpace:
    """Linearize ``diagram`` at ``context`` from ``W_ext_G1`` to ``y_G1``.

    Uses ``FirstOrderTaylorApproximation`` (no equilibrium requirement; at a consistent
    configuration with zero velocity the point is an equilibrium anyway).

    Returns
    -------
    control.StateSpace
        12 outputs ``[a; wdot; w; rpy]`` and 6 inputs ``[F; T]``; states are the plant's
        ``[q; v]``. Rows 0:6 are the 6x6 acceleration response.
    """
    input_index = diagram.GetInputPort(ports.wrench_input).get_index()
    output_index = diagram.GetOutputPort(ports.hub_output).get_index()
    wrench_port = diagram.get_input_port(input_index)
    if not wrench_port.HasValue(context):
        wrench_port.FixValue(context, np.zeros(6))  # operating point: no external wrench
    affine = FirstOrderTaylorApproximation(
        diagram, context, input_port_index=input_index, output_port_index=output_index
    )
    return control.ss(
        affine.A(),
        affine.B(),
        affine.C(),
        affine.D(),
        inputs=list(HUB_INPUT_NAMES),
        outputs=list(HUB_OUTPUT_NAMES),
    )


def structural_keep(edges: np.ndarray, sources: np.ndarray, sinks: np.ndarray) -> np.ndarray:
    """Nodes of a directed graph reachable from ``sources`` and reaching ``sinks``.

    Parameters
    ----------
    edges : numpy.ndarray of bool, shape (N, N)
        ``edges[i, j]``: node ``j`` drives node ``i``.
    sources, sinks : numpy.ndarray of bool, shape (N,)
        Nodes driven by an input, nodes read by an output.
    """
    edges = np.asarray(edges, dtype=bool)
    return _reached(edges, sinks) & _reached(edges.T, sources)


def _reached(edges: np.ndarray, start) -> np.ndarray:
    """Nodes that drive a ``start`` node through ``edges`` (``edges[i, j]``: ``j`` drives ``i``),
    ``start`` included."""
    reached = np.array(start, dtype=bool)
    frontier = reached.copy()
    while frontier.any():
        new = edges[frontier].any(axis=0) & ~reached
        reached |= new
        frontier = new
    return reached


def structural_prune(system: control.StateSpace, rtol: float = 1e-13) -> control.StateSpace:
    """Remove states that structurally cannot reach an output or be reached from an input.

    Entries ``|x| <= rtol * max|.|`` count as zero. In the Drake twin this removes exactly the
    chaser's rigid-body states (no force depends on its pose or velocity) and, when the target is
    free, the target's states; what remains is the minimal realization up to numerical
    cancellation.
    """
    A, B, C = (np.asarray(m, dtype=float) for m in (system.A, system.B, system.C))
    n = A.shape[0]
    if n == 0:
        return system
    scale = max(np.abs(A).max(initial=0.0), 1.0)
    edges = np.abs(A) > rtol * scale  # edges[i, j]: x_j drives xdot_i
    observable = np.abs(C).max(axis=0) > rtol * max(np.abs(C).max(initial=0.0), 1e-300)
    controllable = np.abs(B).max(axis=1) > rtol * max(np.abs(B).max(initial=0.0), 1e-300)
    keep = np.flatnonzero(structural_keep(edges, controllable, observable))
    return control.ss(
        A[np.ix_(keep, keep)], B[keep, :], C[:, keep], system.D,
        inputs=system.input_labels, outputs=system.output_labels,
    )  # fmt: skip
