"""The synthesis' plant array from LFRs handed over per configuration (the Drake twin's form,
:func:`oos_drake.control.plants.lfr_source_plants`), against the same plants substituted the
other way (:func:`oos_drake.control.plants.from_lfr`: the scheduled LFR array, one batched
substitution) and against transfer functions computed directly (``C (sI - A)^-1 B + D``)."""

import numpy as np
import pandas as pd
import pytest

from oos_drake.control.analysis_model import rotational_channels
from oos_drake.control.plants import from_lfr, lfr_source_plants
from oos_drake.lfr import LFR, usubs
from oos_drake.scenario.model import build_mission_model, mission_values


def transfer(A, B, C, D, s):
    return C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B) + D


@pytest.fixture(scope="module")
def paper_models(paper_scenario):
    scenario = paper_scenario
    times = np.array([0.0, 400.0, 900.0, 1400.0])
    model = rotational_channels(build_mission_model(scenario))
    values = mission_values(times, scenario)
    reference = from_lfr(model, values, pd.DataFrame({"time [s]": times}))
    scheduled = usubs(model, values)
    return times, scheduled, reference


def test_lfrs_per_configuration_give_the_scheduled_arrays_plants(paper_models):
    times, scheduled, reference = paper_models
    nominal = reference.nominal()
    certain = [
        LFR.from_ss(nominal.A[i], nominal.B[i], nominal.C[i], nominal.D[i])
        for i in range(times.size)
    ]
    visited = []

    def uncertain(i):
        visited.append(int(i))
        return scheduled.model(int(i))

    plants = lfr_source_plants(
        pd.DataFrame({"time [s]": times}),
        certain,
        uncertain,
        reference.parameters,
        padding_pole=-1.0,
        source="test",
    )
    lower, upper = plants.bounds
    rng = np.random.default_rng(2)
    index = np.array([0, 1, 1, 3, 2])
    values = lower + (upper - lower) * rng.random((index.size, lower.size))
    values[2] = plants.nominal_values  # a nominal row: no uncertain LFR needed for it
    ours, theirs = plants.evaluate(index, values), reference.evaluate(index, values)
    for k in range(index.size):
        for s in (0.3j, 2.0j, 20.0j):
            np.testing.assert_allclose(
                transfer(ours.A[k], ours.B[k], ours.C[k], ours.D[k], s),
                transfer(theirs.A[k], theirs.B[k], theirs.C[k], theirs.D[k], s),
                rtol=1e-9,
                atol=1e-12,
            )
    assert sorted(set(visited)) == [0, 1, 2, 3]
    # the values reach the models: a perturbed plant differs from the nominal one
    moved = transfer(ours.A[0], ours.B[0], ours.C[0], ours.D[0], 2.0j)
    assert not np.allclose(
        moved, transfer(nominal.A[0], nominal.B[0], nominal.C[0], nominal.D[0], 2.0j)
    )


def test_smaller_models_are_padded_with_decoupled_states_at_the_pole():
    rng = np.random.default_rng(0)
    small = [rng.normal(size=shape) for shape in ((2, 2), (2, 3), (3, 2), (3, 3))]
    large = [rng.normal(size=shape) for shape in ((5, 5), (5, 3), (3, 5), (3, 3))]
    plants = lfr_source_plants(
        pd.DataFrame({"time [s]": [0.0, 1.0]}),
        [LFR.from_ss(*small), LFR.from_ss(*large)],
        lambda i: pytest.fail("no uncertain model is needed at the nominal values"),
        (),
        padding_pole=-7.0,
        source="test",
    )
    sys = plants.nominal()
    assert sys.A.shape == (2, 5, 5)
    np.testing.assert_array_equal(sys.A[0, 2:, 2:], -7.0 * np.eye(3))
    assert not sys.B[0, 2:].any() and not sys.C[0, :, 2:].any() and not sys.A[0, :2, 2:].any()
    for k, matrices in enumerate((small, large)):
        np.testing.assert_allclose(
            transfer(sys.A[k], sys.B[k], sys.C[k], sys.D[k], 1.5j),
            transfer(*matrices, 1.5j),
            rtol=1e-12,
        )


def test_uncertain_nominal_models_are_refused(paper_models):
    _, scheduled, reference = paper_models
    with pytest.raises(ValueError, match="certain LFRs"):
        lfr_source_plants(
            pd.DataFrame({"time [s]": [0.0]}),
            [scheduled.model(0)],
            scheduled.model,
            reference.parameters,
            padding_pole=-1.0,
            source="test",
        )
