"""The console's snapshot for the page (``Supervisor.state()``): values only, frozen, and it
follows arming, the mode, the pilot and a hand-over, and a failsafe.

The loop runs headless (SimulatedClock) in the test's thread through ``Supervisor.step``.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import pytest
from support import Console

from ucat_console.backend.access import LOCAL, AccessConfig
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.backend.supervisor import ConsoleState
from ucat_console.config import AppConfig, ConsoleConfig

TOKEN = "state-token"
PILOT, ASKER = 1, 2


def _values_only(value: Any, path: str = "state") -> None:
    """Every part of ``value`` is a value: a frozen dataclass, a tuple of values, a plain scalar."""
    assert not callable(value) or isinstance(value, type), f"{path} is callable"
    if dataclasses.is_dataclass(value):
        assert type(value).__dataclass_params__.frozen, f"{path} is not frozen"
        for f in dataclasses.fields(value):
            _values_only(getattr(value, f.name), f"{path}.{f.name}")
    elif isinstance(value, (tuple, list)):
        assert isinstance(value, tuple), f"{path} is a list"
        for i, v in enumerate(value):
            _values_only(v, f"{path}[{i}]")
    elif isinstance(value, dict):  # an effect's figures, its change's data (never changed once made)
        assert path.startswith("state.effects"), f"{path} is a dict"
    else:
        assert value is None or isinstance(value, (bool, int, float, str)), f"{path}: {type(value).__name__}"


@pytest.fixture
def console(make_console: Callable[..., Console]) -> Console:
    cfg = AppConfig(console=ConsoleConfig(supervise_period=0.05), access=AccessConfig(token=TOKEN),
                    failsafe=FailsafeConfig(pilot_gone=FailsafeRule("hold", 1.0)))
    return make_console(cfg)


def test_the_snapshot_holds_values_only_and_is_frozen(console: Console) -> None:
    sup = console.sup
    sup.client_connected(PILOT)
    assert sup.take_control(PILOT, TOKEN)
    sup.step(0.5)
    sup.set_setpoints(PILOT, velocity=0.1)  # a change whose effect is measured
    sup.step(0.5)
    st = sup.state()
    assert isinstance(st, ConsoleState)
    assert st.effects and st.effects[0].code == "setpoints"
    _values_only(st)
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.armed = True  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.access.pilot = 5  # type: ignore[misc]
    assert st.robot == sup.cfg.robot and st.limits.max_depth == sup.cfg.loop.max_depth
    assert [s.name for s in st.safety.sensors] == ["imu", "dvl", "depth"]


def test_the_snapshot_follows_arming_the_mode_and_setpoints(console: Console) -> None:
    sup = console.sup
    sup.client_connected(PILOT)
    assert sup.take_control(PILOT, TOKEN)
    before = sup.state()
    assert not before.armed and before.access.is_pilot(PILOT) and not before.access.is_pilot(ASKER)
    sup.arm(PILOT)
    sup.set_mode(PILOT, "baseline")
    sup.set_setpoints(PILOT, velocity=0.1)
    sup.step(0.2)
    after = sup.state()
    assert after.armed and after.mode == "baseline" and after.setpoints.velocity == pytest.approx(0.1)
    assert not before.armed and before.mode != "baseline"  # the earlier snapshot kept its values
    sup.disarm(PILOT)
    assert not sup.state().armed and after.armed


def test_the_snapshot_follows_a_hand_over(console: Console) -> None:
    sup = console.sup
    for c in (PILOT, ASKER):
        sup.client_connected(c)
    sup.set_name(PILOT, "Ada")
    assert sup.take_control(PILOT, TOKEN)
    st = sup.state()
    assert st.access.pilot == PILOT and st.access.pilot_name == "Ada" and st.access.pending is None
    assert st.access.clients == 2 and st.access.viewers == 1
    assert sup.take_control(ASKER, TOKEN) is False
    asked = sup.state()
    assert asked.access.pending == ASKER and asked.access.pilot == PILOT
    sup.hand_over(PILOT, ASKER)
    handed = sup.state()
    assert handed.access.pilot == ASKER and handed.access.pending is None and handed.access.pilot_name == ""
    assert handed.access.is_pilot(ASKER) and not handed.access.is_pilot(PILOT)


def test_the_snapshot_follows_a_failsafe_and_its_cause(console: Console) -> None:
    sup = console.sup
    sup.client_connected(PILOT)
    assert sup.take_control(PILOT, TOKEN)
    sup.step(0.3)
    assert "pilot_gone" not in sup.state().failsafes
    sup.client_disconnected(PILOT)
    sup.step(2.0)
    st = sup.state()
    assert "pilot_gone" in st.failsafes and "pilot_gone" in st.safety.active
    state = st.safety.active_states()["pilot_gone"]
    assert state.active and state.cause and state.action == "hold"
    assert st.safety.rule("pilot_gone").timeout == 1.0
    with pytest.raises(ValueError, match="failsafe"):
        st.safety.rule("no_such_failsafe")


def test_the_pages_commands_go_through_the_supervisors_checks(console: Console) -> None:
    from ucat_console.backend.access import AccessDenied
    from ucat_console.backend.supervisor import CommandRefused

    sup = console.sup
    for c in (PILOT, ASKER):
        sup.client_connected(c)
    assert sup.take_control(PILOT, TOKEN)
    with pytest.raises(AccessDenied, match="read-only"):
        sup.note_gamepad(ASKER, True)
    assert not [e for e in sup.journal() if e.key == "gamepad"]
    sup.note_gamepad(PILOT, True)
    assert sup.journal()[-1].key == "gamepad" and sup.journal()[-1].new == "driving"
    with pytest.raises(AccessDenied):
        sup.require_pilot(ASKER, "plot history")
    assert sup.may_replay(ASKER) is False and sup.may_replay(PILOT) is True  # disarmed: anyone
    sup.arm(LOCAL)
    with pytest.raises(CommandRefused, match="only the pilot"):
        sup.may_replay(ASKER)
    assert sup.may_replay(PILOT) is True
