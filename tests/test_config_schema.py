"""The configuration's JSON Schema: the shipped file is the one the fields make now, every
shipped configuration keeps to it, and what it refuses the loader refuses too."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import jsonschema
import pytest

from ucat_console import shipped
from ucat_console.config import AppConfig
from ucat_console.config_schema import SCHEMA_NAME, app_schema, schema_path, schema_text

REGENERATE = f"ucat-console config schema --out ucat_console/configs/{SCHEMA_NAME}"


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(schema_path().read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _schema_errors(validator: jsonschema.Draft202012Validator, data: dict) -> list[str]:
    return [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(data)]


def test_the_shipped_schema_is_the_one_the_configuration_makes() -> None:
    assert schema_path().read_text(encoding="utf-8") == schema_text(), (
        f"the configuration's fields changed: write its schema again with `{REGENERATE}`")


@pytest.mark.parametrize("name", shipped.config_names())
def test_every_shipped_configuration_keeps_to_the_schema(validator, name: str) -> None:
    path = shipped.config_path(name)
    assert path.read_text(encoding="utf-8").splitlines()[0] == f"#:schema ./{SCHEMA_NAME}"
    with path.open("rb") as fh:
        data = tomllib.load(fh)
    assert _schema_errors(validator, data) == []
    AppConfig.from_dict(data)  # and the loader takes it


def test_a_configuration_written_out_keeps_to_the_schema(validator) -> None:
    """``to_toml`` (``to_dict`` as a file holds it: arrays for tuples), of the defaults and of a
    configuration with another robot and mode."""
    app = AppConfig()
    changed = app.replace(robot="hardware", loop=app.loop.replace(mode="baseline"))
    for written in (app, changed):
        data = tomllib.loads(written.to_toml())
        assert data == json.loads(json.dumps(written.to_dict()))  # the file holds every value
        assert _schema_errors(validator, data) == []


def test_the_schema_gives_each_field_its_range_default_and_description() -> None:
    props = app_schema()["properties"]
    lam_st = props["loop"]["properties"]["mpc"]["properties"]["lam_st"]
    assert lam_st["type"] == "number" and lam_st["default"] == AppConfig().loop.mpc.lam_st
    assert lam_st["description"]
    speed = props["loop"]["properties"]["max_velocity"]
    assert speed["exclusiveMinimum"] == 0.0 and "minimum" not in speed and "(m/s)" in speed["description"]
    assert props["robot"]["enum"] == ["sim", "sim-devices", "hardware"]  # read from the registry
    sensors = props["failsafe"]["properties"]["sensors"]
    assert sensors["type"] == "array" and sensors["items"]["required"] == ["name"]
    units = props["devices"]["properties"]["epos2"]["properties"]["units"]["properties"]
    assert units["gear_ratio"]["exclusiveMinimum"] == 0.0 and units["encoder_lines"]["type"] == "integer"


# (what is wrong, the file's data): each refused by the schema and by the loader
BAD = [
    ("an unknown key", {"loop": {"mpc": {"lam_sT": 2.0}}}),
    ("an unknown table", {"consol": {"port": 80}}),
    ("a value out of range", {"console": {"port": 70000}}),
    ("a value on an open bound", {"loop": {"max_velocity": 0.0}}),
    ("a wrong type", {"console": {"port": "8080"}}),
    ("a boolean for a number", {"loop": {"mpc": {"lam_st": True}}}),
    ("a number for a table", {"loop": {"mpc": 3}}),
    ("a bad choice", {"loop": {"mode": "mpc_async"}}),
    ("a robot not registered", {"robot": "rig-of-theseus"}),
    ("an array of the wrong length", {"devices": {"epos2": {"node_ids": [1, 2, 3]}}}),
    ("a string in an array of numbers", {"plant": {"vehicle": {"cg": [0.0, "0", 0.0]}}}),
    ("an unknown key in an array of tables", {"seek": {"params": [{"name": "mpc.lam_st", "low": 1.0}]}}),
    ("a sensor rule naming no sensor", {"failsafe": {"sensors": [{"action": "warn"}]}}),
    ("a drive's block out of range", {"devices": {"epos2": {"units": {"gear_ratio": 0.0}}}}),
    ("a motor's block out of range", {"plant": {"motor": {"gear_efficiency": 1.5}}}),
]


@pytest.mark.parametrize("data", [d for _, d in BAD], ids=[why for why, _ in BAD])
def test_a_bad_file_is_refused_by_the_schema_and_by_the_loader(validator, data: dict) -> None:
    assert _schema_errors(validator, data), "the schema took it"
    with pytest.raises(ValueError):
        AppConfig.from_dict(data)


# files the loader takes that are not the defaults: the schema takes them too
GOOD = [
    {"loop": {"mpc": {"lam_st": 2}}},  # an integer for a number
    {"failsafe": {"sensors": [{"name": "leak", "action": "warn"}]}},
    {"seek": {"params": [{"name": "mpc.lam_st", "lo": 1.0, "hi": 4.0}]}},
    {"loop": {"manoeuvre": {"steps": [[0.0, 0.6, 2.0], [0.5, 1.0, 3]]}}},
    {"loop": {"mpc": {"table_path": "fin-table.npz"}}},
    {"access": {"token": "a long enough pilot token"}},
]


@pytest.mark.parametrize("data", GOOD)
def test_a_good_file_is_taken_by_the_schema_and_by_the_loader(validator, data: dict) -> None:
    AppConfig.from_dict(data)
    assert _schema_errors(validator, data) == []


def test_the_command_prints_and_writes_the_schema(tmp_path: Path) -> None:
    out = tmp_path / "schema.json"
    run = [sys.executable, "-c", "import sys; from ucat_console.cli import main; sys.exit(main(sys.argv[1:]))",
           "config", "schema"]
    printed = subprocess.run(run, capture_output=True, text=True, check=True, timeout=300).stdout
    assert printed == schema_text()
    subprocess.run([*run, "--out", str(out)], capture_output=True, check=True, timeout=300)
    assert out.read_text(encoding="utf-8") == schema_text()
