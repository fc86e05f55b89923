"""A simulator whose process dies (like a native segfault) for some cases: for executor tests."""

from __future__ import annotations

import os
import time

from oos_drake.campaign.attitude_sim import FlexibleAttitudeSimulator


class CrashingSimulator(FlexibleAttitudeSimulator):
    """Kills its own process (``os._exit``) on run 5."""

    def run(self, case):
        if case.run_id == 5:
            os._exit(3)
        return super().run(case)


def make_simulator(**options) -> CrashingSimulator:
    return CrashingSimulator(**options)


class HangingSimulator(FlexibleAttitudeSimulator):
    """Never finishes run 4 (like a stalled integrator)."""

    def run(self, case):
        if case.run_id == 4:
            time.sleep(3600)
        return super().run(case)


def make_hanging_simulator(**options) -> HangingSimulator:
    return HangingSimulator(**options)
