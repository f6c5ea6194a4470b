"""The fin controllers' registry: a new mode is one registration, and everything that
names a mode (the loop, its configuration, the command line, the page's dropdown and status
bar) reads it."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest
from support import TOKEN, Console, console_config

from ucat_console.backend.loop import modes
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import SetMode
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import MODES, Mode, PlannerSetting, mode_names, register
from ucat_console.backend.loop.planners import MpcFinPlanner
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.cli import build_parser
from ucat_console.control.allocation import INDEPENDENT_FINS, SYNC_FINS, BodySetpoints
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.typedconf import choices_of, describe_range


@pytest.fixture
def echo():
    """A mode registered for the test (the MPC's planner, made through the registry), and
    the settings its planners were made from."""
    made: list[PlannerSetting] = []

    def planner(s: PlannerSetting) -> MpcFinPlanner:
        made.append(s)
        return MpcFinPlanner(s.mpc, s.seed, s.executor)

    register(Mode("echo", "the MPC, registered by a test", "echo", INDEPENDENT_FINS, planner))
    yield made
    MODES.unregister("echo")


def test_the_built_in_modes_are_registered_in_the_page_order() -> None:
    assert mode_names() == ("mpc", "mpc_sync", "baseline", "identify")
    assert mode_names(follows_targets=True) == ("mpc", "mpc_sync", "baseline")
    assert MODES["mpc_sync"].rear_synchronised and not MODES["mpc"].rear_synchronised
    assert MODES["baseline"].reads == ("mpc", "baseline")


def test_the_loop_configuration_takes_the_registered_modes() -> None:
    f = next(f for f in fields(LoopConfig) if f.name == "mode")
    assert choices_of(f) == mode_names()
    with pytest.raises(ValueError, match="mode"):
        LoopConfig(mode="oracle")


def _choices(argv_prefix: list[str], option: str) -> tuple[str, ...]:
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    for name in argv_prefix:
        p = sub[name]
        subs = [a for a in p._actions if a.__class__.__name__ == "_SubParsersAction"]
        sub = subs[0].choices if subs else None
    action = next(a for a in p._actions if option in a.option_strings)
    return tuple(action.choices)


def test_the_command_line_reads_the_registry(echo) -> None:
    assert _choices(["run"], "--mode") == mode_names()
    assert "echo" in _choices(["run"], "--mode")
    assert _choices(["bench", "sim"], "--modes") == mode_names(follows_targets=True)
    assert build_parser().parse_args(["run", "--headless", "--mode", "echo"]).mode == "echo"


def test_a_mode_registered_after_import_is_taken_by_the_configuration_and_the_command_line(
        echo, tmp_path: Path) -> None:
    """``echo`` is registered by this test module, long after the loop's configuration was
    imported: the configuration, a TOML file and ``run --mode`` all take it."""
    from ucat_console.cli import run
    from ucat_console.config import load_config

    assert LoopConfig(mode="echo").mode == "echo"
    assert "'echo'" in describe_range(next(f for f in fields(LoopConfig) if f.name == "mode"))
    toml = tmp_path / "echo.toml"
    toml.write_text('[loop]\nmode = "echo"\n')
    assert load_config(str(toml)).loop.mode == "echo"
    args = build_parser().parse_args(["run", "--headless", "--mode", "echo"])
    assert run._config(args).loop.mode == "echo"
    with pytest.raises(ValueError, match="'oracle' is not allowed; allowed: one of .*'echo'"):
        LoopConfig(mode="oracle")


def test_a_mode_registered_after_import_is_chosen_on_the_page_and_runs(echo, tmp_path: Path) -> None:
    """The page's mode selector lists ``echo``; the pilot's choice passes the supervisor's
    check and the loop runs it."""
    from ucat_console.ui.app import ConsoleApp
    from ucat_console.ui.panels import ControlPanel

    console = Console(console_config(), tmp_path)
    app = ConsoleApp(console.sup, port=0)
    try:
        sup = console.sup
        sup.client_connected(3)
        assert sup.take_control(3, TOKEN)
        pilot = ControlPanel(app, 3, app.server.gui)
        assert "echo" in pilot.mode.options
        pilot.mode.value = "echo"
        assert pilot.act(lambda: sup.set_mode(3, pilot.mode.value)) is True
        assert sup.mode == "echo"
        sup.step(1.0)
        assert len(echo) == 4  # each logical fin's planner made through the registry
        with pytest.raises(CommandRefused, match="'oracle' is not one of .*echo"):
            sup.set_mode(3, "oracle")
    finally:
        app.stop()
        console.stop()


def test_a_registered_mode_runs_in_the_loop(echo) -> None:
    stream = TelemetryStream()
    plans = []
    stream.subscribe(lambda channel, msg: plans.append(msg) if channel.startswith("fin/") and
                     channel.endswith("/plan") else None)
    io = SimRobotIO(depth=1.0, velocity=0.2, seed=0)
    loop = ClosedLoop(LoopConfig(mode="mpc"), io, stream, setpoints=BodySetpoints(velocity=0.2, depth=1.0))
    loop.run_until(1.0)
    switched = loop.submit(SetMode("echo", who="test"))
    loop.run_until(4.0)
    assert switched.result(timeout=0) == "mpc"  # the mode in force before
    loop.close()
    assert loop.mode == "echo"
    assert len(echo) == 4 and {s.mpc for s in echo} == {loop.mpc_config}
    assert len({s.seed for s in echo}) == 4  # each logical fin its own stream
    assert {p.mode for p in plans} == {"mpc", "echo"}
    with pytest.raises(ValueError, match="is not one of mpc, mpc_sync, baseline, identify, echo"):
        SetMode("oracle")


def test_a_mode_is_refused_when_the_loop_cannot_run_it() -> None:
    planner = MODES["mpc"].planner
    with pytest.raises(ValueError, match="registered already"):
        register(Mode("mpc", "again", "again", INDEPENDENT_FINS, planner))
    with pytest.raises(ValueError, match="fins must be INDEPENDENT_FINS or SYNC_FINS"):
        Mode("pairs", "front and rear pairs", "pairs", ((0, 1), (2, 3)), planner)
    with pytest.raises(ValueError, match="reads"):
        Mode("x", "x", "x", SYNC_FINS, planner, reads=("weather",))
    with pytest.raises(ValueError, match="mode: 'nope' is not one of"):
        modes.mode("nope")


def test_the_status_bar_labels_each_mode_from_the_registry(echo) -> None:
    from ucat_console.ui.status_bar import mode_label

    assert [mode_label(m) for m in mode_names()] == ["MPC", "MPC sync", "baseline", "identify", "echo"]
    assert mode_label("unknown") == "unknown"
