"""A slow fin is seen: the loop's ``fin_slow`` event lights the bar's Vehicle light (its Fins
part) with what was reported, until ``fin_slow_cleared``; the event is in the recording."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from support import Console

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event
from ucat_console.ui.status_bar import lights, vehicle_parts

SLOW = "fin 2's cycles take 3.01 times their plans' duration: a weak or lagging drive"


def loop_event(sup: Any, code: str, message: str, level: str, ratio: float) -> None:
    """An event of the closed loop, as its actuators publish it."""
    sup._loop_stream.publish(ch.EVENTS, Event(t=sup.loop.time, source="loop", code=code, message=message,
                                              level=level, data={"fin": 2, "ratio": ratio}))


def test_a_slow_fin_lights_the_vehicle_light_with_its_reason_and_is_recorded(
        tmp_path: Path, make_console: Callable[..., Console]) -> None:
    sup = make_console().sup
    sup.start_recording(LOCAL, "slow fin")
    sup.step(0.5)
    fins = next(x for x in vehicle_parts(sup.state()) if x.name == "Fins")
    assert fins.state == "ok" and "every fin keeps its plans' pace" in fins.why
    loop_event(sup, "fin_slow", SLOW, "warning", 3.01)
    sup.step(0.5)
    fins = next(x for x in vehicle_parts(sup.state()) if x.name == "Fins")
    assert fins.state == "warn" and fins.why == SLOW
    vehicle = next(x for x in lights(sup.state()) if x.name == "Vehicle")
    assert vehicle.state == "warn" and vehicle.why.startswith(f"Fins: {SLOW}")
    loop_event(sup, "fin_slow_cleared", "fin 2's cycles keep their plans' pace again (1.02)", "info", 1.02)
    sup.step(0.5)
    assert next(x for x in vehicle_parts(sup.state()) if x.name == "Fins").state == "ok"
    paths = sup.stop_recording(LOCAL)
    with SessionReader(paths[0], tmp_path) as r:
        codes = [(e.source, e.code, e.data.get("fin")) for e in r.events()]
    assert ("loop", "fin_slow", 2) in codes and ("loop", "fin_slow_cleared", 2) in codes


def test_fins_stronger_than_their_model_light_the_fins_part_until_they_are_not(
        make_console: Callable[..., Console]) -> None:
    sup = make_console().sup
    scaled = ("the fins make 4.6 times the fin model's force: the body layer asks them for that much less; "
              "identify the fins (ucat-console identify --fit scale)")
    sup._loop_stream.publish(ch.EVENTS, Event(t=sup.loop.time, source="loop", code="fin_force_scale",
                                              message=scaled, level="warning", data={"scale": 4.6}))
    sup.step(0.5)
    fins = next(x for x in vehicle_parts(sup.state()) if x.name == "Fins")
    assert fins.state == "warn" and fins.why == scaled
    sup._loop_stream.publish(ch.EVENTS, Event(t=sup.loop.time, source="loop", code="fin_force_scale_cleared",
                                              message="the fins make 1.20 times the fin model's force",
                                              level="info", data={"scale": 1.2}))
    sup.step(0.5)
    assert next(x for x in vehicle_parts(sup.state()) if x.name == "Fins").state == "ok"
