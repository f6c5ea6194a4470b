"""AppConfig: composition of the blocks, TOML in and out, errors naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from ucat_console.backend.failsafe_config import FailsafeRule, PilotGoneRule

from ucat_console.config import AppConfig, load_config


def test_defaults_are_the_blocks_defaults() -> None:
    app = AppConfig()
    assert app.robot == "sim"
    assert app.console.host == "127.0.0.1"
    assert app.console.port == 8080
    # a gone pilot: hold, then disarm 30 s later
    assert app.failsafe.pilot_gone == PilotGoneRule("hold", 2.0, "disarm", 30.0)
    assert app.failsafe.imu == FailsafeRule("disarm", 1.0, "none")


def test_a_files_tables_follow_the_object_tree(tmp_path: Path) -> None:
    path = tmp_path / "run.toml"
    path.write_text("[loop]\nmode = \"baseline\"\n[loop.mpc]\nlam_st = 2.0\n[loop.body.hull]\nsurge_mass = 30.0\n")
    app = load_config(path)
    assert (app.loop.mode, app.loop.mpc.lam_st, app.loop.body.hull.surge_mass) == ("baseline", 2.0, 30.0)
    d = app.to_dict()
    assert d["loop"]["mpc"]["lam_st"] == 2.0 and d["loop"]["body"]["hull"]["surge_mass"] == 30.0
    assert not {"mpc", "baseline", "body", "executor", "power"} & set(d)  # no table outside the tree


def test_toml_round_trip_keeps_every_value(tmp_path: Path) -> None:
    app = AppConfig().replace(robot="hardware")
    app = app.replace(loop=app.loop.replace(mpc=app.loop.mpc.replace(lam_f=3.0)), console=app.console.replace(port=0))
    path = tmp_path / "run.toml"
    path.write_text(app.to_toml())
    back = load_config(path)
    assert back == app
    assert back.loop.mpc.lam_f == 3.0
    assert "\n[loop.mpc]\n" in app.to_toml() and "\n[mpc]\n" not in app.to_toml()


def test_partial_file_keeps_defaults_elsewhere(tmp_path: Path) -> None:
    path = tmp_path / "pool.toml"
    path.write_text('[failsafe.pilot_gone]\naction = "surface"\ntimeout = 3.5\n[loop]\nmode = "baseline"\n')
    app = load_config(path)
    # the pilot-gone rule's escalation stays when its table sets the action only
    assert app.failsafe.pilot_gone == PilotGoneRule("surface", 3.5, "disarm", 30.0)
    assert app.failsafe.dvl == AppConfig().failsafe.dvl
    assert app.loop.mode == "baseline"


@pytest.mark.parametrize(
    "text, key",
    [
        ('[failsafe.motor]\naction = "explode"\n', "failsafe.motor.action"),
        ('[failsafe.pilot_gone]\nescalate = "warn"\n', "failsafe.pilot_gone.escalate"),
        ('[failsafe.pilot_gone]\naction = "surface"\nescalate = "hold"\n', "failsafe.pilot_gone.escalate"),
        ("[failsafe.pilot_gone]\nescalate_after = -1.0\n", "failsafe.pilot_gone.escalate_after"),
        ("[console]\nport = 70000\n", "console.port"),
        ("[console]\nsupervise_period = 0.0\n", "console.supervise_period"),
        ('[console]\nplot_rate = "fast"\n', "console.plot_rate"),
        ("[access]\ntoken = \"short\"\n", "token"),
        ("[loop.mpc]\nlam_st = -1.0\n", "loop.mpc.lam_st"),
        ("[loop.body.hull]\nsurge_mass = 0.0\n", "loop.body.hull.surge_mass"),
        ("[mpc]\nlam_st = -1.0\n", "loop.mpc.lam_st"),  # an older file's table: the key it loads as
        ("loop = 3\n[mpc]\nlam_st = 2.0\n", "loop: expected a table"),
        ('robot = "boat"\n', "robot"),
        ("[console]\nnope = 1\n", "console.nope"),
        # a page is gone after three unanswered heartbeats: they must fit in the pilot's timeout
        ("[console]\nheartbeat_period = 1.0\n", "console.heartbeat_period"),
        ("[failsafe.pilot_gone]\ntimeout = 0.5\n", "failsafe.pilot_gone.timeout"),
    ],
)
def test_bad_values_are_refused_naming_the_key(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=key.replace(".", r"\.")) as e:
        load_config(path)
    assert str(path) in str(e.value)


def test_a_binary_file_is_refused_naming_the_file(tmp_path: Path) -> None:
    p = tmp_path / "pool.toml"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00binary")
    with pytest.raises(ValueError, match=r"pool\.toml: not a text file"):
        load_config(p)
    with pytest.raises(ValueError, match=r"is a directory"):
        load_config(tmp_path)


def test_secret_fields_are_left_out_of_a_redacted_config_and_its_repr() -> None:
    from ucat_console.backend.access import AccessConfig

    cfg = AppConfig(access=AccessConfig(token="s3cret-pilot-token"))
    assert "s3cret-pilot-token" in cfg.to_toml()  # the file the operator writes keeps it
    assert "s3cret-pilot-token" not in cfg.to_toml(redact=True)
    assert "s3cret-pilot-token" not in repr(cfg)
    assert AppConfig.from_dict(cfg.to_dict(redact=True)).access.token == ""


def test_the_emulated_rig_ships_the_simulated_robots_controller() -> None:
    """sim-devices drives the same simulated robot as sim-tuned (behind the emulators): its
    controller settings are sim-tuned's, so it swims and tracks as that does."""
    from ucat_console.config import load_config

    tuned, rig = load_config("sim-tuned"), load_config("sim-devices")
    assert rig.loop.mpc == tuned.loop.mpc and rig.loop.body == tuned.loop.body \
        and rig.loop.baseline == tuned.loop.baseline


@pytest.mark.parametrize("text, robot, keys", [
    ('robot = "rig"\n[devices]\nrobot = "hardware"\n', "hardware", "robot = 'rig' and devices.robot = 'hardware'"),
    ('robot = "rig"\n', "sim-devices", "robot = 'rig'"),  # the old default behind the drivers
    ('robot = "sim"\n[devices]\nrobot = "hardware"\nenable_at_start = true\n', "sim", "devices.robot = 'hardware'"),
])
def test_an_older_files_two_robot_keys_load_as_the_one_selector_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, text: str, robot: str, keys: str) -> None:
    path = tmp_path / "old.toml"
    path.write_text(text)
    with caplog.at_level("WARNING", logger="ucat_console.config"):
        app = load_config(path)
    assert app.robot == robot
    assert f"{keys}: the robot is one key now; loaded as robot = '{robot}'" in caplog.text
    assert "robot" not in app.to_dict()["devices"]  # written back in the present form


def test_an_older_files_robot_keys_that_meant_nothing_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "old.toml"
    path.write_text('robot = "rig"\n[devices]\nrobot = "sim"\n')
    with pytest.raises(ValueError, match="^.*devices.robot: 'sim' is the in-process simulator"):
        load_config(path)


def test_an_older_files_controller_tables_load_into_the_loop_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "old.toml"
    path.write_text('[mpc]\nlam_st = 2.0\n[body]\nheave_trim = -1.5\n[body.hull]\nsurge_mass = 30.0\n'
                    '[loop]\nmode = "baseline"\n[loop.mpc]\nlam_f = 4.0\n')
    with caplog.at_level("WARNING", logger="ucat_console.config"):
        app = load_config(path)
    assert (app.loop.mpc.lam_st, app.loop.mpc.lam_f, app.loop.mode) == (2.0, 4.0, "baseline")
    assert (app.loop.body.heave_trim, app.loop.body.hull.surge_mass) == (-1.5, 30.0)
    assert app.loop.executor == AppConfig().loop.executor
    assert ("[mpc], [body]: the controller blocks are tables of [loop] now; loaded as [loop.mpc], [loop.body] "
            "(write those instead)") in caplog.text
    assert "mpc" not in app.to_dict() and app.to_dict()["loop"]["mpc"]["lam_st"] == 2.0  # written back in the tree


def test_an_older_files_controller_table_that_agrees_with_the_loops_loads(tmp_path: Path) -> None:
    path = tmp_path / "old.toml"
    path.write_text("[mpc]\nlam_st = 2.0\n[loop.mpc]\nlam_st = 2.0\nlam_f = 4.0\n")
    assert (load_config(path).loop.mpc.lam_st, load_config(path).loop.mpc.lam_f) == (2.0, 4.0)


@pytest.mark.parametrize("text, old, new", [
    ("[mpc]\nlam_st = 2.0\n[loop.mpc]\nlam_st = 3.0\n", "mpc.lam_st", "loop.mpc.lam_st"),
    ("[body.hull]\nsurge_mass = 30.0\n[loop.body.hull]\nsurge_mass = 31.0\n",
     "body.hull.surge_mass", "loop.body.hull.surge_mass"),
])
def test_an_older_files_controller_key_that_differs_from_the_loops_is_refused_naming_both(
        tmp_path: Path, text: str, old: str, new: str) -> None:
    path = tmp_path / "old.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=rf"{old.replace('.', '[.]')}: .* and {new.replace('.', '[.]')} .*both give it"):
        load_config(path)
