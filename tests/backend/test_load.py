"""The simulated robot behind its device emulators (real drivers) swimming while child
processes load the CPU: a busy machine fakes no drive or sensor fault and trips no
failsafe. Events are counted; how late the loop ran is the benchmark's (``ucat-console
bench load``), not this test's."""

from __future__ import annotations

import os

import pytest

from ucat_console.bench.load import swim_under_load

pytestmark = pytest.mark.slow


def test_a_busy_machine_fakes_no_fault_on_the_emulated_rig() -> None:
    hogs = 4 * (os.cpu_count() or 2)  # a load average of several times the cores
    r = swim_under_load(load_s=25.0, after_s=3.0, hogs=hogs)
    assert r["plans_made"] > 0  # the robot swam: plans were made and carried out
    assert r["faults"] == [], r["faults"]  # no drive fault, no sensor fault, no failsafe
    assert r["drive_faults"] == r["sensor_faults"] == r["failsafes"] == r["rearmed"] == 0
