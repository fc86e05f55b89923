"""systune's hard surplus and verification: a hard goal holds BETWEEN the checked models.

A family of two-mass plants (``test_systune.two_mass``, spring ``k`` [N/m]) along a parameter
``p`` in [0, 1], softest at ``p = 0.525``, between two checked models:
``k(p) = 0.3 + 2.7 (2 p - 1.05)^2``. A PID is tuned with hard margins (6 dB, 30 deg) on 17
evenly spaced models (working set from 3 of them, every model checked) and verified on the
16 midpoints; the test recomputes the disk margin on a grid 4x denser than the checked one
(65 models) independently of systune: the balanced disk margin's closed form
``1 / max |1 / (1 + L) - 1/2|`` with python-control's own loop ``L`` on 20000 frequencies,
and the closed-loop poles.

- tuned to the bound (``hard_surplus=0``): met on the 17 checked models but not between them;
  the midpoint verification sees it and the status is ``"infeasible"``;
- with a 2 % surplus: met on all 65, the status ``"ok"``.
"""

import control
import numpy as np
import pytest
from test_systune import OMEGA, loop_at_u, pid, two_mass  # tests/control is on sys.path

from oos_drake.blas import single_threaded_blas
from oos_drake.control.goals import Margins, WeightedGain, disk_alpha
from oos_drake.control.systune import SystuneOptions, systune

CHECKED = np.linspace(0.0, 1.0, 17)
DENSE = np.linspace(0.0, 1.0, 4 * (CHECKED.size - 1) + 1)  # 4x denser, CHECKED = DENSE[::4]
MIDPOINTS = (CHECKED[:-1] + CHECKED[1:]) / 2
GM_DB, PM_DEG = 6.0, 30.0
ALPHA = disk_alpha(GM_DB, PM_DEG)
GOALS = [WeightedGain("d", "y"), Margins("u", GM_DB, PM_DEG, kind="hard")]
SURPLUS = 0.02


def spring(p):
    return 0.3 + 2.7 * (2 * np.asarray(p) - 1.05) ** 2  # [N/m]


def tune(surplus):
    """Working set from 3 evenly spaced models; one BLAS thread (the optimizer's path on this
    family depends on round-off: with another BLAS thread count it may end elsewhere)."""
    options = SystuneOptions(working_set=3, max_iterations=60, hard_surplus=surplus)
    plants = [two_mass(k) for k in spring(CHECKED)]
    verify = [two_mass(k) for k in spring(MIDPOINTS)]
    with single_threaded_blas():
        return systune(plants, pid(), GOALS, options=options, verify=verify)


def disk_margins(controller, p):
    """Per ``p``: (balanced disk margin from its closed form, closed loop stable)."""
    out = []
    for k in spring(p):
        plant = two_mass(k)
        Lw = control.tf(loop_at_u(plant, controller))(1j * OMEGA)
        closed = control.feedback(plant[0, 0], controller)  # u = C e, e = -y
        stable = bool(np.all(np.real(closed.poles()) < 0))
        out.append((1.0 / np.max(np.abs(1.0 / (1.0 + Lw) - 0.5)), stable))
    return np.array(out)


@pytest.fixture(scope="module")
def to_the_bound():
    return tune(0.0)


@pytest.fixture(scope="module")
def with_surplus():
    return tune(SURPLUS)


def test_tuned_to_the_bound_the_goal_dips_between_the_checked_models(to_the_bound):
    result = to_the_bound
    found = disk_margins(result.controller, DENSE)
    assert np.all(found[:, 1].astype(bool))
    checked, between = found[::4, 0], np.delete(found[:, 0], np.s_[::4])
    assert np.min(checked) >= ALPHA * (1 - 1e-3)  # met on the 17 checked models...
    assert result.goal("Margins(u)").value <= 1 + 1e-6
    assert np.min(between) < ALPHA * (1 - 1e-4)  # ...but not between them
    # the midpoint verification sees it: the status is not "ok"
    assert result.status == "infeasible"
    assert result.models_verified == CHECKED.size + MIDPOINTS.size
    verified = result.verified[1]
    assert verified.name == "Margins(u)" and not verified.met
    midpoints = found[2::4, 0]
    np.testing.assert_allclose(verified.per_model, ALPHA / midpoints, rtol=2e-3)


def test_with_the_surplus_the_goal_holds_on_a_grid_4x_denser(with_surplus):
    result = with_surplus
    assert result.status == "ok"
    found = disk_margins(result.controller, DENSE)
    assert np.all(found[:, 1].astype(bool))  # every closed loop stable
    # tuned with the surplus on the checked models...
    goal = result.goal("Margins(u)")
    assert goal.value <= 1 / (1 + SURPLUS) + 1e-6
    np.testing.assert_allclose(goal.per_model, ALPHA / found[::4, 0], rtol=2e-3)
    # ...the disk margin goal holds on all 65, recomputed here
    assert np.all(found[:, 0] >= ALPHA)
    assert result.verified_value("Margins(u)") <= 1
    np.testing.assert_allclose(result.verified[1].per_model, ALPHA / found[2::4, 0], rtol=2e-3)
