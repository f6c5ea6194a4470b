"""The supervisor's parts on their own: each takes the few commands it uses (a host), so a
test gives it fakes and watches what it asks for, with no supervisor, loop or robot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from ucat_console.backend.access import LOCAL, AccessDenied
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.backend.supervisor.manoeuvre import ManoeuvreHost, ManoeuvreRun
from ucat_console.backend.supervisor.rig_control import RigControl, RigHost
from ucat_console.telemetry.events import Event


class FakeConsole:
    """What the parts see of a console: a pilot, a mode, a recording, a loop time, a gate."""

    def __init__(self) -> None:
        self.pilot = 1
        self.armed = True
        self.mode = "mpc"
        self.session = ""
        self.t = 10.0
        self.calls: list[tuple[Any, ...]] = []
        self.has_drives = True
        self.reset_ok = True

    def require_pilot(self, who: Any, what: str) -> None:
        if who != LOCAL and who != self.pilot:
            raise AccessDenied(f"{what}: client {who} is not the pilot")

    def set_mode(self, who: Any, mode: str) -> None:
        self.calls.append(("mode", who, mode))
        self.mode = mode

    def start_recording(self, who: Any, notes: str) -> str:
        self.calls.append(("record", who, notes))
        self.session = "s1"
        return self.session

    def stop_recording(self, who: Any) -> list[Path]:
        self.calls.append(("stop", who))
        self.session = ""
        return [Path("s1.mcap")]

    def add_marker(self, who: Any, note: str) -> None:
        self.calls.append(("marker", who, note))

    def manoeuvre_host(self) -> ManoeuvreHost:
        return ManoeuvreHost(
            require_pilot=self.require_pilot, armed=lambda: self.armed, mode=lambda: self.mode,
            set_mode=self.set_mode, recording=lambda: self.session, start_recording=self.start_recording,
            stop_recording=self.stop_recording, add_marker=self.add_marker, time=lambda: self.t, duration=8.0,
        )

    # the arming gate's part the device commands use
    def reset_drive_faults(self) -> bool:
        self.calls.append(("reset",))
        return self.reset_ok

    def zero_depth(self) -> float:
        return 101_325.0

    def publish_event(self, source: str, code: str, message: str, level: str = "info",
                      data: dict | None = None) -> Event:
        self.calls.append(("event", code, level))
        return Event(self.t, source, code, message, level, data or {})

    def rig_host(self, rig: Any = None) -> RigHost:
        return RigHost(robot="hardware" if rig is None else "sim-devices", rig=rig, gate=self,  # type: ignore[arg-type]
                       require_pilot=self.require_pilot, in_loop=lambda fn: fn(),
                       publish_event=self.publish_event, notify=lambda: self.calls.append(("notify",)))


def test_a_manoeuvre_records_switches_mode_and_puts_everything_back_through_its_host() -> None:
    c = FakeConsole()
    run = ManoeuvreRun(c.manoeuvre_host(), 1)
    assert run.start() == "s1"
    assert c.calls == [("record", 1, "identification manoeuvre"), ("mode", 1, "identify"),
                       ("marker", 1, "identification manoeuvre starts")]
    c.t += 5.0
    assert run.progress == pytest.approx(5.0 / (8.0 + ManoeuvreRun.TAIL_S)) and not run.poll()
    c.t += 5.0
    assert run.poll() and run.finished and run.paths == [Path("s1.mcap")]
    assert c.calls[-2:] == [("mode", LOCAL, "mpc"), ("stop", LOCAL)]  # the console's own act
    assert run.poll()  # finished once


def test_a_manoeuvre_keeps_a_recording_it_did_not_start_and_ends_when_disarmed() -> None:
    c = FakeConsole()
    c.session = "running"
    run = ManoeuvreRun(c.manoeuvre_host(), 1)
    assert run.start() == "running"
    c.armed = False
    assert run.poll()
    assert ("record", 1, "identification manoeuvre") not in c.calls
    assert c.calls[-1] == ("stop", LOCAL)  # its session, stopped when it ends


def test_a_manoeuvre_is_refused_to_a_viewer_and_while_disarmed() -> None:
    c = FakeConsole()
    with pytest.raises(AccessDenied):
        ManoeuvreRun(c.manoeuvre_host(), 2).start()
    c.armed = False
    with pytest.raises(CommandRefused, match="arm the motors first"):
        ManoeuvreRun(c.manoeuvre_host(), 1).start()
    assert c.calls == []


def test_device_commands_act_through_their_host() -> None:
    c = FakeConsole()
    rc = RigControl(c.rig_host())
    with pytest.raises(CommandRefused, match="robot = 'sim-devices'.*runs robot 'hardware'"):
        rc.inject_fault(1, "imu", "silence")
    c.armed = False
    rc.reset_drive_faults(1)
    assert c.calls == [("reset",), ("event", "drive_fault_reset", "info"), ("notify",)]
    c.reset_ok = False
    with pytest.raises(CommandRefused, match="not every drive left its fault"):
        rc.reset_drive_faults(1)
    assert ("event", "drive_fault_reset", "error") in c.calls
    assert rc.zero_depth(1) == 101_325.0
    c.armed = True
    with pytest.raises(CommandRefused, match="disarm first"):
        rc.zero_depth(1)
    with pytest.raises(AccessDenied):
        rc.reset_drive_faults(2)
