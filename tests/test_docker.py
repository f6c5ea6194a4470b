"""The robot-computer image (docker/): what the container starts is a command the console
accepts, on a configuration that loads, with the devices that configuration names.

No container engine runs where the tests run, so the image itself is not built here; these
checks catch the files drifting apart (docker/README.md says how to build and run it)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import yaml

from ucat_console.cli import build_parser
from ucat_console.config import load_config

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"


def dockerfile_instruction(name: str) -> str:
    text = (DOCKER / "Dockerfile").read_text()
    found = re.findall(rf"^{name}\s+(.+)$", text, flags=re.MULTILINE)
    assert len(found) == 1, f"{name}: expected one instruction, found {found}"
    return found[0]


def compose_service() -> dict:
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    (service,) = compose["services"].values()
    return service


def container_path_on_host(service: dict, path: str) -> Path:
    """The repository file behind a container path, through the compose file's bind mounts."""
    for volume in service["volumes"]:
        host, container = volume.split(":")[:2]
        if path.startswith(container.rstrip("/") + "/"):
            return (DOCKER / host / path[len(container.rstrip("/")) + 1:]).resolve()
    raise AssertionError(f"{path}: not under any volume of the compose service")


def test_the_container_command_is_the_console_on_the_robot_configuration() -> None:
    entrypoint = json.loads(dockerfile_instruction("ENTRYPOINT"))
    cmd = json.loads(dockerfile_instruction("CMD"))
    service = compose_service()
    assert entrypoint == ["ucat-console"]
    assert service["command"] == cmd

    args = build_parser().parse_args(cmd)
    assert args.command == "run" and args.host == "0.0.0.0"
    config = container_path_on_host(service, str(args.config))
    assert config == ROOT / "config" / "robot.toml"
    app = load_config(config)
    assert app.robot == "rig" and app.devices.robot == "hardware"


def test_the_container_reaches_every_device_the_robot_configuration_names() -> None:
    service = compose_service()
    app = load_config(ROOT / "config" / "robot.toml")
    passed = {d.split(":")[1] for d in service["devices"]}
    assert {app.devices.imu.port, app.devices.pressure.port} <= passed
    # SocketCAN and the DVL's Ethernet live in the host's network namespace
    assert app.devices.epos2.interface == "socketcan"
    assert service["network_mode"] == "host"


def test_the_image_installs_the_project_and_keeps_sessions_outside() -> None:
    assert dockerfile_instruction("FROM").startswith("python:3.11")
    assert "pip install -e ." in (DOCKER / "Dockerfile").read_text()
    workdir = dockerfile_instruction("WORKDIR")
    volume = json.loads(dockerfile_instruction("VOLUME"))
    assert volume == [f"{workdir}/sessions"]
    assert any(v.endswith(f":{workdir}/sessions") for v in compose_service()["volumes"])
