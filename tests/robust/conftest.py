"""Fixtures shared by the robust tests."""

import numpy as np
import pytest
from published import rct_two_mass_loop

from oos_drake.robust import robstab
from oos_drake.robust.lfr_analysis import block_map
from oos_drake.robust.mu_intervals import Realization


@pytest.fixture(scope="session")
def two_mass():
    """The RCT two-mass closed loop ``T``, the realization and BLK of its ``M``, and
    ``robstab(T)`` (computed once for the conformance and cover tests)."""
    T = rct_two_mass_loop()
    real = Realization(np.asarray(T.A), np.asarray(T.Bw), np.asarray(T.Cz), np.asarray(T.Dzw))
    return T, real, block_map(T).blk, robstab(T)
