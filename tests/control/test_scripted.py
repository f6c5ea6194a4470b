"""Scripted manoeuvres' core: where a script is at a time, kinds expanded into segments, the
plan listing, refused tables naming the segment and the key."""

from __future__ import annotations

import pytest

from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.scripted import Script, ScriptError, Segment, at, plan, script_of


def two() -> Script:
    return Script("two", (Segment("a", BodySetpoints(0.1, 1.0, 0.0), 2.0, 3.0),
                          Segment("b", BodySetpoints(0.2, 1.5, 0.1), 0.0, 4.0, mode="baseline")))


def test_at_walks_settle_then_measure_of_each_segment_then_done() -> None:
    s = two()
    assert s.duration == 9.0 and s.starts == (0.0, 5.0)
    cases = [(0.0, 0, "settle", 0.0, 2.0), (1.999, 0, "settle", 0.0, 2.0), (2.0, 0, "measure", 2.0, 5.0),
             (4.999, 0, "measure", 2.0, 5.0), (5.0, 1, "measure", 5.0, 9.0),  # no settle: measured at once
             (9.0, 2, "done", 9.0, 9.0), (100.0, 2, "done", 9.0, 9.0)]
    for t, index, phase, t0, t1 in cases:
        step = at(s, t)
        assert (step.index, step.phase, step.t0, step.t1) == (index, phase, t0, t1), t
    assert at(s, 6.0).setpoints == BodySetpoints(0.2, 1.5, 0.1) and at(s, 6.0).mode == "baseline"
    assert at(s, 1.0).mode == ""  # the mode in force at the start
    assert at(s, 50.0).setpoints == BodySetpoints(0.2, 1.5, 0.1)
    with pytest.raises(ValueError, match="t: -1"):
        at(s, -1.0)


def test_a_ladder_expands_to_one_segment_per_rung_and_top_level_values_are_defaults() -> None:
    s = script_of("e4", {"depth": 1.0, "settle": 5.0, "measure": 10.0,
                         "segment": [{"kind": "ladder", "speeds": [0.1, 0.2, 0.3]},
                                     {"kind": "depth_step", "from_depth": 0.5, "to_depth": 1.5, "measure": 7.0},
                                     {"kind": "turn", "velocity": 0.2, "yaw_rate": 0.1, "mode": "mpc"}]})
    assert [sg.setpoints.velocity for sg in s.segments] == [0.1, 0.2, 0.3, 0.0, 0.0, 0.2]
    assert [sg.setpoints.depth for sg in s.segments] == [1.0, 1.0, 1.0, 0.5, 1.5, 1.0]
    assert [sg.measure_s for sg in s.segments] == [10.0, 10.0, 10.0, 7.0, 7.0, 10.0]
    assert [sg.source for sg in s.segments] == [0, 0, 0, 1, 1, 2]
    assert s.segments[-1].setpoints.yaw_rate == 0.1 and s.modes == ("mpc",)
    assert s.duration == 3 * 15.0 + 2 * 12.0 + 15.0
    text = plan(s)
    assert text.splitlines()[0] == "e4: 6 segments, 84 s (1 min 24 s)"
    assert "6. turn: velocity 0.2 m/s, depth 1 m, yaw rate 0.1 rad/s, mode mpc; settle 5 s, measure 10 s" in text


@pytest.mark.parametrize("table, segment, key", [
    ({"settle": 1, "measure": 1, "segment": [{"depth": 1}, {"depth": 1, "speed": 2}]}, 1, "speed"),
    ({"settle": 1, "measure": 1, "segment": [{"depth": 1, "velocity": "fast"}]}, 0, "velocity"),
    ({"settle": 1, "segment": [{"depth": 1}]}, 0, "measure"),
    ({"settle": 1, "measure": 0, "segment": [{"depth": 1}]}, 0, "measure"),
    ({"settle": 1, "measure": 1, "segment": [{"depth": -1}]}, 0, "depth"),
    ({"settle": 1, "measure": 1, "segment": [{"kind": "ladder", "depth": 1, "speeds": [0.1, 9.0]}]}, 0, "speeds"),
    ({"settle": 1, "measure": 1, "segment": [{"kind": "turn", "depth": 1}]}, 0, "yaw_rate"),
    ({"settle": 1, "measure": 1, "segment": [{"kind": "spiral", "depth": 1}]}, 0, "kind"),
    ({"settle": 1, "measure": 1, "speed": 1, "segment": [{"depth": 1}]}, None, "speed"),
    ({"settle": 1, "measure": 1}, None, "segment"),
])
def test_a_bad_table_names_its_segment_and_key(table: dict, segment: int | None, key: str) -> None:
    with pytest.raises(ScriptError) as e:
        script_of("bad", table)
    assert (e.value.segment, e.value.key) == (segment, key)
    assert str(e.value).startswith(f"{key}:")


def test_the_callers_checks_refuse_what_the_console_would() -> None:
    def envelope(sp: BodySetpoints) -> BodySetpoints:
        return sp.within(0.3, 2.0, 0.2)

    def modes(name: str) -> None:
        if name != "mpc":
            raise ValueError(f"mode: {name!r} is not one of mpc")

    ok = {"settle": 1, "measure": 1, "segment": [{"depth": 1, "velocity": 0.3, "mode": "mpc"}]}
    assert script_of("ok", ok, envelope, modes).segments[0].setpoints.velocity == 0.3
    for seg, key in (({"depth": 2.5}, "depth"), ({"depth": 1, "velocity": 0.31}, "velocity"),
                     ({"depth": 1, "mode": "baseline"}, "mode")):
        with pytest.raises(ScriptError) as e:
            script_of("bad", {"settle": 1, "measure": 1, "segment": [seg]}, envelope, modes)
        assert e.value.key == key
