"""Spec texts shared by the campaign tests, and a campaign directory made without running it."""

import textwrap
from pathlib import Path

from oos_drake.campaign.runner import _write_campaign, plan_campaign


def prepare_campaign(spec_path, out, worst_cases=None, simulator_options=None):
    """Validate the spec, build the plan, then (only then) create the campaign directory
    (arguments of :func:`~oos_drake.campaign.runner.plan_campaign`); returns the directory, the
    spec and the plan."""
    spec, plan = plan_campaign(spec_path, worst_cases, simulator_options)
    _write_campaign(Path(out), spec, plan)
    return Path(out), spec, plan


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
