"""Drake plant arrays for the synthesis vs the TITOP LFR substitution (an independent model).

The Drake source's plants at non-nominal parameter values come from LFRs extracted from the twin
(``ulinearize``); they are held to the TITOP LFR substituted at the same values, and to an
independent computation: the twin relinearized with the values written into its Context
(``rotational_plant(configuration, values)``), compared by closed-loop poles and H-infinity
norms (Hamiltonian bisection, not the synthesis' modal evaluation).
"""

import numpy as np
import pytest

pytestmark = pytest.mark.drake
pytest.importorskip("pydrake")

from oos_drake.app.synth import mission_times, scenario_plants, source_plants  # noqa: E402
from oos_drake.control.baseline import baseline_gains, inertia_from_plant  # noqa: E402
from oos_drake.control.interconnection import (  # noqa: E402
    plant_statespace,
    weighted_interconnection,
)
from oos_drake.control.plants import _pad  # noqa: E402
from oos_drake.control.synthesis import SynthesisOptions, _worst_case_search, tune  # noqa: E402
from oos_drake.multibody.mission_lfr import uncertain_parameters  # noqa: E402
from oos_drake.multibody.scenario_plant import twin_diagram  # noqa: E402
from oos_drake.multibody.synthesis_plants import (  # noqa: E402
    PADDING_POLE,
    DrakePlantSource,
    apply_physical_values,
    rotational_plant,
)
from oos_drake.robust.hinf import hinfnorm  # noqa: E402

CONFIGURATIONS = 9  # 0 .. 1500 s every 187.5 s: free target, arm-held, docked, tilted
OMEGA = np.logspace(-3, 3, 400)  # rad/s


@pytest.fixture(scope="module")
def sources(paper_scenario):
    times = mission_times(CONFIGURATIONS, paper_scenario)
    return DrakePlantSource(times, paper_scenario), scenario_plants(CONFIGURATIONS, paper_scenario)


def plant_array(drake):
    """The synthesis' plant array of a Drake source (as ``oos synth --plant drake`` makes it)."""
    return source_plants(drake, PADDING_POLE)


def relative_error(a, b):
    Ha, Hb = a.freqresp(OMEGA), b.freqresp(OMEGA)
    worst = np.linalg.norm(Ha - Hb, ord=2, axis=(-2, -1)).max(axis=-1)
    return worst / np.linalg.norm(Hb, ord=2, axis=(-2, -1)).max(axis=-1)


def test_parameters_are_the_lfr_blocks(sources):
    drake, lfr = sources
    plants = plant_array(drake)
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
    error = relative_error(plant_array(drake).evaluate(index), lfr.evaluate(index))
    assert error.max() < 1e-8, error


def test_perturbed_plants_agree_with_the_lfr(sources):
    drake, lfr = sources
    plants = plant_array(drake)
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
    assert drake.nominal[0].nstates == 24  # t = 0: target free
    nominal = plant_array(drake).nominal()
    A, B, C = nominal.A[0], nominal.B[0], nominal.C[0]
    assert A.shape == (48, 48)
    padded = np.flatnonzero(np.all(B == 0, axis=1) & np.all(C == 0, axis=0))
    assert padded.size == 24
    np.testing.assert_array_equal(A[np.ix_(padded, padded)], PADDING_POLE * np.eye(24))
    rest = np.setdiff1d(np.arange(48), padded)
    assert not np.any(A[np.ix_(rest, padded)]) and not np.any(A[np.ix_(padded, rest)])


def test_each_configuration_is_extracted_once_and_nothing_is_relinearized(paper_scenario):
    drake = DrakePlantSource(mission_times(3, paper_scenario), paper_scenario)
    plants = plant_array(drake)
    lower, upper = plants.bounds
    plants.evaluate([1, 1], np.vstack([lower, upper]))
    plants.evaluate([1, 1, 2], np.vstack([upper, lower, plants.nominal_values]))
    statistics = drake.statistics()
    assert statistics["lfr_extractions"] == 1  # configuration 1 only; nominal rows need none
    assert statistics["nominal_linearizations"] == 3
    assert set(drake._lfrs) == {1}


def _closed_loops(A, B, C, D, K):
    return weighted_interconnection(plant_statespace(A, B, C, D)).close(K)


def _poles_match(a, b, rtol):
    """Every eigenvalue of ``a`` has one of ``b`` within ``rtol`` (relative to its size)."""
    distance = np.abs(a[:, None] - b[None, :]).min(axis=1)
    return np.all(distance <= rtol * np.maximum(np.abs(a), 1e-3))


def test_extracted_plants_equal_the_twin_relinearized_with_the_values(sources):
    # the independent reference: the values written into the twin's Context, relinearized
    drake, _ = sources
    plants = plant_array(drake)
    lower, upper = plants.bounds
    rng = np.random.default_rng(7)
    index = np.array([0, 5, 5])  # free target (its blocks absent from its LFR), docked
    values = np.vstack([upper, lower, lower + (upper - lower) * rng.random(lower.size)])
    names = [p.name for p in plants.parameters]
    reference = [
        _pad(
            *rotational_plant(
                drake.configurations[i], drake.scenario, dict(zip(names, v, strict=True))
            ),
            48,
            PADDING_POLE,
        )
        for i, v in zip(index, values, strict=True)
    ]
    A, B, C, D = (np.stack([m[k] for m in reference]) for k in range(4))
    error = relative_error(plants.evaluate(index, values), plant_statespace(A, B, C, D))
    assert error.max() < 1e-8, error
    assert relative_error(plants.evaluate(index), plant_statespace(A, B, C, D))[1:].min() > 1e-3


@pytest.mark.slow
def test_worst_case_search_equals_the_titop_path_and_drake_relinearized(sources):
    # the synthesis' worst-case search on both sources from the same gain and seed; the points
    # it finds, closed with the gain, against the twin relinearized with the values in its
    # Context (independent of the LFR extraction) and the TITOP LFR substituted
    drake, lfr = sources
    plants = {"drake": plant_array(drake), "lfr": lfr}
    # a gain tuned a little (the baseline's peak, gamma ~11, does not depend on Delta_real)
    K0 = baseline_gains(inertia_from_plant(lfr.evaluate([2]))[0])
    K = tune(weighted_interconnection(lfr.nominal()), K0, max_iterations=15)[0]
    configs = np.array([0, 2, 5, 7])  # free target, arm-held, docked, tilted arrays
    options = SynthesisOptions(worst_case_samples=4, worst_case_ascent_steps=1)
    found = {
        kind: _worst_case_search(p, configs, K, None, options, np.random.default_rng(5))
        for kind, p in plants.items()
    }
    np.testing.assert_allclose(found["drake"][1], found["lfr"][1], rtol=1e-7)
    assert drake.statistics()["nominal_linearizations"] == CONFIGURATIONS  # no relinearization
    # off-nominal points everywhere: the search's, else (nominal worst case) the upper corner
    off = np.any(found["drake"][0] != plants["drake"].nominal_values, axis=1)
    assert off.sum() >= 2, found["drake"][0]
    values = np.where(off[:, None], found["drake"][0], plants["drake"].bounds[1])
    names = [p.name for p in plants["drake"].parameters]
    ours = plants["drake"].evaluate(configs, values)
    theirs = lfr.evaluate(configs, values)
    for k, c in enumerate(configs):
        reference = _pad(
            *rotational_plant(
                drake.configurations[c], drake.scenario, dict(zip(names, values[k], strict=True))
            ),
            48,
            PADDING_POLE,
        )
        loops = {
            "drake": _closed_loops(ours.A[k], ours.B[k], ours.C[k], ours.D[k], K),
            "lfr": _closed_loops(theirs.A[k], theirs.B[k], theirs.C[k], theirs.D[k], K),
            "relinearized": _closed_loops(*reference, K),
        }
        norms = {n: hinfnorm((m.A, m.B, m.C, m.D), tol=1e-10).norm for n, m in loops.items()}
        poles = {n: np.linalg.eigvals(loops[n].A) for n in ("drake", "relinearized")}
        assert np.all(poles["relinearized"].real < 0), c
        for kind in ("drake", "lfr"):
            np.testing.assert_allclose(norms[kind], norms["relinearized"], rtol=1e-7, err_msg=kind)
        # same realization family (both padded alike; TITOP keeps a free target's own modes as
        # decoupled states instead): the closed-loop poles too
        assert _poles_match(poles["drake"], poles["relinearized"], 1e-6), c
        if off[k]:  # the search's own value (the synthesis' modal evaluation) is that norm
            np.testing.assert_allclose(found["drake"][1][k], norms["relinearized"], rtol=1e-5)
    # the values reach the model: the worst cases raise the nominal loops' norms
    nominal = plants["drake"].evaluate(configs)
    nominal_norms = np.array([
        hinfnorm((m.A, m.B, m.C, m.D)).norm
        for m in [_closed_loops(nominal.A[k], nominal.B[k], nominal.C[k], nominal.D[k], K)
                  for k in range(configs.size)]
    ])  # fmt: skip
    print("worst / nominal closed-loop norms:", found["drake"][1] / nominal_norms)
    assert np.all(found["drake"][1] >= nominal_norms * (1 - 1e-7))
    assert np.max(found["drake"][1] / nominal_norms) > 1.001  # measured 1.002


def test_unknown_parameter_is_a_clear_error(paper_scenario):
    handles = twin_diagram(paper_scenario, "hub")
    context = handles.diagram.CreateDefaultContext()
    with pytest.raises(ValueError, match="w7_SA1"):
        apply_physical_values(handles, context, {"w7_SA1": 3.0}, paper_scenario)
    with pytest.raises(ValueError, match="m_RH2"):
        apply_physical_values(handles, context, {"m_RH2": -1.0}, paper_scenario)


def test_scenario_parameters_are_the_papers_delta_real(paper_scenario):
    names = [p.name for p in uncertain_parameters(paper_scenario)]
    assert names == sorted(
        ["m_RH2", "Jxx_RH2", "Jyy_RH2", "Jzz_RH2", "w1_SA1", "w1_SA2", "w1_SA3", "w1_SA4"]
    )
