"""``--plant lfr`` and ``--plant drake``: the same model array, hence the same controller.

The two sources are independent models of the spacecraft (TITOP LFR substitution, Drake
linearization of the multibody twin) that agree to ~1e-13. From the same start the optimizer makes
the same steps on both (checked for 20 iterations) until a discrete decision (line-search
acceptance, a tie between nearly active peaks) flips on round-off; after that the paths differ
like two runs from perturbed starts. "The same controller" over a whole synthesis is therefore
checked as (a) the same gamma within the optimizer's own reproducibility (1 %, as for perturbed
starts), (b) each gain giving the same closed-loop norms on the other source's plants, (c) gains
close relative to their block scale.
"""

import json

import numpy as np
import pytest

pytest.importorskip("pydrake")

from oos_drake.app.main import main  # noqa: E402
from oos_drake.app.synth import (  # noqa: E402
    ControllerOptions,
    baseline_for,
    compute_controller,
    make_plants,
)
from oos_drake.scenario.data import load_scenario  # noqa: E402

PAPER = load_scenario("paper")
from oos_drake.control.interconnection import weighted_interconnection  # noqa: E402
from oos_drake.control.synthesis import (  # noqa: E402
    ModelSet,
    SynthesisOptions,
    gamma_over,
    synthesize,
    tune,
)


def gain_difference(K1, K2):
    """Largest entry difference relative to the mean diagonal magnitude of its block."""
    scale = np.hstack(
        [
            np.full((3, 3), np.abs(np.diag(K1[:, :3])).mean()),
            np.full((3, 3), np.abs(np.diag(K1[:, 3:])).mean()),
        ]
    )
    return float(np.max(np.abs(K1 - K2) / scale))


def compare_sources(configurations, options):
    results, plants = {}, {}
    for kind in ("lfr", "drake"):
        plants[kind] = make_plants(kind, configurations, PAPER)
        results[kind] = synthesize(plants[kind], baseline_for(plants[kind]), options=options)
    return plants, results


def test_the_optimizer_takes_the_same_steps_on_both_sources():
    # from the same start the nonsmooth BFGS makes the same steps on both arrays until a
    # discrete decision (line search, active set) flips on round-off: ~20 iterations here
    plants = {kind: make_plants(kind, 3, PAPER) for kind in ("lfr", "drake")}
    K0 = baseline_for(plants["lfr"])
    np.testing.assert_allclose(baseline_for(plants["drake"]), K0, rtol=1e-9)
    runs = {
        kind: tune(weighted_interconnection(p.nominal()), K0, max_iterations=20)
        for kind, p in plants.items()
    }
    (K_lfr, gamma_lfr, res_lfr), (K_drake, gamma_drake, res_drake) = runs.values()
    assert res_lfr.iterations == res_drake.iterations == 20
    assert gamma_lfr < 0.25 * res_lfr.history[0]  # it did move
    # measured: 7e-11 (gamma) and 8e-10 (gains) after 20 iterations, 2e-9 after 25
    np.testing.assert_allclose(gamma_drake, gamma_lfr, rtol=1e-7)
    assert np.abs(K_drake - K_lfr).max() <= 1e-6 * np.abs(K_lfr).max()


def test_worst_case_search_runs_on_perturbed_drake_plants():
    options = SynthesisOptions(
        restarts=0,
        max_iterations=10,
        worst_case_rounds=1,
        worst_case_samples=4,
        worst_case_ascent_steps=1,
        worst_case_configurations=2,
        worst_case_rtol=-1.0,  # add the worst cases whatever they give
    )
    plants, results = compare_sources(3, options)
    for kind, result in results.items():
        added = result.models[result.models["worst_case"]]
        values = added[list(result.parameter_names)].to_numpy(dtype=float)
        assert len(added) == 2, kind
        assert np.all(np.any(values != plants[kind].nominal_values, axis=1)), kind
    # same worst-case points on both sources give the same closed-loop norms
    lfr, drake = results["lfr"], results["drake"]
    names = list(lfr.parameter_names)
    models = ModelSet(drake.models["config"].to_numpy(), drake.models[names].to_numpy(dtype=float))
    np.testing.assert_allclose(
        gamma_over(plants["lfr"], models, drake.K).gamma,
        gamma_over(plants["drake"], models, drake.K).gamma,
        rtol=1e-7,
    )


def _nominal(plants):
    N = plants.size
    return ModelSet(np.arange(N), np.broadcast_to(plants.nominal_values, (N, 8)))


@pytest.mark.slow
def test_full_mission_lfr_and_drake_give_the_same_controller(default_synthesis):
    # `oos synth` and `oos synth --plant drake`, default options (200 configurations, 2
    # restarts, up to 4 worst-case rounds); the LFR one is the session's default synthesis
    # (tests/conftest.py), shared with the headline checks. Measured: gamma 0.354278 (lfr) vs
    # 0.353896 (drake), gains 11.2 % of their block scale apart, and every gain on the segment
    # between them within 1 % of gamma: one flat optimal valley. (synthesize() directly, with
    # 1 restart: 0.35399 vs 0.35886, 1.4 % apart -- the optimizer's own spread.)
    record = json.loads((default_synthesis / "controller.json").read_text())
    gains = record["controller"]
    K_lfr = np.hstack([gains["K_p"]["value"], gains["K_d"]["value"]])
    gamma_lfr = record["gamma"]
    drake = compute_controller(PAPER, ControllerOptions(plant="drake"))
    K_drake, gamma_drake = drake.result.K, drake.result.gamma
    plants = {"lfr": make_plants("lfr", 200, PAPER), "drake": drake.plants}
    print(
        f"gamma lfr {gamma_lfr:.6g} drake {gamma_drake:.6g}; gain difference "
        f"{gain_difference(K_lfr, K_drake):.3g} of the block scale; drake wall "
        f"{drake.wall_time_s:.0f} s"
    )
    assert gamma_drake < 1.0
    # the same start: the baseline tuned on either array's configuration nearest the docking
    K0_lfr = baseline_for(plants["lfr"], PAPER.mission.first_docking_time)
    np.testing.assert_allclose(drake.K0, K0_lfr, rtol=1e-9)
    # the same gamma within the optimizer's own reproducibility (perturbed starts: 1 %)
    assert abs(gamma_drake - gamma_lfr) <= 0.01 * gamma_lfr, (gamma_lfr, gamma_drake)
    # each gain (and the start) on the other source's plants: identical closed loops
    for K in (K0_lfr, K_lfr, K_drake):
        per_source = [gamma_over(p, _nominal(p), K).gamma for p in plants.values()]
        np.testing.assert_allclose(per_source[1], per_source[0], rtol=1e-6)
    assert gain_difference(K_lfr, K_drake) < 0.3
    # one flat valley: every gain on the segment between them within 1 % of gamma
    for t in (0.25, 0.5, 0.75):
        K = (1 - t) * K_lfr + t * K_drake
        gamma = gamma_over(plants["lfr"], _nominal(plants["lfr"]), K).gamma.max()
        assert gamma <= 1.01 * max(gamma_lfr, gamma_drake)


def test_synth_with_drake_plants_end_to_end(tmp_path):
    out = tmp_path / "synth"
    status = main(
        [
            "synth",
            "--plant",
            "drake",
            "--configurations",
            "3",
            "--restarts",
            "0",
            "--max-iterations",
            "5",
            "--worst-case-rounds",
            "1",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    record = json.loads((out / "controller.json").read_text())
    assert record["model_source"] == "drake"
    assert record["gamma"] < record["gamma_baseline"]
    assert (out / "closed_loop.npz").exists() and (out / "models.parquet").exists()
