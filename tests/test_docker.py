"""The robot-computer image (docker/): what the container starts is a command the console
accepts, on a configuration that loads, with the devices that configuration names.

No container engine runs where the tests run, so the image itself is not built here; these
checks catch the files drifting apart (docker/README.md says how to build and run it), and
check that ``docker/check_rootfs.py``, which carries the Dockerfile out in a Debian root by
hand, reads the whole Dockerfile and the build context as docker would."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import yaml

from ucat_console.cli import build_parser
from ucat_console.config import load_config

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
_spec = importlib.util.spec_from_file_location("check_rootfs", DOCKER / "check_rootfs.py")
check_rootfs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_rootfs)


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
    text = (DOCKER / "Dockerfile").read_text()
    assert 'pip install -c constraints.txt -e ".[foxglove]"' in text  # pinned, reproducible
    assert (ROOT / "constraints.txt").is_file()
    patterns = [x for x in (DOCKER / "Dockerfile.dockerignore").read_text().splitlines()
                if x and not x.startswith("#")]
    assert not check_rootfs.ignored("constraints.txt", patterns)  # in the build context
    workdir = dockerfile_instruction("WORKDIR")
    volume = json.loads(dockerfile_instruction("VOLUME"))
    assert volume == [f"{workdir}/sessions"]
    assert any(v.endswith(f":{workdir}/sessions") for v in compose_service()["volumes"])


def test_the_rootfs_check_knows_every_instruction_of_the_dockerfile() -> None:
    steps = check_rootfs.instructions(DOCKER / "Dockerfile")
    assert steps[0] == ("FROM", check_rootfs.BASE)
    assert {word for word, _ in steps} <= {"FROM", "ENV", "WORKDIR", "COPY", "RUN", "VOLUME",
                                          "ENTRYPOINT", "CMD"}
    runs = [rest for word, rest in steps if word == "RUN"]
    assert any(r.startswith("apt-get update") and "can-utils" in r for r in runs)  # joined lines
    assert any("ucat-console prepare" in r for r in runs)  # the compiled code goes into the image
    assert ("ENTRYPOINT", dockerfile_instruction("ENTRYPOINT")) in steps


def test_the_build_context_leaves_out_only_what_the_dockerignore_names() -> None:
    files = set(check_rootfs.context_files())
    assert {"pyproject.toml", "config/robot.toml", "ucat_console/backend/sessions/reader.py",
            "ucat_console/backend/devices/epos2.eds"} <= files
    assert not any(f.startswith(("tests/", "docker/", "benchmarks/", "sessions/")) for f in files)
    ignore = ["sessions", "**/__pycache__", ".git"]
    assert check_rootfs.ignored("sessions/x_001.mcap", ignore)
    assert not check_rootfs.ignored("ucat_console/backend/sessions/reader.py", ignore)  # rooted
    assert check_rootfs.ignored("ucat_console/control/__pycache__/mpc.cpython-311.pyc", ignore)
