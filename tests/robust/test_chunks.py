"""Big batches in chunks (``oos_drake.robust.memory.in_chunks``/``joined``): a chunked call
returns what separate calls on the same slices return, field by field."""

from dataclasses import dataclass, fields

import numpy as np
import pytest

from oos_drake.robust import memory, mu_lower, mu_upper
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.mu_lower import LowerBoundResult, mu_lower_bound
from oos_drake.robust.mu_upper import UpperBoundResult, mu_upper_bound

BLK = [[-2, 0], [1, 1], [2, 0]]


@dataclass
class _Sum:
    total: np.ndarray


def _batch(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, 5, 5)) + 1j * rng.standard_normal((n, 5, 5))


def _assert_joined(result, parts):
    for f in fields(result):
        got, ref = getattr(result, f.name), [getattr(p, f.name) for p in parts]
        if f.name == "iterations":
            assert got == max(ref)
        elif any(r is None for r in ref):
            assert got is None
        else:
            np.testing.assert_array_equal(got, np.concatenate(ref), err_msg=f.name)


def test_upper_bound_in_chunks_equals_the_calls_on_the_slices(monkeypatch):
    s, M = parse_blk(BLK), _batch(5)
    x0 = mu_upper_bound(M, s, max_iter=3).params
    monkeypatch.setattr(mu_upper, "CHUNK", 2)
    got = mu_upper_bound(M, s, max_iter=8, x0=x0)
    parts = [mu_upper_bound(M[i : i + 2], s, max_iter=8, x0=x0[i : i + 2]) for i in (0, 2, 4)]
    assert isinstance(got, UpperBoundResult)
    _assert_joined(got, parts)


def test_lower_bound_in_chunks_equals_the_calls_on_the_slices(monkeypatch):
    s, M = parse_blk(BLK), _batch(5, seed=1)
    starts = _batch(5, seed=2)[:, 0, :]
    monkeypatch.setattr(mu_lower, "CHUNK", 2)
    got = mu_lower_bound(M, s, start_inputs=starts, rng=np.random.default_rng(3))
    rng = np.random.default_rng(3)  # one generator through the chunks, as in the chunked call
    parts = [
        mu_lower_bound(M[i : i + 2], s, start_inputs=starts[i : i + 2], rng=rng) for i in (0, 2, 4)
    ]
    assert isinstance(got, LowerBoundResult)
    _assert_joined(got, parts)


def test_joined_merges_dicts_and_keeps_none():
    @dataclass
    class Part:
        values: np.ndarray
        extra: np.ndarray | None
        count: int
        found: dict

    parts = [Part(np.arange(2), None, 3, {0: "a"}), Part(np.arange(3), np.ones(1), 5, {1: "b"})]
    got = memory.joined(Part, parts)
    np.testing.assert_array_equal(got.values, [0, 1, 0, 1, 2])
    assert got.extra is None and got.count == 5 and got.found == {0: "a", 1: "b"}


@pytest.mark.parametrize("size", [1, 2, 7])
def test_in_chunks_slices_only_the_per_matrix_arguments(size):
    M = np.arange(12.0).reshape(6, 2)
    seen = []

    def call(M, *, w, scale):
        seen.append((M.shape[0], None if w is None else w.shape[0], scale))
        return _Sum(M.sum(axis=1) * scale + (0 if w is None else w))

    got = memory.in_chunks(call, M, size, _Sum, {"w": np.ones(6)}, scale=2.0)
    np.testing.assert_array_equal(got.total, M.sum(axis=1) * 2.0 + 1.0)
    assert all(n == w and s == 2.0 for n, w, s in seen)
    assert [n for n, _, _ in seen] == [min(size, 6 - i) for i in range(0, 6, size)]
