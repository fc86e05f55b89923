"""Drake plant arrays for the synthesis vs the TITOP LFR substitution (an independent model)."""

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.control.cli import mission_times, scenario_plants  # noqa: E402
from oos_drake.multibody.scenario_plant import cached_scenario_diagram  # noqa: E402
from oos_drake.multibody.synthesis_plants import (  # noqa: E402
    PADDING_POLE,
    DrakePlantSource,
    apply_physical_values,
    uncertain_parameters,
)

CONFIGURATIONS = 9  # 0 .. 1500 s every 187.5 s: free target, arm-held, docked, tilted
OMEGA = np.logspace(-3, 3, 400)  # rad/s


@pytest.fixture(scope="module")
def sources():
    times = mission_times(CONFIGURATIONS)
    return DrakePlantSource(times), scenario_plants(CONFIGURATIONS)


def relative_error(a, b):
    Ha, Hb = a.freqresp(OMEGA), b.freqresp(OMEGA)
    worst = np.linalg.norm(Ha - Hb, ord=2, axis=(-2, -1)).max(axis=-1)
    return worst / np.linalg.norm(Hb, ord=2, axis=(-2, -1)).max(axis=-1)


def test_parameters_are_the_lfr_blocks(sources):
    drake, lfr = sources
    plants = drake.plant_array()
    assert [p.name for p in plants.parameters] == [p.name for p in lfr.parameters]
    for ours, theirs in zip(plants.parameters, lfr.parameters, strict=True):
        np.testing.assert_allclose(
            [ours.nominal, ours.lower, ours.upper],
            [theirs.nominal, theirs.lower, theirs.upper],
            rtol=1e-12,
            err_msg=ours.name,
        )


def test_nominal_plants_agree_with_the_lfr(sources):
    drake, lfr = sources
    index = np.arange(CONFIGURATIONS)
    error = relative_error(drake.plant_array().evaluate(index), lfr.evaluate(index))
    assert error.max() < 1e-8, error


def test_perturbed_plants_agree_with_the_lfr(sources):
    drake, lfr = sources
    plants = drake.plant_array()
    lower, upper = plants.bounds
    rng = np.random.default_rng(3)
    index = np.array([0, 2, 5, 7])  # free, arm-held, docked, tilted
    values = np.vstack([lower, upper, *(lower + (upper - lower) * rng.random((2, lower.size)))])
    index = np.repeat(index, len(values))
    values = np.tile(values, (4, 1))
    ours = plants.evaluate(index, values)
    error = relative_error(ours, lfr.evaluate(index, values))
    assert error.max() < 1e-8, error
    # the values reach the model: the responses move well beyond the agreement level
    moved = relative_error(ours, plants.evaluate(index))
    assert moved.min() > 1e-3, moved


def test_free_target_models_are_padded_with_decoupled_states(sources):
    drake, _ = sources
    A, B, C, _ = (M[0] for M in drake.nominal_matrices)  # t = 0: target free, 24 states
    assert drake.order == 48
    padded = np.flatnonzero(np.all(B == 0, axis=1) & np.all(C == 0, axis=0))
    assert padded.size == 24
    np.testing.assert_array_equal(A[np.ix_(padded, padded)], PADDING_POLE * np.eye(24))
    rest = np.setdiff1d(np.arange(48), padded)
    assert not np.any(A[np.ix_(rest, padded)]) and not np.any(A[np.ix_(padded, rest)])


def test_perturbed_linearizations_are_cached(sources):
    drake, _ = sources
    plants = drake.plant_array()
    values = plants.bounds[1][None]
    plants.evaluate([3], values)
    count = drake.linearizations
    plants.evaluate([3, 3], np.vstack([values, values]))
    assert drake.linearizations == count


def test_unknown_parameter_is_a_clear_error():
    handles = cached_scenario_diagram("hub")
    context = handles.diagram.CreateDefaultContext()
    with pytest.raises(ValueError, match="w7_SA1"):
        apply_physical_values(handles, context, {"w7_SA1": 3.0})
    with pytest.raises(ValueError, match="m_RH2"):
        apply_physical_values(handles, context, {"m_RH2": -1.0})


def test_scenario_parameters_are_the_papers_delta_real():
    names = [p.name for p in uncertain_parameters()]
    assert names == sorted(
        ["m_RH2", "Jxx_RH2", "Jyy_RH2", "Jzz_RH2", "w1_SA1", "w1_SA2", "w1_SA3", "w1_SA4"]
    )
