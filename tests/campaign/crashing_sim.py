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


class ProbeSimulator(FlexibleAttitudeSimulator):
    """Burns 0.2 s of processor time, sleeps 0.3 s and reports its OpenBLAS thread counts."""

    def run(self, case):
        from oos_drake.blas import _global_pair, _libraries

        start = time.process_time()
        while time.process_time() - start < 0.2:
            pass
        time.sleep(0.3)
        threads = [pair[1]() for pair in map(_global_pair, _libraries()) if pair is not None]
        from oos_drake.campaign.simulator import RunOutput

        return RunOutput(metrics={"blas_threads": float(max(threads, default=-1))})


def make_probe_simulator(**options) -> ProbeSimulator:
    return ProbeSimulator(**options)


class NaNSimulator(FlexibleAttitudeSimulator):
    """Returns a NaN APE on run 2 (like an integrator that produced NaN without raising)."""

    def run(self, case):
        output = super().run(case)
        if case.run_id == 2:
            from dataclasses import replace

            output = replace(output, metrics={**output.metrics, "ape": float("nan")})
        return output


def make_nan_simulator(**options) -> NaNSimulator:
    return NaNSimulator(**options)


class SlowSimulator(FlexibleAttitudeSimulator):
    """Sleeps 0.5 s per run: a campaign that stays in progress long enough to be disturbed."""

    def run(self, case):
        time.sleep(0.5)
        return super().run(case)


def make_slow_simulator(**options) -> SlowSimulator:
    return SlowSimulator(**options)
