"""Property tests: bounds ordered, both certificates valid, delta in the block structure."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from oos_drake.robust import mussv, parse_blk

block_row = st.one_of(
    st.tuples(st.integers(-3, -1), st.just(0)),  # repeated real
    st.tuples(st.integers(1, 3), st.just(0)),  # repeated complex
    st.tuples(st.integers(1, 3), st.integers(1, 3)),  # full
)


@settings(max_examples=40, deadline=None)
@given(
    blk=st.lists(block_row, min_size=1, max_size=4),
    seed=st.integers(0, 2**32 - 1),
    real_matrix=st.booleans(),
    scale=st.sampled_from([1e-150, 1e-3, 1.0, 1e3, 1e150]),
)
def test_bounds_ordered_and_certified(blk, seed, real_matrix, scale):
    structure = parse_blk(blk)
    c, r = structure.m_shape
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((2, c, r))
    if not real_matrix:
        M = M + 1j * rng.standard_normal((2, c, r))
    M = scale * M
    res = mussv(M, blk, upper_iterations=40, lower_iterations=30, lower_restarts=2)
    assert np.all(res.lower >= 0)
    assert np.all(res.lower <= res.upper * (1 + 1e-9))
    chk = res.check(M)
    assert np.all(chk["lmi_max_eig"] <= 1e-8)
    ok = res.lower > 0
    assert np.all(chk["singularity"][ok] <= 1e-7)
    assert np.all(np.abs(chk["delta_norm_error"][ok]) <= 1e-8)
    # delta lives in the structure: zero off the blocks, real on real blocks, scalar on repeated
    for block in structure.blocks:
        sub = res.delta[:, block.r_slice, block.c_slice]
        if block.repeated:
            d0 = sub[:, 0, 0]
            assert np.allclose(sub, d0[:, None, None] * np.eye(block.rows))
            if block.kind == "real":
                assert np.allclose(d0.imag, 0.0)
    off = res.delta.copy()
    for block in structure.blocks:
        off[:, block.r_slice, block.c_slice] = 0.0
    assert np.allclose(off, 0.0)
