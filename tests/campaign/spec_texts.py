"""Spec texts shared by the campaign tests."""

import textwrap

#: A small, quick spec (runs of ~5 ms); tests append or replace sections.
BASE_SPEC = textwrap.dedent(
    """
    name = "small"
    n_runs = 12
    random_seed = 7
    sampler = "monte-carlo"
    metrics = ["ape", "peak_torque"]

    [simulator]
    name = "flexible-attitude"
    options = { control_rate = 5.0 }

    [window]
    kind = "event"
    event = "capture"
    before = 5.0
    after = 40.0

    [dispersions]
    J_hub = { distribution = "uniform", low = 400.0, high = 600.0 }
    k_dock = { distribution = "log-uniform", low = 1.0e2, high = 1.0e5 }
    omega_capture = { distribution = "normal", mean = 0.0, std = 0.004 }

    [requirements]
    ape = { max = 0.0079 }
    peak_torque = { max = 2.0 }

    [timeseries]
    keep = "all"
    signals = ["theta_hub", "torque_command"]
    """
)
