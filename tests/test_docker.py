"""The robot-computer image (docker/): what the container starts is a command the console
accepts, on a configuration that loads, with the devices that configuration names; and the
image itself, built by docker/build.sh with buildah and run (marked ``image``)."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest
import yaml

from ucat_console import shipped
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.cli import build_parser
from ucat_console.config import load_config

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"


def dockerfile_instruction(name: str) -> str:
    text = (DOCKER / "Dockerfile").read_text()
    found = re.findall(rf"^{name}\s+(.+)$", text, flags=re.MULTILINE)
    assert len(found) == 1, f"{name}: expected one instruction, found {found}"
    return found[0]


def dockerfile_env() -> dict[str, str]:
    text = (DOCKER / "Dockerfile").read_text().replace("\\\n", " ")
    (env,) = re.findall(r"^ENV\s+(.+)$", text, flags=re.MULTILINE)
    return dict(item.split("=", 1) for item in env.split())


def dockerfile_labels() -> dict[str, str]:
    text = (DOCKER / "Dockerfile").read_text().replace("\\\n", " ")
    (labels,) = re.findall(r"^LABEL\s+(.+)$", text, flags=re.MULTILINE)
    return dict(item.split("=", 1) for item in shlex.split(labels))


def dockerfile_args() -> dict[str, str]:
    text = (DOCKER / "Dockerfile").read_text()
    return dict(re.findall(r"^ARG\s+(\w+)=(\S+)$", text, flags=re.MULTILINE))


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
    assert entrypoint == ["ucat-console"]
    args = build_parser().parse_args(cmd)
    assert args.command == "run" and args.host == "0.0.0.0"
    app = load_config(args.config)  # the image's own copy, by name
    assert app.robot == "hardware"
    # compose runs the same command on the repository's copy, mounted (edits apply at a start)
    service = compose_service()
    composed = build_parser().parse_args(service["command"])
    assert (composed.command, composed.host) == ("run", "0.0.0.0")
    assert container_path_on_host(service, composed.config) == shipped.config_path(args.config)


def test_the_container_reaches_every_device_the_robot_configuration_names() -> None:
    service = compose_service()
    app = load_config("robot")
    passed = {d.split(":")[1] for d in service["devices"]}
    assert {app.devices.imu.port, app.devices.pressure.port} <= passed
    # SocketCAN and the DVL's Ethernet live in the host's network namespace
    assert app.devices.epos2.interface == "socketcan"
    assert service["network_mode"] == "host"


def test_the_image_installs_the_pinned_package_and_records_into_its_volume() -> None:
    assert dockerfile_instruction("FROM").startswith("python:3.11")
    text = (DOCKER / "Dockerfile").read_text()
    assert "pip install -c /tmp/ucat-console/constraints.txt /tmp/ucat-console " in text
    assert "rm -rf /tmp/ucat-console" in text  # the installed package, not the source tree
    sessions = dockerfile_env()["UCAT_CONSOLE_SESSIONS"]
    assert json.loads(dockerfile_instruction("VOLUME")) == [sessions]
    assert any(v.endswith(f":{sessions}") for v in compose_service()["volumes"])


def test_the_image_is_labelled_with_the_projects_metadata() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    labels = dockerfile_labels()
    # the version label is the build argument docker/build.sh sets from pyproject.toml; its
    # default (a plain `docker build`) is the same
    assert labels["org.opencontainers.image.version"] == "${UCAT_CONSOLE_VERSION}"
    assert dockerfile_args()["UCAT_CONSOLE_VERSION"] == project["version"]
    assert 'UCAT_CONSOLE_VERSION=$version' in (DOCKER / "build.sh").read_text()
    assert labels["org.opencontainers.image.title"] == project["name"]
    assert labels["org.opencontainers.image.source"] == project["urls"]["Source"]
    assert labels["org.opencontainers.image.licenses"] == project["license"]
    assert labels["org.opencontainers.image.description"]


def test_the_image_runs_as_a_user_in_the_serial_group_on_a_prepared_generic_cache() -> None:
    text = (DOCKER / "Dockerfile").read_text()
    user = dockerfile_instruction("USER")
    assert user not in ("root", "0")
    (useradd,) = re.findall(r"useradd .*", text)
    assert "--groups dialout" in useradd and useradd.rstrip("\\ ").endswith(f" {user}")
    env = dockerfile_env()
    cache = env["UCAT_CONSOLE_CACHE_DIR"]
    # numba's code for any CPU of the architecture, at the build's prepare and at every run
    assert env["NUMBA_CPU_NAME"] == "generic" and "NUMBA_CACHE_DIR" not in env
    # the cache and the sessions folder are the user's, made before the user prepares the cache
    assert re.search(rf"install -d -o {user} -g {user} .*{re.escape(cache)}", text)
    assert re.search(rf"install -d -o {user} -g {user} .*{re.escape(env['UCAT_CONSOLE_SESSIONS'])}", text)
    assert text.index(f"USER {user}") < text.index("RUN ucat-console prepare")


def test_the_image_carries_the_licence_and_the_third_party_notices() -> None:
    text = (DOCKER / "Dockerfile").read_text()
    assert re.search(r"/usr/share/doc/ucat-console\s+\\?\s*/tmp/ucat-console/LICENSE /tmp/ucat-console/THIRD_PARTY_NOTICES.md", text)
    ignored = (DOCKER / "Dockerfile.dockerignore").read_text().split()
    assert "THIRD_PARTY_NOTICES.md" not in ignored and "LICENSE" not in ignored


@pytest.mark.image
@pytest.mark.timeout(3600)
def test_the_image_builds_and_a_recorded_headless_run_works_in_it(tmp_path: Path) -> None:
    if shutil.which("buildah") is None and shutil.which("apt-get") is None:
        pytest.fail("buildah is not installed and cannot be (no apt-get)")
    sessions = tmp_path / "sessions"
    try:
        proc = subprocess.run(["bash", str(DOCKER / "build.sh"), "--tag", "ucat-console:test",
                               "--sessions", str(sessions)],
                              capture_output=True, text=True, timeout=3500)
    finally:  # the image is not kept (900 MB): the next run builds afresh anyway
        subprocess.run(["buildah", "rmi", "ucat-console:test"], capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    (recording,) = sessions.glob("*.mcap")  # the smoke run's, on this machine
    with SessionReader(recording, sessions) as r:
        assert r.duration >= 5.0 - 0.05
        assert r.message_counts()["body/state"] > 0
        assert any(e.code == "armed" for e in r.events())
    # run as the image's user, not root, and served by the cache prepared at build time
    assert re.search(r"smoke test as ucat \(.*\bdialout\b.*\)", proc.stdout), proc.stdout[-2000:]
    assert "smoke test: 0 compiled-code files written" in proc.stdout, proc.stdout[-2000:]
    size = re.search(r"image ucat-console:test \((\w+)\): (\S+ \w+)", proc.stdout)
    assert size, proc.stdout[-2000:]
