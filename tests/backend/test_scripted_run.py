"""Scripted manoeuvres on the console: loading their files (errors naming the file, the
segment's line and the key; the console's limits), running one on the simulated robot
(markers and segment figures recorded, what it found put back), stopping at a disarm."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import pytest
from support import Console, console_config

from ucat_console import shipped
from ucat_console.backend.access import LOCAL, AccessDenied
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.manoeuvre_files import load_script, parse_script
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.control.allocation import BodySetpoints

SHORT = """\
description = "two short holds"
depth = 0.5
settle = 1.0
measure = 3.0

[[segment]]
label = "slow"
velocity = 0.1

[[segment]]
label = "faster"
velocity = 0.2
mode = "baseline"
"""


def test_the_shipped_manoeuvres_load_with_their_paper_setpoints() -> None:
    loop = LoopConfig()
    assert shipped.manoeuvre_names() == ["ab_modes", "depth_step", "e4_ladder", "fig8_circle"]
    e4 = load_script("e4_ladder", loop)
    assert [s.setpoints for s in e4.segments] == [BodySetpoints(v, 1.0, 0.0) for v in (0.1, 0.2, 0.3, 0.4)]
    assert [s.setpoints for s in load_script("fig8_circle", loop).segments] == [BodySetpoints(0.2, 3.0, 0.1)]
    assert [s.setpoints.depth for s in load_script("depth_step", loop).segments] == [0.5, 1.5]
    ab = load_script("ab_modes", loop)
    assert [s.mode for s in ab.segments] == ["mpc", "baseline"]
    assert ab.segments[0].setpoints == ab.segments[1].setpoints == BodySetpoints(0.2, 1.0, 0.0)


def test_a_bad_file_names_the_file_the_line_and_the_key(tmp_path: Path) -> None:
    loop = LoopConfig()
    bad = tmp_path / "bad.toml"
    cases = [
        # a bad key: the segment's header line and the key's line
        (SHORT.replace('label = "faster"', 'lable = "faster"'), r"segment 1 \(line 10: \[\[segment\]\]\), line 11: lable: not a key"),
        # a bad value
        (SHORT.replace("velocity = 0.2", 'velocity = "0.2"'), r"segment 1 \(line 10: \[\[segment\]\]\), line 12: velocity: expected a finite number"),
        # outside the console's envelope (loop.max_velocity 0.5 m/s: the loop's own check)
        (SHORT.replace("velocity = 0.2", "velocity = 0.8"), r"segment 1 \(line 10: \[\[segment\]\]\), line 12: velocity: 0.8 is out of range; allowed: \[-0.5, 0.5\] m/s"),
        # a top-level default outside it: the segment that takes it, and the default's line
        (SHORT.replace("depth = 0.5", "depth = 60.0"), r"segment 0 \(line 6: \[\[segment\]\]\), its default at line 2: depth: 60.0 is out of range"),
        (SHORT.replace('mode = "baseline"', 'mode = "identify"'), r"segment 1 \(line 10: \[\[segment\]\]\), line 13: mode: 'identify' does not follow the body loops"),
        # a syntax error: tomllib's line
        (SHORT.replace("velocity = 0.1", "velocity = = 0.1"), r"Invalid value \(at line 8, column 12\)"),
    ]
    for text, message in cases:
        bad.write_text(text)
        with pytest.raises(ValueError, match=rf"^{bad}: {message}"):
            load_script(str(bad), loop)
    with pytest.raises(ValueError, match="neither a shipped manoeuvre .*e4_ladder"):
        load_script("e5_ladder", loop)
    with pytest.raises(ValueError, match="no such file"):
        load_script(str(tmp_path / "none.toml"), loop)
    # the console's own envelope: a narrower one refuses what the default allows
    with pytest.raises(ValueError, match=r"velocity: 0.2 is out of range; allowed: \[-0.15, 0.15\]"):
        parse_script(SHORT, "short", LoopConfig(max_velocity=0.15))


def test_a_manoeuvre_runs_its_segments_records_markers_and_figures_and_puts_back_what_it_found(
        make_console: Callable[..., Console], tmp_path: Path) -> None:
    c = make_console(console_config(base="sim-tuned"))
    sup = c.sup
    script = parse_script(SHORT, "short", sup.cfg.loop)
    with pytest.raises(CommandRefused, match="arm the motors first"):
        sup.start_script(LOCAL, script)
    sup.set_setpoints(LOCAL, velocity=0.05, depth=0.3)
    sup.arm(LOCAL)
    with pytest.raises(AccessDenied):
        sup.start_script(7, script)  # a viewer
    run = sup.start_script(LOCAL, script)
    assert sup.mode == "mpc" and sup.setpoints == BodySetpoints(0.1, 0.5, 0.0)
    with pytest.raises(CommandRefused, match="a manoeuvre is running"):
        sup.start_script(LOCAL, script)
    sup.step(5.0)
    assert sup.mode == "baseline" and sup.setpoints.velocity == 0.2
    sup.step(4.0)
    assert run.finished and run.reason == "completed"
    assert sup.mode == "mpc" and sup.setpoints == BodySetpoints(0.05, 0.3, 0.0)  # put back
    paths = run.paths
    assert paths  # it recorded (nothing was recording) and stopped its recording
    markers = [e.message for e in c.events if e.code == "marker"]
    assert markers == ["short #1/2 slow: settle", "short #1/2 slow: measure", "short #2/2 faster: settle",
                       "short #2/2 faster: measure", "short: end (completed)"]
    segs = [e for e in c.events if e.code == "segment"]
    assert [e.data["label"] for e in segs] == ["slow", "faster"]
    for e in segs:
        f = e.data["figures"]
        assert f["energy_per_metre"]["value"] > 0.0 and f["speed"]["value"] > 0.0
        assert e.data["t1"] - e.data["t0"] == pytest.approx(3.0)
        lo, hi = f["energy_per_metre"]["lo"], f["energy_per_metre"]["hi"]
        assert lo is None or lo <= f["energy_per_metre"]["value"] <= hi
    assert segs[0].data["mode"] == "mpc" and segs[1].data["mode"] == "baseline"
    with SessionReader(paths[0], tmp_path) as r:
        recorded = [e for e in r.events() if e.code in ("marker", "segment")]
    assert [e.message for e in recorded if e.code == "marker"] == markers
    assert [e.data["label"] for e in recorded if e.code == "segment"] == ["slow", "faster"]


def test_a_disarm_stops_it_at_once_and_puts_back_the_setpoints(make_console: Callable[..., Console]) -> None:
    c = make_console(console_config(base="sim-tuned"))
    sup = c.sup
    sup.arm(LOCAL)
    before = sup.setpoints
    run = sup.start_script(LOCAL, parse_script(SHORT, "short", sup.cfg.loop))
    sup.step(2.0)
    sup.disarm(LOCAL)
    assert run.finished and run.reason == "the robot is disarmed"  # no chunk needed
    assert sup.setpoints == before and sup.mode == "mpc"
    assert not any(e.code == "segment" for e in c.events)  # the measure window never ended
    (end,) = [e for e in c.events if e.code == "manoeuvre"]
    assert end.data["reason"] == "the robot is disarmed" and end.data["measured"] == 0
    sup.step(5.0)  # nothing more happens
    assert sup.setpoints == before and [e.message for e in c.events if e.code == "marker"][-1] == \
        "short: end (the robot is disarmed)"


def test_it_stops_when_its_pilot_is_gone(make_console: Callable[..., Console]) -> None:
    c = make_console(console_config(base="sim-tuned"))
    sup = c.sup
    sup.client_connected(1)
    assert sup.take_control(1, sup.access.token)
    sup.arm(1)
    run = sup.start_script(1, parse_script(SHORT, "short", sup.cfg.loop))
    sup.step(1.5)
    assert not run.finished and sup.setpoints.velocity == 0.1
    sup.client_disconnected(1)
    sup.step(0.2)
    assert run.finished and run.reason in ("its pilot is no longer the pilot", "failsafe pilot_gone")
    assert sup.setpoints.velocity == 0.0  # what it found
