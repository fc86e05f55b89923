"""systune's working set: hard goals hold on EVERY model of the array, not only the tuned ones.

A family of two-mass plants (``test_systune.two_mass``, spring ``k`` [N/m]) whose flexible
frequency varies along a parameter ``p`` in [0, 1] and is lowest in the middle:
``k(p) = 0.3 + 2.7 (2 p - 1)^2``. A PID tuned with hard margins on the two ends (``k = 3``)
meets the goal there but not in between; with the working set started at the two ends, every
model checked and the violators added, the margins hold on all nine models. Every margin is
checked independently of the systune code: python-control's ``stability_margins`` on the loop
broken at ``u`` (python-control's own products of the plant and the returned controller) and
the balanced disk margin's closed form ``1 / max |1 / (1 + L) - 1/2|`` on a dense grid.
"""

import control
import numpy as np
import pytest
from test_systune import (  # tests/control is on sys.path
    OMEGA,
    ab13dd_norm,
    closed_loop,
    loop_at_u,
    pid,
    two_mass,
)

from oos_drake.control.goals import Margins, WeightedGain, disk_alpha
from oos_drake.control.margins import disk_gain_phase
from oos_drake.control.systune import SystuneOptions, systune

P = np.linspace(0.0, 1.0, 9)
SPRINGS = 0.3 + 2.7 * (2 * P - 1) ** 2  # [N/m]: 3 at both ends, 0.3 in the middle
FAMILY = [two_mass(k) for k in SPRINGS]
GM_DB, PM_DEG = 6.0, 30.0
GOALS = [WeightedGain("d", "y"), Margins("u", GM_DB, PM_DEG, kind="hard")]
ITERATIONS = 60  # per phase: enough on these 5-state plants, keeps the file fast
ALPHA = disk_alpha(GM_DB, PM_DEG)


def margins(controller):
    """Per model: (balanced disk margin, gain margin [dB], phase margin [deg], stable)."""
    out = []
    for plant in FAMILY:
        L = loop_at_u(plant, controller)
        gm, pm, *_ = control.stability_margins(L)
        closed = control.feedback(plant[0, 0], controller)  # u = C e, e = -y
        stable = bool(np.all(np.real(closed.poles()) < 0))
        Lw = control.tf(L)(1j * OMEGA)  # the loop's polynomials evaluated on the grid
        disk = 1.0 / np.max(np.abs(1.0 / (1.0 + Lw) - 0.5))  # balanced disk margin
        out.append((disk, 20 * np.log10(gm), pm, stable))
    return np.array(out)


@pytest.fixture(scope="module")
def ends_only():
    """Tuned on the two end models only (the old path: the goals' values on those)."""
    return systune(
        [FAMILY[0], FAMILY[-1]], pid(), GOALS, options=SystuneOptions(max_iterations=ITERATIONS)
    )


@pytest.fixture(scope="module")
def working_set():
    """Started on the same two ends, every model checked, the violators added."""
    return systune(
        FAMILY, pid(), GOALS, options=SystuneOptions(working_set=2, max_iterations=ITERATIONS)
    )


def test_tuning_on_the_ends_misses_the_goal_between_them(ends_only):
    assert ends_only.status == "ok"  # met at the two models it was tuned on...
    found = margins(ends_only.controller)
    ends = found[[0, -1]]
    assert np.all(ends[:, 0] >= ALPHA * (1 - 1e-3))
    assert np.all(ends[:, 1] >= GM_DB - 1e-2) and np.all(ends[:, 2] >= PM_DEG - 1e-2)
    # ...but between them the disk margin is below the goal, the gain margin below 6 dB
    # and some loops are not even stable
    middle = found[1:-1]
    assert np.min(middle[:, 0]) < 0.5 * ALPHA
    assert np.min(middle[:, 1]) < GM_DB
    assert not np.all(middle[:, 3].astype(bool))


def test_working_set_holds_the_hard_goal_on_every_model(working_set):
    result = working_set
    assert result.status == "ok"
    assert result.models_checked == len(FAMILY)
    assert {0, len(FAMILY) - 1} <= set(result.working_set)
    assert len(result.working_set) > 2 and len(result.rounds) > 1  # violators were added
    assert result.rounds[0]["violators"] > 0 and result.rounds[-1]["violators"] == 0
    found = margins(result.controller)
    assert np.all(found[:, 3].astype(bool))  # every closed loop stable
    assert np.all(found[:, 0] >= ALPHA * (1 - 1e-3))  # the disk margin goal, closed form
    # the margins the disk guarantees, and python-control's loop-at-a-time margins
    gm_disk, pm_disk = disk_gain_phase(np.min(found[:, 0]))
    assert gm_disk >= GM_DB - 1e-2 and pm_disk >= PM_DEG - 1e-2
    assert np.all(found[:, 1] >= GM_DB - 1e-2) and np.all(found[:, 2] >= PM_DEG - 1e-2)
    # the reported value is over all nine models: alpha / (smallest disk margin)
    goal = result.goal("Margins(u)")
    assert goal.per_model.size == len(FAMILY)
    assert goal.value == pytest.approx(ALPHA / np.min(found[:, 0]), rel=2e-3)
    assert goal.details["disk_margin"] == pytest.approx(np.min(found[:, 0]), rel=2e-3)


def test_round_budget_ending_with_violators_is_infeasible():
    result = systune(
        FAMILY,
        pid(),
        GOALS,
        options=SystuneOptions(working_set=2, max_rounds=1, max_iterations=ITERATIONS),
    )
    assert result.status == "infeasible"
    assert sorted(result.working_set) == [0, len(FAMILY) - 1]
    assert result.rounds[0]["violators"] > 0 and result.rounds[0]["added"] == 0
    found = margins(result.controller)
    goal = result.goal("Margins(u)")
    assert not goal.met
    # the value reported is the worst over every model, not the tuned ends' (<= 1)
    assert np.max(goal.per_model[[0, -1]]) <= 1 + 1e-6
    unstable = ~found[:, 3].astype(bool)
    assert np.all(np.isinf(goal.per_model[unstable]))
    assert np.all(goal.per_model[~unstable] == pytest.approx(ALPHA / found[~unstable, 0], 2e-3))


def test_unreachable_hard_goals_are_infeasible_with_the_best_values():
    # the margins with ||T_dy||_inf <= 5: the soft optimum under the margins is about 23
    goals = [
        Margins("u", GM_DB, PM_DEG, kind="hard"),
        WeightedGain("d", "y", right_weight=0.2, kind="hard", name="gain"),
    ]
    result = systune(
        FAMILY, pid(), goals, options=SystuneOptions(working_set=3, max_iterations=ITERATIONS)
    )
    assert result.status == "infeasible"
    assert result.models_checked == len(FAMILY)
    found = margins(result.controller)
    assert np.all(found[:, 3].astype(bool))  # the best point reached is stable
    margin, gain = result.goal("Margins(u)"), result.goal("gain")
    assert result.hard == max(margin.value, gain.value) > 1
    assert not (margin.met and gain.met)
    # the best values reached, over every model: disk margins and slycot's ab13dd norms
    assert margin.value == pytest.approx(ALPHA / np.min(found[:, 0]), rel=2e-3)
    norms = [ab13dd_norm(closed_loop(plant, result.controller, ["d"], ["y"])) for plant in FAMILY]
    assert gain.value == pytest.approx(0.2 * max(norms), rel=1e-4)
