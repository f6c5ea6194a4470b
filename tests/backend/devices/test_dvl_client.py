"""DVL A50 protocol: documented messages field by field, line framing, client and emulator."""

from __future__ import annotations

import json
import math
import socket
import threading

import pytest

from ucat_console.backend.devices.dvl import (
    DvlClient,
    DvlConfig,
    DvlFormatError,
    DvlLineParser,
    LineIssue,
    encode_command,
    parse_position,
    parse_response,
    parse_velocity,
)
from ucat_console.backend.devices.dvl_emulator import DvlEmulator, DvlEmulatorConfig, DvlTruth
from ucat_console.backend.devices.faults import FaultSettings

# A velocity report in the documented TCP format (Water Linked DVL protocol, json_v3)
DOC_VELOCITY = """
{
  "time": 106.3935775756836,
  "vx": -3.713480691658333e-05,
  "vy": 5.703703573090024e-05,
  "vz": 2.4990416932269e-05,
  "fom": 0.00016016385052353144,
  "covariance": [
    [2.4471841442164077e-08, -3.3937477272871774e-09, -1.6659699175747278e-09],
    [-3.3937477272871774e-09, 1.4654466085062268e-08, 4.0409570134514183e-10],
    [-1.6659699175747278e-09, 4.0409570134514183e-10, 1.5971971523143225e-09]
  ],
  "altitude": 0.4949815273284912,
  "transducers": [
    {"id": 0, "velocity": 0.00010825289791682735, "distance": 0.5568000078201294,
     "rssi": -30.494251251220703, "nsd": -88.73271179199219, "beam_valid": true},
    {"id": 1, "velocity": -1.4719001228513662e-05, "distance": 0.5663999915122986,
     "rssi": -31.095735549926758, "nsd": -89.5116958618164, "beam_valid": true},
    {"id": 2, "velocity": 2.7863150535267778e-05, "distance": 0.537600040435791,
     "rssi": -27.180519104003906, "nsd": -96.98075103759766, "beam_valid": true},
    {"id": 3, "velocity": 1.9419496311456896e-05, "distance": 0.5472000241279602,
     "rssi": -28.006759643554688, "nsd": -88.32147216796875, "beam_valid": true}
  ],
  "velocity_valid": true,
  "status": 0,
  "format": "json_v3",
  "type": "velocity",
  "time_of_validity": 1638191471563017,
  "time_of_transmission": 1638191471752336
}
"""

# A position report in the documented format (angles in degrees)
DOC_POSITION = """
{
  "ts": 49056.809,
  "x": 12.43563613697886467,
  "y": 64.617631152402609587,
  "z": 1.767641898933798075,
  "std": 0.001959984190762043,
  "roll": 0.6173566579818726,
  "pitch": 0.6173566579818726,
  "yaw": 0.6173566579818726,
  "type": "position_local",
  "status": 0,
  "format": "json_v2"
}
"""

DOC_RESPONSE = """
{
  "response_to":"get_config",
  "success":true,
  "error_message":"",
  "result":{
    "speed_of_sound":1475,
    "acoustic_enabled":true,
    "dark_mode":false,
    "mounting_rotation_offset":20
  },
  "format":"json_v3",
  "type":"response"}
"""


def one_line(doc: str, end: bytes = b"\n") -> bytes:
    return json.dumps(json.loads(doc)).encode() + end


# ---------------------------------------------------------------- pure decoding


def test_documented_velocity_report_field_by_field() -> None:
    [msg] = DvlLineParser().feed(one_line(DOC_VELOCITY))
    v = parse_velocity(msg, t=12.5)
    assert v.t == 12.5
    assert v.vx == -3.713480691658333e-05
    assert v.vy == 5.703703573090024e-05
    assert v.vz == 2.4990416932269e-05
    assert v.fom == 0.00016016385052353144
    assert v.altitude == 0.4949815273284912
    assert v.valid is True


def test_documented_position_report_field_by_field() -> None:
    [msg] = DvlLineParser().feed(one_line(DOC_POSITION, b"\r\n"))
    p = parse_position(msg, t=3.0)
    assert (p.x, p.y, p.z) == (12.43563613697886467, 64.617631152402609587, 1.767641898933798075)
    assert p.std == 0.001959984190762043
    deg = 0.6173566579818726 * math.pi / 180.0  # the A50 sends degrees
    assert p.roll == pytest.approx(deg, rel=1e-15)
    assert p.pitch == pytest.approx(deg, rel=1e-15)
    assert p.yaw == pytest.approx(deg, rel=1e-15)


def test_documented_response() -> None:
    [msg] = DvlLineParser().feed(one_line(DOC_RESPONSE))
    r = parse_response(msg)
    assert r.response_to == "get_config" and r.success and r.error_message == ""
    assert r.result["mounting_rotation_offset"] == 20


def test_invalid_velocity_is_missing_data_not_zero() -> None:
    msg = json.loads(DOC_VELOCITY)
    msg.update(velocity_valid=False, vx=0.0, vy=0.0, vz=0.0, altitude=-1.0)
    v = parse_velocity(msg, t=0.0)
    assert v.valid is False
    assert math.isnan(v.vx) and math.isnan(v.vy) and math.isnan(v.vz)
    assert math.isnan(v.altitude)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"velocity_valid": "yes"}, "velocity_valid"),
        ({"vx": None}, "vx"),
        ({"vy": "0.1"}, "vy"),
        ({"fom": True}, "fom"),
    ],
)
def test_bad_velocity_fields_are_named(change: dict, match: str) -> None:
    msg = json.loads(DOC_VELOCITY)
    msg.update(change)
    with pytest.raises(DvlFormatError, match=match):
        parse_velocity(msg, t=0.0)


def test_missing_field_is_named() -> None:
    msg = json.loads(DOC_POSITION)
    del msg["yaw"]
    with pytest.raises(DvlFormatError, match="yaw"):
        parse_position(msg, t=0.0)


def test_line_parser_framing() -> None:
    parser = DvlLineParser()
    stream = b'{"a": 1}\r\n{"b": 2}\n{"c": 3'
    assert parser.feed(stream) == [{"a": 1}, {"b": 2}]
    assert parser.feed(b'}\r') == []
    assert parser.feed(b"\n") == [{"c": 3}]


def test_line_parser_reports_malformed_and_continues() -> None:
    items = DvlLineParser().feed(b'{"a": 1\n[1, 2]\n\xff\xfe\n{"ok": true}\n')
    kinds = [i.kind if isinstance(i, LineIssue) else i for i in items]
    assert kinds == ["malformed_json", "not_object", "malformed_json", {"ok": True}]


def test_command_encoding() -> None:
    assert encode_command("reset_dead_reckoning") == b'{"command":"reset_dead_reckoning"}\n'
    assert (
        encode_command("set_config", {"speed_of_sound": 1480})
        == b'{"command":"set_config","parameters":{"speed_of_sound":1480}}\n'
    )


# ---------------------------------------------------------------- client against a raw server


class RawServer:
    """A one-connection TCP server on 127.0.0.1 the test writes bytes into."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(1)
        self.port = self.sock.getsockname()[1]
        self.conn: socket.socket | None = None
        self._accepted = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        self.conn, _ = self.sock.accept()
        self._accepted.set()

    def send(self, data: bytes) -> None:
        assert self._accepted.wait(5.0)
        assert self.conn is not None
        self.conn.sendall(data)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.sock.close()


@pytest.fixture
def raw_client(collector):
    server = RawServer()
    vel, pos, events = collector(), collector(), collector()
    client = DvlClient(
        DvlConfig(host="127.0.0.1", port=server.port, silence_timeout_s=5.0, silence_reconnect_s=0.0),
        vel, pos, events,
    )
    client.start()
    yield server, client, vel, pos, events
    client.stop()
    server.close()


def test_client_survives_partial_lines_and_malformed_json(raw_client, wait_for) -> None:
    server, client, vel, pos, events = raw_client
    line = one_line(DOC_VELOCITY, b"\r\n")
    server.send(line[:17])
    server.send(line[17:80])
    server.send(line[80:] + b'{"type": "velocity", "vx": \n')
    server.send(b"not json at all\n" + one_line(DOC_POSITION))
    wait_for(lambda: len(pos) == 1, what="position after the malformed lines")
    assert len(vel) == 1 and vel.items[0].vx == -3.713480691658333e-05
    malformed = events.with_code("malformed_json")
    assert malformed and malformed[0].source == "dvl"
    assert client.connected


def test_client_delivers_invalid_velocity_as_missing(raw_client, wait_for) -> None:
    server, client, vel, pos, events = raw_client
    msg = json.loads(DOC_VELOCITY)
    msg.update(velocity_valid=False, vx=0.0, vy=0.0, vz=0.0, altitude=-1.0)
    server.send(json.dumps(msg).encode() + b"\n")
    wait_for(lambda: len(vel) == 1, what="velocity")
    v = vel.items[0]
    assert v.valid is False and math.isnan(v.vx)


def test_client_reports_a_message_with_bad_fields(raw_client, wait_for) -> None:
    server, client, vel, pos, events = raw_client
    msg = json.loads(DOC_VELOCITY)
    del msg["vz"]
    server.send(json.dumps(msg).encode() + b"\n")
    bad = wait_for(lambda: events.with_code("invalid_data"), what="invalid_data event")
    assert "vz" in bad[0].message
    assert len(vel) == 0


# ---------------------------------------------------------------- client against the emulator


def moving(t: float) -> DvlTruth:
    return DvlTruth(vx=0.25, vy=-0.125, vz=0.0, altitude=1.5, x=10.0 + 0.25 * t, y=2.0, yaw=0.5)


@pytest.fixture
def emulated(collector):
    made = []

    def make(emulator_config=DvlEmulatorConfig(velocity_rate_hz=15.0, position_rate_hz=10.0), **client_kw):
        emulator = DvlEmulator(moving, emulator_config).start()
        vel, pos, events = collector(), collector(), collector()
        cfg = dict(host="127.0.0.1", port=emulator.port, reconnect_min_s=0.05, reconnect_max_s=0.2)
        cfg.update(client_kw)
        client = DvlClient(DvlConfig(**cfg), vel, pos, events)
        client.start()
        made.append((client, emulator))
        return emulator, client, vel, pos, events

    yield make
    for client, emulator in made:
        client.stop()
        emulator.stop()


def test_emulator_reports_truth(emulated, wait_for) -> None:
    emulator, client, vel, pos, events = emulated()
    wait_for(lambda: len(vel) >= 2 and len(pos) >= 2, what="reports")
    v = vel.items[-1]
    assert (v.vx, v.vy, v.vz, v.altitude, v.valid) == (0.25, -0.125, 0.0, 1.5, True)
    p = pos.items[-1]
    assert p.y == 2.0 and p.yaw == pytest.approx(0.5, abs=1e-12)
    assert events.with_code("connected")[0].level == "info"


def test_command_round_trips(emulated, wait_for) -> None:
    emulator, client, vel, pos, events = emulated()
    assert client.wait_connected(5.0)
    config = client.get_config()
    assert config.success and config.result["speed_of_sound"] == 1475.0
    assert client.set_config(speed_of_sound=1500.0).success
    assert client.get_config().result["speed_of_sound"] == 1500.0
    refused = client.set_config(speed_of_sound=5000.0)
    assert not refused.success and "speed_of_sound" in refused.error_message
    assert events.with_code("command_failed")
    assert client.calibrate_gyro().success
    assert client.reset_dead_reckoning().success
    # after the reset the dead-reckoning origin is the truth position at the reset
    n = len(pos)
    wait_for(lambda: len(pos) > n + 1, what="position after reset")
    assert abs(pos.items[-1].x) < 1.0  # 10 m before the reset
    assert emulator.commands == [
        "get_config", "set_config", "get_config", "set_config", "calibrate_gyro", "reset_dead_reckoning",
    ]


def test_command_timeout_is_a_failed_response_and_an_event(emulated) -> None:
    emulator, client, vel, pos, events = emulated(
        DvlEmulatorConfig(faults=FaultSettings(slow_delay_s=0.5))
    )
    assert client.wait_connected(5.0)
    emulator.inject("slow")
    r = client.command("calibrate_gyro", timeout_s=0.1)
    assert r.timed_out and not r.success
    assert events.with_code("command_timeout")[0].data["command"] == "calibrate_gyro"


def test_invalid_fault_gives_valid_false(emulated, wait_for) -> None:
    emulator, client, vel, pos, events = emulated()
    emulator.inject("invalid")
    wait_for(lambda: any(not v.valid for v in vel.items), what="invalid velocity")
    emulator.clear()
    bad = [v for v in vel.items if not v.valid]
    assert all(math.isnan(v.vx) for v in bad)


def test_corrupt_fault_is_reported_and_survived(emulated, wait_for) -> None:
    emulator, client, vel, pos, events = emulated()
    assert client.wait_connected(5.0)
    emulator.inject("corrupt")
    wait_for(lambda: events.with_code("malformed_json"), what="malformed_json event")
    emulator.clear()
    n = len(vel)
    wait_for(lambda: len(vel) > n + 1, what="velocity after corruption")
    assert client.connections == 1


def test_silence_detected_then_recovered(emulated, wait_for) -> None:
    emulator, client, vel, pos, events = emulated(silence_timeout_s=0.3, silence_reconnect_s=0.0)
    wait_for(lambda: len(vel) > 1, what="velocity")
    emulator.inject("silence")
    wait_for(lambda: events.with_code("silence"), what="silence event")
    emulator.clear()
    wait_for(lambda: events.with_code("recovered"), what="recovered event")


def test_reconnects_after_emulator_restart(emulated, collector, wait_for) -> None:
    emulator, client, vel, pos, events = emulated()
    wait_for(lambda: len(vel) > 0, what="first velocity")
    port = emulator.port
    emulator.stop()
    wait_for(lambda: events.with_code("disconnected"), what="disconnected event")
    restarted = DvlEmulator(moving, DvlEmulatorConfig(port=port, velocity_rate_hz=15.0)).start()
    try:
        wait_for(lambda: events.with_code("reconnected"), what="reconnected event")
        n = len(vel)
        wait_for(lambda: len(vel) > n, what="velocity after reconnect")
        assert client.connections == 2
    finally:
        restarted.stop()


def test_no_server_is_reported_not_raised(collector, wait_for) -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    events = collector()
    client = DvlClient(DvlConfig(host="127.0.0.1", port=port), lambda v: None, lambda p: None, events)
    client.start()
    try:
        wait_for(lambda: events.with_code("connect_failed"), what="connect_failed")
        r = client.get_config()
        assert not r.success and r.error_message == "not connected"
    finally:
        client.stop()


def test_emulator_rate_bounds() -> None:
    with pytest.raises(ValueError, match="velocity_rate_hz"):
        DvlEmulatorConfig(velocity_rate_hz=20.0)
