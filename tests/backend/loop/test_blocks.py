"""The loop's tunable blocks: one live registry, read by the loop's one command for them, the
supervisor's tuning (check, journal, undo) and the page's tuning folders. A block registered
here, from outside the package, is tuned like a built-in one."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import pytest
from support import TOKEN, Console, console_config

from ucat_console.backend.loop.blocks import Block, block, block_names, register, unregister
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import CommandRefused, SetBlock
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.params import MpcConfig, PidGains
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.typedconf import Config, param

PILOT = 3


@dataclass(frozen=True)
class Trim(Config):
    """A test's own block: a gain (tuned live) and an offset (not tuned)."""

    gain: float = param(1.0, lo=0.0, hi=10.0, doc="the test's gain")
    offset: float = param(0.0, lo=-1.0, hi=1.0, doc="not tuned live")


@dataclass
class Applied:
    """What the block's apply was given: (loop time, config), in order."""

    got: list[tuple[float, Trim]]

    @property
    def configs(self) -> list[Trim]:
        return [cfg for _, cfg in self.got]


@pytest.fixture
def trim() -> Iterator[Applied]:
    """The block "trim", registered for the test; its apply records what it gets."""
    applied = Applied([])
    register(Block("trim", Trim, "Trim of the test", ("gain",), initial=lambda c: Trim(),
                   apply=lambda loop, cfg: applied.got.append((loop.time, cfg)), label="trim "))
    yield applied
    unregister("trim")


def test_the_built_in_blocks_are_registered_in_the_page_order() -> None:
    assert block_names() == ("mpc", "pid.velocity", "pid.depth", "pid.yaw_rate", "baseline")
    assert block("pid.depth").config is PidGains and block("mpc").config is MpcConfig
    assert block("pid.depth").initial(LoopConfig()) == LoopConfig().body.depth
    with pytest.raises(ValueError, match="block: 'pid.roll' is not one of mpc, pid.velocity, .*baseline"):
        block("pid.roll")


def test_a_bad_block_entry_is_refused_naming_what_is_wrong(trim: Applied) -> None:
    with pytest.raises(ValueError, match="'trim' is registered already"):
        register(block("trim"))
    with pytest.raises(ValueError, match=r"fields \['scale'\] are not fields of Trim \(gain, offset\)"):
        Block("other", Trim, "Other", ("scale",), initial=lambda c: Trim(), apply=lambda loop, cfg: None)
    with pytest.raises(ValueError, match="config must be a frozen config dataclass"):
        Block("other", dict, "Other", ("gain",), initial=lambda c: Trim(), apply=lambda loop, cfg: None)
    with pytest.raises(ValueError, match="expected a Block"):
        register("trim")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'other' is not one of"):
        unregister("other")


def test_the_loop_command_takes_a_block_registered_after_import(trim: Applied) -> None:
    assert block_names()[-1] == "trim"
    assert SetBlock("trim", Trim(gain=2.0)).cfg == Trim(gain=2.0)
    with pytest.raises(CommandRefused, match="trim config: expected a Trim, got MpcConfig"):
        SetBlock("trim", MpcConfig())
    with pytest.raises(CommandRefused, match="block: 'trims' is not one of mpc, .*baseline, trim"):
        SetBlock("trims", Trim(gain=2.0))


def test_the_loop_applies_a_registered_block_through_its_entry_at_its_next_event(trim: Applied) -> None:
    stream = TelemetryStream()
    events: list[Any] = []
    stream.subscribe(lambda c, m: events.append(m), [ch.EVENTS])
    loop = ClosedLoop(LoopConfig(mode="mpc"), SimRobotIO(depth=1.0, velocity=0.2, seed=0), stream,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    try:
        loop.run_until(0.5)
        assert loop.block_config("trim") == Trim()  # where the loop started it
        loop.submit(SetBlock("trim", Trim(gain=2.0), "pilot"))
        assert loop.block_config("trim") == Trim(gain=2.0)  # commanded at once
        assert trim.got == []  # in force only at the loop's next event
        loop.run_until(1.0)
        assert trim.configs == [Trim(gain=2.0)]
        assert 0.5 <= trim.got[0][0] <= 1.0
        tuning = [e for e in events if e.code == "tuning"]
        assert [(e.data["block"], e.data["changes"], e.data["who"]) for e in tuning] == [
            ("trim", {"gain": [1.0, 2.0]}, "pilot")]
    finally:
        loop.close()


def test_the_supervisor_checks_journals_and_undoes_a_registered_block(trim: Applied, tmp_path: Path) -> None:
    console = Console(console_config(), tmp_path)
    sup = console.sup
    try:
        sup.client_connected(PILOT)
        assert sup.take_control(PILOT, TOKEN)
        assert sup.tuning()["trim"] == Trim() and sup.saved_tuning()["trim"] == Trim()
        for changes, why in [({"trim.gain": 50.0}, "trim.gain: 50.0 is out of range"),
                             ({"trim.gain": "high"}, "trim.gain: expected a number"),
                             ({"trim.offset": 0.5}, "trim.offset: not a tunable parameter")]:
            with pytest.raises(CommandRefused, match=why):
                sup.set_params(PILOT, changes)
        sup.set_params(PILOT, {"trim.gain": 3.0})
        assert sup.param_value("trim.gain") == 3.0
        sup.step(0.2)
        assert trim.configs == [Trim(gain=3.0)]
        last = sup.journal()[-1]
        assert (last.key, last.old, last.new, last.who) == ("trim.gain", 1.0, 3.0, f"client {PILOT}")
        assert sup.current_config() == sup.cfg  # the block is not part of the configuration file

        sup.undo_tuning(PILOT)
        sup.step(0.2)
        assert trim.configs == [Trim(gain=3.0), Trim(gain=1.0)]
        assert (sup.journal()[-1].key, sup.journal()[-1].new) == ("trim.gain", 1.0)
        sup.undo_tuning(PILOT)  # a second undo redoes it
        sup.step(0.2)
        assert trim.configs[-1] == Trim(gain=3.0)
        sup.revert_tuning(PILOT)  # back to the saved tuning
        sup.step(0.2)
        assert trim.configs[-1] == Trim() and sup.tuning()["trim"] == Trim()
    finally:
        console.stop()


def test_a_block_registered_while_the_console_runs_is_tuned_and_reverted(tmp_path: Path) -> None:
    console = Console(console_config(), tmp_path)
    sup = console.sup
    got: list[Trim] = []
    register(Block("late", Trim, "Late", ("gain",), initial=lambda c: Trim(gain=2.0),
                   apply=lambda loop, cfg: got.append(cfg)))
    try:
        sup.client_connected(PILOT)
        assert sup.take_control(PILOT, TOKEN)
        assert sup.tuning()["late"] == sup.saved_tuning()["late"] == Trim(gain=2.0)  # where it starts
        sup.set_params(PILOT, {"late.gain": 5.0})
        sup.step(0.2)
        sup.revert_tuning(PILOT)
        sup.step(0.2)
        assert got == [Trim(gain=5.0), Trim(gain=2.0)]
    finally:
        unregister("late")
        console.stop()
    assert "late" not in sup.tuning() and "late" not in sup.saved_tuning()


def test_a_built_in_block_goes_into_the_configuration_in_force(tmp_path: Path) -> None:
    console = Console(console_config(), tmp_path)
    sup = console.sup
    try:
        sup.client_connected(PILOT)
        assert sup.take_control(PILOT, TOKEN)
        sup.set_params(PILOT, {"pid.yaw_rate.ki": 0.25, "baseline.frequency": 1.5})
        cfg = sup.current_config()
        assert cfg.loop.body.yaw_rate.ki == 0.25 and cfg.loop.baseline.frequency == 1.5
        assert cfg.loop.body.depth == sup.cfg.loop.body.depth and cfg.loop.mpc == sup.cfg.loop.mpc
    finally:
        console.stop()


def test_the_page_builds_an_input_for_a_registered_block_under_its_title(
        trim: Applied, tmp_path: Path, monkeypatch) -> None:
    from ucat_console.ui.app import ConsoleApp
    from ucat_console.ui.panels import ControlPanel

    console = Console(console_config(), tmp_path)
    app = ConsoleApp(console.sup, port=0)
    try:
        sup, gui = console.sup, app.server.gui
        titles: list[str] = []
        add_folder = gui.add_folder
        monkeypatch.setattr(gui, "add_folder", lambda label, *a, **kw: (titles.append(label),
                                                                         add_folder(label, *a, **kw))[1])
        sup.client_connected(PILOT)
        assert sup.take_control(PILOT, TOKEN)
        pilot = ControlPanel(app, PILOT, gui)
        assert [t for t in titles if t in ("Depth PID", "Baseline", "Trim of the test")] == [
            "Depth PID", "Baseline", "Trim of the test"]  # the registry's order
        assert "trim.offset" not in pilot.params
        gain = pilot.params["trim.gain"]
        assert gain.label.startswith("trim gain [0.0, 10.0]") and gain.value == 1.0
        gain.value = 4.0
        assert pilot.act(pilot._apply_tuning, tuning=True) is True
        sup.step(0.2)
        assert trim.configs == [Trim(gain=4.0)]
        gain.value = 40.0  # out of range: refused on the server, the input back to the value in force
        assert pilot.act(pilot._apply_tuning, tuning=True) is False
        assert "trim.gain" in pilot.messages[-1] and gain.value == 4.0
    finally:
        app.stop()
        console.stop()

