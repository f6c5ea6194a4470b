"""The auxiliary sensors' registry, followed as docs/extending.md ("A new sensor") says: a
sensor registered from outside the package (a hull thermometer a fake source feeds) is in
the telemetry stream, in a recorded session read back, in the page's status bar, and its
failsafe trips (too hot for its timeout, then silent) and clears, with the rule the
configuration sets; unregistered, it is gone from every one."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import pytest
from support import Console, wait_for

from ucat_console.backend import sensors
from ucat_console.backend.access import LOCAL
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule, SensorRule
from ucat_console.backend.safety import channels as safety_channels
from ucat_console.backend.safety import failsafe_names
from ucat_console.backend.sensors import OpenContext, Sensor, SensorFailsafe, SensorStatus, Source
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.config import AppConfig, load_config
from ucat_console.robot.fields import Doc
from ucat_console.robot.readings import Time
from ucat_console.telemetry import channels as ch
from ucat_console.ui.status_bar import vehicle_parts

NAME = "hull_temperature"
CHANNEL = f"sensors/{NAME}"
#: the temperature the failsafe trips at (C) and how long the sensor may be silent (s)
HOT, STALE = 60.0, 1.0


@dataclass(frozen=True)
class HullTemperature:
    """The air temperature inside the hull."""

    t: Time
    celsius: Annotated[float, Doc("air temperature inside the hull", "degC")]


class FakeThermometer:
    """What the test sets the hull's temperature to (None: the thermometer is silent)."""

    def __init__(self) -> None:
        self.celsius: float | None = 21.5
        self.opened = threading.Event()
        self.closed = threading.Event()

    def open(self, ctx: OpenContext) -> Source:
        assert ctx.simulated and ctx.robot is not None  # what a real driver would be built from
        self.opened.set()
        return Source(self.read, 0.02, "fake thermometer", self.closed.set)

    def read(self, t: float) -> HullTemperature | None:
        c = self.celsius
        return None if c is None else HullTemperature(t, c)


def hull_light(s: SensorStatus) -> tuple[str, str]:
    if s.reading is None or s.age > STALE / 2:
        return "warn", f"no temperature for {s.age:.1f} s"
    if s.reading.celsius >= HOT - 10.0:
        return "warn", f"{s.reading.celsius:.1f} C, near {HOT:g} C"
    return "ok", f"{s.reading.celsius:.1f} C ({s.where})"


@pytest.fixture
def thermometer():
    """The sensor registered from the test module (its one register call), and taken out."""
    fake = FakeThermometer()
    sensors.register(Sensor(
        NAME, "the hull's air temperature (a fake thermometer)", HullTemperature, fake.open, "Hull temp",
        hull_light,
        SensorFailsafe(NAME, FailsafeRule("hold", 0.5),
                       lambda r: f"hull at {r.celsius:.1f} C, over {HOT:g} C" if r.celsius > HOT else None,
                       stale_after=STALE),
        absent="no hull thermometer",
    ))
    yield fake
    sensors.unregister(NAME)


def _light(sup) -> tuple[str, str]:
    x = next(x for x in vehicle_parts(sup.state()) if x.name == "Hull temp")
    return x.state, x.why


def test_a_registered_sensor_is_streamed_recorded_shown_and_watched(thermometer, tmp_path: Path) -> None:
    cfg = load_config("sim-tuned")
    c = Console(cfg.replace(console=cfg.console.replace(record_on_arm=False)), tmp_path)
    sup = c.sup
    got: list[HullTemperature] = []
    sup.stream.subscribe(lambda _c, m: got.append(m), [CHANNEL])
    try:
        assert thermometer.opened.is_set() and CHANNEL in safety_channels() and NAME in failsafe_names()
        sid = sup.start_recording(LOCAL)
        sup.arm(LOCAL)
        sup.set_setpoints(LOCAL, velocity=0.2)
        wait_for(lambda: got, what="a reading on the sensor's channel")
        sup.step(0.5)
        wait_for(lambda: sup.sensors.latest(NAME).t >= sup.loop.time, what="a reading at the loop's time")
        assert got[-1].celsius == 21.5 and not sup.safety.is_active(NAME)
        assert _light(sup) == ("ok", "21.5 C (fake thermometer)")

        thermometer.celsius = 72.0  # too hot: held for the rule's 0.5 s, then hold
        t_hot = wait_for(lambda: (r := sup.sensors.latest(NAME)).celsius == 72.0 and r.t, what="the hot reading")
        assert _light(sup)[0] == "warn"
        sup.step(0.3)
        assert not sup.safety.is_active(NAME)  # not yet for its timeout
        sup.step(0.5)
        ev = c.event("failsafe", NAME)
        assert ev is not None and ev.data["action"] == "hold" and "72.0 C, over 60 C" in ev.data["cause"]
        assert ev.t >= t_hot + 0.5
        assert sup.setpoints.velocity == 0.0 and sup.armed  # held, as the rule says
        state, why = _light(sup)
        assert state == "bad" and f"failsafe {NAME}" in why

        thermometer.celsius = 30.0
        wait_for(lambda: sup.sensors.latest(NAME).celsius == 30.0, what="a cool reading")
        sup.step(0.1)
        assert not sup.safety.is_active(NAME) and c.event("failsafe", "cleared") is not None

        thermometer.celsius = None  # silent: no reading for STALE s, then the rule's 0.5 s
        n = len(c.events)
        sup.step(STALE + 0.5 + 0.3)
        ev = c.event("failsafe", NAME, after=n)
        assert ev is not None and "Hull temp: no reading for" in ev.data["cause"]
        paths = sup.stop_recording(LOCAL)
    finally:
        c.stop()
    assert thermometer.closed.is_set()
    with SessionReader(paths[0], tmp_path) as r:
        assert sid in str(paths[0])
        recorded = [m for _c, m in r.messages([CHANNEL])]
        assert CHANNEL in r.channels
    assert {m.celsius for m in recorded} == {21.5, 72.0, 30.0}
    assert all(isinstance(m, HullTemperature) for m in recorded)
    entry = sensors.sensor(NAME)
    sensors.unregister(NAME)  # a console without the sensor opens the file, that channel unread
    try:
        with SessionReader(paths[0], tmp_path) as r:
            assert CHANNEL not in r.channels and next(r.messages([ch.BODY_STATE]), None) is not None
    finally:
        sensors.register(entry)


def test_the_configuration_sets_a_registered_sensors_rule(thermometer) -> None:
    cfg = AppConfig.from_dict({"failsafe": {"sensors": [{"name": NAME, "action": "warn", "timeout": 3.0}]}})
    assert cfg.failsafe.rule(NAME) == FailsafeRule("warn", 3.0)
    assert NAME in cfg.failsafe.warn_only()  # a protective rule set only to warn is listed
    assert FailsafeConfig().rule(NAME) == FailsafeRule("hold", 0.5)  # the registration's default
    with pytest.raises(ValueError, match=f"failsafe.sensors\\[0\\].name: 'hull' is not allowed; allowed: one of 'leak', '{NAME}'"):
        AppConfig.from_dict({"failsafe": {"sensors": [{"name": "hull"}]}})
    with pytest.raises(ValueError, match=f"sensors: '{NAME}' is set more than once"):
        FailsafeConfig(sensors=(SensorRule(name=NAME), SensorRule(name=NAME)))
    with pytest.raises(ValueError, match=f"sensor: '{NAME}' is already registered"):
        sensors.register(sensors.sensor(NAME))


def test_an_unregistered_sensor_is_gone_and_bad_entries_are_refused(thermometer) -> None:
    entry = sensors.sensor(NAME)
    sensors.unregister(NAME)
    try:
        assert NAME not in sensors.sensor_names() and NAME not in failsafe_names()
        with pytest.raises(ValueError, match=f"unknown telemetry channel '{CHANNEL}'"):
            ch.message_type(CHANNEL)
        with pytest.raises(ValueError, match=f"sensor: '{NAME}' is not one of leak"):
            sensors.sensor(NAME)
        with pytest.raises(ValueError, match="failsafe 'leak' is already one of the failsafes"):
            sensors.register(Sensor(NAME, "", HullTemperature, entry.open, "x", hull_light,
                                    SensorFailsafe("leak", FailsafeRule(), stale_after=1.0)))
        with pytest.raises(ValueError, match="failsafe 'depth' is already one of the failsafes"):
            sensors.register(Sensor(NAME, "", HullTemperature, entry.open, "x", hull_light,
                                    SensorFailsafe("depth", FailsafeRule(), stale_after=1.0)))
        with pytest.raises(ValueError, match="its reading must be a dataclass with a time field t"):
            sensors.register(Sensor(NAME, "", float, entry.open, "x", hull_light))
        with pytest.raises(ValueError, match="channel 'sensors/imu' is already one of the telemetry channels"):
            sensors.register(Sensor("imu", "", HullTemperature, entry.open, "x", hull_light))
        assert NAME not in sensors.sensor_names() and "imu" not in sensors.sensor_names()
    finally:
        sensors.register(entry)  # for the fixture to take out
