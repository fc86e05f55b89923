"""Hypothesis: LFR algebra + usubs equals python-control built directly with the same values."""

import control
import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from lfr_helpers import assert_response_close, control_response, random_ss

from oos_drake.lfr import feedback, inv, ureal, usubs

OMEGA = np.array([0.07, 0.6, 3.1, 17.0])


def _ureals():
    return [
        ureal("a", 1.0, percent=40),
        ureal("b", 2.0, range=(1.0, 5.0)),  # asymmetric: bilinear
        ureal("c", -0.5, plusminus=[-0.3, 0.2]),
    ]


@st.composite
def scenarios(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    n1, n2, n3 = (draw(st.integers(0, 3)) for _ in range(3))
    size = draw(st.integers(1, 2))
    ops = draw(
        st.lists(
            st.sampled_from(["series", "parallel", "feedback", "gain", "inverse", "sub", "rmul"]),
            min_size=1,
            max_size=5,
        )
    )
    deltas = draw(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3))
    return seed, (n1, n2, n3), size, ops, deltas


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_algebra_then_usubs_equals_control(scenario):
    seed, orders, size, ops, deltas = scenario
    rng = np.random.default_rng(seed)
    blocks = _ureals()
    specs = [b.uncertainty[name] for b, name in zip(blocks, "abc", strict=True)]
    values = [float(spec.to_physical(d)) for spec, d in zip(specs, deltas, strict=True)]
    systems = [random_ss(rng, n, size, size, d_scale=0.2) for n in orders]
    lfr_expr = systems[0] * blocks[0]
    ctl_expr = systems[0] * values[0]
    for k, op in enumerate(ops):
        other = systems[(k + 1) % 3]
        j = k % 3
        if op == "series":
            lfr_expr, ctl_expr = lfr_expr * (blocks[j] * other), ctl_expr * (values[j] * other)
        elif op == "parallel":
            lfr_expr, ctl_expr = lfr_expr + other * blocks[j], ctl_expr + other * values[j]
        elif op == "sub":
            lfr_expr, ctl_expr = blocks[j] * other - lfr_expr, values[j] * other - ctl_expr
        elif op == "rmul":
            gain = rng.standard_normal((size, size))
            lfr_expr, ctl_expr = gain * lfr_expr, control.ss(ctl_expr).__rmul__(gain)
        elif op == "feedback":
            lfr_expr = feedback(lfr_expr, blocks[j] * other, sign=-1)
            ctl_expr = control.feedback(ctl_expr, values[j] * other, sign=-1)
        elif op == "gain":
            lfr_expr, ctl_expr = lfr_expr * blocks[j], ctl_expr * values[j]
        elif op == "inverse":
            shift = 3.0 * np.eye(size)
            lfr_expr = inv(lfr_expr + shift * blocks[1])
            ctl_expr = control.ss(ctl_expr + shift * values[1]) ** -1
    try:
        closed = usubs(
            lfr_expr,
            {
                name: v
                for name, v in zip("abc", values, strict=True)
                if name in lfr_expr.occurrences
            },
        )
    except ValueError:
        assume(False)
    ctl_ss = control.ss(ctl_expr)
    assume(ctl_ss.nstates < 40)
    expected = control_response(ctl_ss, OMEGA)
    assume(np.all(np.isfinite(expected)) and np.max(np.abs(expected)) < 1e8)
    # conditioning guard: skip near-singular interconnections (both sides are then inaccurate)
    poles = np.linalg.eigvals(ctl_ss.A) if ctl_ss.nstates else np.zeros(0)
    assume(np.all(np.min(np.abs(1j * OMEGA[:, None] - poles[None, :]), axis=1, initial=1.0) > 1e-3))
    assert_response_close(closed.freqresp(OMEGA), expected, rtol=1e-9)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_reduce_preserves_the_substituted_response(scenario):
    seed, orders, size, ops, deltas = scenario
    rng = np.random.default_rng(seed)
    blocks = _ureals()
    systems = [random_ss(rng, n, size, size, d_scale=0.2) for n in orders]
    expr = systems[0] * blocks[0]
    for k, op in enumerate(ops):
        other = systems[(k + 1) % 3]
        j = k % 3
        if op in ("series", "gain"):
            expr = expr * (blocks[j] * other)
        elif op in ("parallel", "rmul"):
            expr = expr + other * blocks[j] + other * blocks[j]  # deliberately redundant
        elif op == "sub":
            expr = blocks[j] * other - expr
        elif op == "feedback":
            expr = feedback(expr, blocks[j] * other)
        elif op == "inverse":
            expr = inv(expr + 3.0 * np.eye(size) * blocks[1])
    try:
        red = expr.reduce()
    except ValueError:
        assume(False)
    assert red.nstates <= expr.nstates
    for name, reps in red.occurrences.items():
        assert reps <= expr.occurrences[name]
    values = {
        name: np.array([-1.0, d, 1.0])
        for name, d in zip("abc", deltas, strict=True)
        if name in expr.occurrences
    }
    try:
        full = usubs(expr, values, normalized=True).freqresp(OMEGA)
    except ValueError:
        assume(False)
    small = usubs(
        red, {k: v for k, v in values.items() if k in red.occurrences}, normalized=True
    ).freqresp(OMEGA)
    assume(np.all(np.isfinite(full)) and np.max(np.abs(full)) < 1e6)
    scale = np.max(np.abs(full), axis=(-2, -1), keepdims=True)
    # the rank decisions use an absolute threshold 1e-10 ||M||: directions below it may be dropped,
    # so tiny responses (products of small random feedthroughs) are compared absolutely
    slack = 1e-9 * max(1.0, float(np.linalg.norm(expr.M)))
    assert np.all(np.abs(small - full) <= 1e-7 * scale + slack)
