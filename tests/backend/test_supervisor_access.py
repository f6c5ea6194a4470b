"""Who flies when the pilot's link drops while another page waits for a hand-over, and the
start-up warning for a protective failsafe set only to warn.

The loop runs headless (SimulatedClock) in the test's thread through ``Supervisor.step``.
"""

from __future__ import annotations

import logging
from typing import Callable

import pytest
from support import Console

from ucat_console.backend.access import AccessDenied
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import AppConfig, ConsoleConfig

TOKEN = "pool-side-token"
PILOT, WAITING, RETURNING = 1, 2, 3


def make_config(**failsafes: FailsafeRule) -> AppConfig:
    return AppConfig(console=ConsoleConfig(supervise_period=0.05), access=AccessConfig(token=TOKEN),
                     failsafe=FailsafeConfig(**failsafes))


def test_a_waiting_request_never_takes_control_when_the_pilots_link_drops(
        make_console: Callable[..., Console]) -> None:
    console = make_console(make_config(pilot_gone=FailsafeRule("hold", 2.0, "disarm", 30.0)))
    sup = console.sup
    for c in (PILOT, WAITING):
        sup.client_connected(c, "10.0.0.2")
    assert sup.take_control(PILOT, TOKEN) is True
    sup.set_setpoints(PILOT, velocity=0.2)
    sup.arm(PILOT)
    sup.step(1.0)
    assert sup.take_control(WAITING, TOKEN) is False  # asks, then sits idle
    sup.step(1.0)
    n = len(console.events)
    sup.client_disconnected(PILOT, silent_for=2.0)  # the pilot's link dropped 2 s ago
    assert sup.access.pilot is None and sup.access.pending is None
    lapsed = console.event("access", "request_lapsed", n)
    assert lapsed is not None and lapsed.data["client"] == WAITING
    with pytest.raises(AccessDenied, match="read-only"):
        sup.disarm(WAITING)
    sup.step(0.1)
    fired = console.event("failsafe", "pilot_gone", n)
    assert fired is not None and fired.data["action"] == "hold"
    assert sup.armed and sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0
    # the operator comes back with the token on a new page: control at once, and DISARM
    sup.client_connected(RETURNING, "10.0.0.3")
    assert sup.take_control(RETURNING, TOKEN) is True
    sup.disarm(RETURNING)
    assert not sup.armed
    sup.step(0.1)
    assert sup.safety.active() == ()


def test_a_gone_pilot_with_a_waiting_request_still_escalates_to_disarm(
        make_console: Callable[..., Console]) -> None:
    sup = make_console(make_config(pilot_gone=FailsafeRule("hold", 2.0, "disarm", 10.0))).sup
    for c in (PILOT, WAITING):
        sup.client_connected(c)
    sup.take_control(PILOT, TOKEN)
    sup.set_setpoints(PILOT, velocity=0.2)
    sup.arm(PILOT)
    sup.take_control(WAITING, TOKEN)
    sup.step(0.5)
    sup.client_disconnected(PILOT)
    sup.step(2.2)
    assert sup.armed and sup.safety.active() == ("pilot_gone",)
    sup.step(10.0)
    assert not sup.armed and sup.access.pilot is None


def test_a_protective_failsafe_set_to_warn_is_logged_at_start(
        make_console: Callable[..., Console], caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    make_console(make_config(imu=FailsafeRule("warn", 1.0), pilot_gone=FailsafeRule("warn", 2.0),
                             tracking=FailsafeRule("warn", 10.0)))
    lines = [r.getMessage() for r in caplog.records if "set to warn" in r.getMessage()]
    assert len(lines) == 2
    assert "failsafe pilot_gone is set to warn" in lines[0] and "failsafe imu is set to warn" in lines[1]
    assert all("will not act on the robot" in line for line in lines)


def test_no_warning_when_every_protective_failsafe_acts(
        make_console: Callable[..., Console], caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    make_console(make_config())
    assert not [r for r in caplog.records if "set to warn" in r.getMessage()]
