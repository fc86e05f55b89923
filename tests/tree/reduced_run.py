"""``oos run`` at reduced sizes for the trees' end-to-end tests: every stage's options made
smaller, as the stages' command lines were before they became function calls."""

from __future__ import annotations

import dataclasses


def reduce_run_stages(monkeypatch, *, skip: dict[str, str] | None = None) -> None:
    """Make ``oos run``'s stages small: synthesis on 4 configurations (no restart, 25
    iterations, one worst-case round); analysis as
    ``oos analyze --configurations 4 --points-per-decade 3 --no-sensitivity --no-time-check
    --performance-models 1 --performance-points 5 --docking-points 3 --spike-budget 5
    --iterations 20``; margins on 2 configurations; the confirmation searched up to
    ``alpha = 2`` (``--alpha-limit 2``: flexible_satellite's real and modal physical limit is
    1.6); ``skip`` adds stages the run leaves out (name -> reason)."""
    import oos_drake.app.analyze as analyze
    import oos_drake.app.synth as synth
    import oos_drake.scenario.tree_scenario as tree_scenario
    from oos_drake.analysis.confirm import ConfirmOptions
    from oos_drake.analysis.margins import MarginsOptions

    controller_options = synth.pipeline_controller_options
    monkeypatch.setattr(  # oos synth --configurations 4 --restarts 0 --max-iterations 25 ...
        synth,
        "pipeline_controller_options",
        lambda **kwargs: dataclasses.replace(
            controller_options(**kwargs),
            configurations=4,
            restarts=0,
            max_iterations=25,
            worst_case_rounds=1,
        ),
    )
    monkeypatch.setattr(
        analyze,
        "pipeline_margins_options",
        lambda analysis, configurations: MarginsOptions(2, analysis, False),
    )
    confirm_options = analyze.pipeline_confirm_options
    monkeypatch.setattr(
        analyze,
        "pipeline_confirm_options",
        lambda *args, **kwargs: dataclasses.replace(
            confirm_options(*args, **kwargs), twin=ConfirmOptions(alpha_limit=2.0)
        ),
    )
    full = analyze.pipeline_analysis_options

    def smaller_analysis(*args, **kwargs):
        options = full(*args, **kwargs)
        return dataclasses.replace(
            options,
            configurations=4,
            points_per_decade=3,
            sensitivity=False,
            time_check=False,
            performance_models=1,
            performance_points=5,
            docking_points=3,
            spike_budget=5.0,
            sweep=dataclasses.replace(options.sweep, upper_iterations=20),
        )

    monkeypatch.setattr(analyze, "pipeline_analysis_options", smaller_analysis)
    if skip:
        unsupported = tree_scenario.unsupported_stages
        monkeypatch.setattr(
            tree_scenario, "unsupported_stages", lambda scenario: {**unsupported(scenario), **skip}
        )


def sweep_peak(loops) -> float:
    """Largest singular value of the closed loops ``loops`` (``closed_loop.npz``: batched A, B,
    C, D and each loop's ``omega_peak_rad_s``) over a dense frequency sweep (1e-4 to 1e3
    rad/s, 4000 points, plus 81 points within 2 % of each recorded peak): a second method for
    the synthesis' gamma, computed here by ``C (jw I - A)^-1 B + D``."""
    import numpy as np

    near_peaks = loops["omega_peak_rad_s"][:, None] * np.geomspace(0.98, 1.02, 81)
    w = np.unique(np.concatenate([np.geomspace(1e-4, 1e3, 4000), near_peaks.ravel()]))
    peak = 0.0
    n = loops["A"].shape[1]
    for A, B, C, D in zip(loops["A"], loops["B"], loops["C"], loops["D"], strict=True):
        H = C @ np.linalg.solve(1j * w[:, None, None] * np.eye(n) - A, B) + D
        peak = max(peak, float(np.linalg.svd(H, compute_uv=False)[:, 0].max()))
    return peak


def assert_stable_at_range_corners(controller_file, scenario, times) -> None:
    """The analysis' closed loops (sensors, wheel, roll-off, the ``Delta_add``/``Delta_mul``
    channels) with the controller of ``controller_file``, at configurations ``times`` [s]:
    stable with every real uncertain block at the low end, then at the high end of its range
    (eigenvalues of the substituted closed loop, computed here)."""
    import numpy as np

    from oos_drake.analysis.controller import scenario_controller
    from oos_drake.analysis.models import mission_closed_loop
    from oos_drake.lfr import usubs

    controller = scenario_controller(controller_file, scenario)
    times = np.asarray(times, dtype=float)
    closed = mission_closed_loop(controller, times, scenario).system
    for corner in (0, 1):
        values = {
            name: np.full(times.size, block.range[corner])
            for name, block in closed.uncertainty.items()
            if block.kind == "ureal"
        }
        A = np.asarray(usubs(closed, values).nominal.A)
        assert np.linalg.eigvals(A).real.max() < 0, corner
