"""Assemble TITOP blocks into one LFR by connecting named 6-DOF port signals.

Each component names its input and output signals (6 channels each: an acceleration twist or a
wrench). Every component input is either an external input of the assembly or the output of
exactly one component. The assembly is the block-diagonal append of the components closed by the
static interconnection ``u = Q y + R w`` (``z = S y``):

.. math::

    T_{w \\to z} = S\\, (I - G Q)^{-1} G\\, R

computed with :func:`oos_drake.lfr.feedback`, so the uncertain blocks keep their occurrences
(no new ones are created by the interconnection) and the algebraic loops of the TITOP models
(direct feedthrough of rigid bodies) are solved exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oos_drake.lfr import LFR, append, as_lfr, feedback

__all__ = ["Component", "assemble", "SIGNAL_WIDTH"]

#: Channels per port signal (6-DOF twist or wrench).
SIGNAL_WIDTH = 6


@dataclass(frozen=True)
class Component:
    """One block of an assembly.

    Parameters
    ----------
    name : str
        Component name (error messages).
    system : LFR
        The block; shape ``(6 * len(outputs), 6 * len(inputs))``.
    inputs, outputs : tuple of str
        Signal names of its 6-channel inputs and outputs, in channel order.
    """

    name: str
    system: LFR
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def __post_init__(self):
        object.__setattr__(self, "inputs", tuple(self.inputs))
        object.__setattr__(self, "outputs", tuple(self.outputs))
        expected = (SIGNAL_WIDTH * len(self.outputs), SIGNAL_WIDTH * len(self.inputs))
        if tuple(self.system.shape) != expected:
            raise ValueError(
                f"component {self.name!r}: system shape {tuple(self.system.shape)} does not match "
                f"{len(self.outputs)} output and {len(self.inputs)} input signals of width "
                f"{SIGNAL_WIDTH} (expected {expected})"
            )


def assemble(components: Sequence[Component], inputs: Sequence[str], outputs: Sequence[str]) -> LFR:
    """Connect components by signal names and return the LFR from ``inputs`` to ``outputs``.

    Parameters
    ----------
    components : sequence of Component
        The blocks.
    inputs : sequence of str
        External input signals (each 6 channels), in order.
    outputs : sequence of str
        Signals to expose as outputs (each must be a component output), in order.

    Returns
    -------
    LFR
        ``6 len(outputs) x 6 len(inputs)`` with every component's states and uncertain blocks.

    Raises
    ------
    ValueError
        A signal produced twice, an input signal nobody produces, an external input that is also
        produced, or an unknown output.
    """
    w = SIGNAL_WIDTH
    produced: dict[str, int] = {}
    y_offset = 0
    for component in components:
        for signal in component.outputs:
            if signal in produced:
                raise ValueError(
                    f"signal {signal!r} is produced twice (component {component.name!r})"
                )
            produced[signal] = y_offset
            y_offset += w
    ny = y_offset
    external = {}
    for k, signal in enumerate(inputs):
        if signal in produced:
            raise ValueError(f"external input {signal!r} is also a component output")
        if signal in external:
            raise ValueError(f"external input {signal!r} listed twice")
        external[signal] = k * w
    nu = w * sum(len(c.inputs) for c in components)
    q = np.zeros((nu, ny))
    r = np.zeros((nu, w * len(inputs)))
    u_offset = 0
    used_external = set()
    for component in components:
        for signal in component.inputs:
            rows = slice(u_offset, u_offset + w)
            if signal in produced:
                q[rows, produced[signal] : produced[signal] + w] = np.eye(w)
            elif signal in external:
                r[rows, external[signal] : external[signal] + w] = np.eye(w)
                used_external.add(signal)
            else:
                raise ValueError(
                    f"component {component.name!r}: input signal {signal!r} is neither an "
                    "external input nor produced by a component"
                )
            u_offset += w
    unused = [s for s in inputs if s not in used_external]
    if unused:
        raise ValueError(f"external inputs {unused} drive no component")
    s = np.zeros((w * len(outputs), ny))
    for k, signal in enumerate(outputs):
        if signal not in produced:
            raise ValueError(f"output signal {signal!r} is not produced by any component")
        s[k * w : (k + 1) * w, produced[signal] : produced[signal] + w] = np.eye(w)
    plant = append(*[c.system for c in components])
    closed = feedback(plant, as_lfr(q), sign=+1)
    return s @ closed @ r
