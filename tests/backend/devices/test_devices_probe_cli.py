"""``ucat-console devices probe``: each emulator probed in-process, JSON lines checked."""

from __future__ import annotations

import json
import socket
import sys
import types
from pathlib import Path

import pytest

import ucat_console.cli as cli


@pytest.fixture
def run(monkeypatch):
    # only this feature's sub-command, so the test does not depend on the others
    monkeypatch.setattr(cli, "COMMANDS", ["devices"])

    def run(*argv: str) -> int:
        return cli.main(["devices", "probe", *argv])

    return run


def read_lines(path: Path) -> list[dict]:
    lines = path.read_text().splitlines()
    assert lines, "no JSON lines written"
    records = [json.loads(line) for line in lines]  # every line is one valid JSON object
    for r in records:
        assert isinstance(r, dict) and "kind" in r and "t" in r
    return records


def test_probe_imu_emulator(run, tmp_path) -> None:
    out = tmp_path / "imu.jsonl"
    assert run("imu", "--emulate", "--duration", "0.4", "--json", str(out), "--quiet") == 0
    records = [r for r in read_lines(out) if r["kind"] == "imu"]
    assert records
    for r in records:
        assert len(r["accel"]) == 3 and len(r["gyro"]) == 3
    assert r["accel"] == [0.0, 0.0, -9.80665]  # the synthetic source is level at rest: -g0, in m/s^2
    assert any(len(r.get("quaternion", [])) == 4 for r in records)


def test_probe_dvl_emulator(run, tmp_path) -> None:
    out = tmp_path / "dvl.jsonl"
    assert run("dvl", "--emulate", "--duration", "0.5", "--json", str(out), "--quiet") == 0
    records = read_lines(out)
    velocities = [r for r in records if r["kind"] == "dvl_velocity"]
    assert velocities
    v = velocities[-1]
    assert set(v) >= {"vx", "vy", "vz", "velocity_valid", "altitude", "fom"}
    assert (v["vx"], v["velocity_valid"], v["altitude"]) == (0.3, True, 2.0)
    assert any(r["kind"] == "dvl_config" for r in records)


def test_probe_pressure_emulator(run, tmp_path) -> None:
    out = tmp_path / "p.jsonl"
    assert run("pressure", "--emulate", "--duration", "0.4", "--json", str(out), "--quiet") == 0
    depths = [r["depth_m"] for r in read_lines(out) if r["kind"] == "pressure"]
    assert depths and all(0.7 < d < 1.3 for d in depths)  # 1 m +- 0.2 m synthetic source


def test_probe_without_a_device_fails_and_writes_faults(run, tmp_path) -> None:
    out = tmp_path / "none.jsonl"
    status = run("pressure", "--port", str(tmp_path / "no-tty"), "--duration", "0.1", "--json", str(out), "--quiet")
    assert status == 1
    faults = [r for r in read_lines(out) if r["kind"] == "fault"]
    assert faults and faults[0]["reason"] == "port_error" and faults[0]["source"] == "pressure"


def test_probe_dvl_nobody_listening(run, tmp_path) -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    out = tmp_path / "dvl.jsonl"
    status = run("dvl", "--host", "127.0.0.1", "--port", str(port), "--duration", "0.2", "--json", str(out), "--quiet")
    assert status == 1
    assert [r["reason"] for r in read_lines(out) if r["kind"] == "fault"][0] == "connect_failed"


def test_probe_epos_calls_the_epos2_probe(run, tmp_path, monkeypatch) -> None:
    calls = []

    def probe(interface, channel, node, bitrate, duration, emit):
        calls.append((interface, channel, node, bitrate, duration))
        emit({"kind": "epos2", "t": 1.0, "position_rad": 0.5, "velocity_rad_s": 0.0, "state": "operation_enabled"})
        return 0

    fake = types.ModuleType("ucat_console.backend.devices.epos2_probe")
    fake.probe = probe
    monkeypatch.setitem(sys.modules, "ucat_console.backend.devices.epos2_probe", fake)
    out = tmp_path / "epos.jsonl"
    args = ("epos", "--interface", "virtual", "--channel", "probe-test", "--node", "3", "--duration", "0.1")
    assert run(*args, "--json", str(out), "--quiet") == 0
    assert calls == [("virtual", "probe-test", 3, None, 0.1)]
    assert read_lines(out)[0]["position_rad"] == 0.5


def test_bad_duration_is_a_usage_error(run) -> None:
    assert run("imu", "--emulate", "--duration", "-1") == 2
