"""The live Foxglove server: ``ucat-console run --foxglove-port 0`` on 127.0.0.1, read by a
Foxglove WebSocket client (the protocol, foxglove.sdk.v1, spoken with ``websockets``), as Foxglove and
Lichtblick read it; and the server on its own stream."""

from __future__ import annotations

import json
import os
import re
import signal
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from websockets.sync.client import connect

from support import sim_config, wait_for
from ucat_console.backend.foxglove_live import FoxgloveServer
from ucat_console.backend.sessions import codec, foxglove
from ucat_console.backend.sessions.schema import json_schema_bytes
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import BodyState, Setpoints
from ucat_console.telemetry.stream import TelemetryStream

ROOT = Path(__file__).resolve().parents[2]
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk speaks (foxglove.websocket.v1 renamed)
MESSAGE_DATA = 0x01  # binary opcode of a message, both ways


class Client:
    """A Foxglove WebSocket client: the server's channels, subscriptions, received messages."""

    def __init__(self, url: str) -> None:
        self.ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30)
        self.info: dict = {}
        self.channels: dict[str, dict] = {}
        self._subs: dict[int, str] = {}
        wait_for(lambda: self._pump() or (self.info and len(self.channels) >= len(C.CHANNELS)),
                 timeout=30, what="serverInfo and the advertised channels")

    def _pump(self, timeout: float = 0.2) -> list[tuple[str, int, bytes]]:
        """Read what has arrived: control messages recorded, data messages returned."""
        out = []
        while True:
            try:
                frame = self.ws.recv(timeout=timeout)
            except TimeoutError:
                return out
            timeout = 0.0
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    self.info = msg
                elif msg["op"] == "advertise":
                    self.channels.update({c["topic"]: c for c in msg["channels"]})
            elif frame[0] == MESSAGE_DATA:
                sub, ns = struct.unpack_from("<IQ", frame, 1)
                out.append((self._subs[sub], ns, frame[13:]))

    def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sid = len(self._subs) + 1
            self._subs[sid] = topic
            subs.append({"id": sid, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, topics: set[str], timeout: float = 30.0) -> list[tuple[str, int, bytes]]:
        """Messages until every topic of ``topics`` has sent at least one."""
        got: list = []
        wait_for(lambda: got.extend(self._pump()) or topics <= {t for t, _, _ in got},
                 timeout=timeout, what=f"messages on {sorted(topics)}")
        return got

    def close(self) -> None:
        self.ws.close()


@pytest.mark.slow
def test_run_serves_the_live_robot_to_a_foxglove_client_read_only(tmp_path):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from ucat_console.cli import main; sys.exit(main())",
         "run", "--config", str(sim_config(tmp_path)), "--headless",
         "--duration", "120", "--mode", "baseline", "--velocity", "0.2", "--depth", "0.5",
         "--foxglove-port", "0"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    client = None
    try:
        url = None
        for line in proc.stdout:
            m = re.search(r"Foxglove server on (ws://127\.0\.0\.1:\d+)", line)
            if m:
                url = m.group(1)
                break
        assert url, "the command printed no Foxglove server address"
        client = Client(url)
        # read-only: no capability that lets a client publish, set parameters or call
        assert not {"clientPublish", "parameters", "services"} & set(client.info["capabilities"])
        # the channels and schemas of a session file
        assert set(client.channels) == set(C.CHANNELS) | set(foxglove.DERIVED_TOPICS)
        body = client.channels[C.BODY_STATE]
        assert (body["encoding"], body["schemaName"], body["schemaEncoding"]) == (
            "json", "ucat_console.BodyState", "jsonschema")
        assert body["schema"] == json_schema_bytes(BodyState).decode()
        assert client.channels["foxglove/scene"]["schemaName"] == "foxglove.SceneUpdate"
        topics = {C.BODY_STATE, C.fin_state(0), C.fin_plan(0), C.fin_strouhal(0), C.SETPOINTS,
                  "foxglove/tf/base_link", "foxglove/tf/fin0", "foxglove/scene",
                  "foxglove/tf/odom"}
        client.subscribe(*topics)
        got = client.receive(topics)
        states = [codec.decode(BodyState, d) for t, _, d in got if t == C.BODY_STATE]
        assert states and all(isinstance(s, BodyState) for s in states)
        assert all(ns > 1_600_000_000 * 10**9 for _, ns, _ in got)  # UNIX nanoseconds
        tf = [json.loads(d) for t, _, d in got if t.startswith("foxglove/tf/")]
        assert {x["child_frame_id"] for x in tf} & {"base_link", "fin0"}
        for topic in topics:  # in log-time order on every channel
            ns = [n for t, n, _ in got if t == topic]
            assert ns == sorted(ns), topic
        # a client that tries to command: advertise a channel, publish a setpoint, set a
        # parameter; the server takes none of it and goes on publishing the same setpoints
        client.ws.send(json.dumps({"op": "advertise", "channels": [{
            "id": 7, "topic": C.SETPOINTS, "encoding": "json",
            "schemaName": "ucat_console.Setpoints"}]}))
        client.ws.send(bytes([MESSAGE_DATA]) + struct.pack("<I", 7)
                       + codec.encode(Setpoints(0.0, 9.0, 5.0, 1.0)))
        client.ws.send(json.dumps({"op": "setParameters", "parameters": [
            {"name": "velocity", "value": 9.0}]}))
        after = client.receive({C.SETPOINTS, C.BODY_STATE})
        after += client.receive({C.SETPOINTS})  # and the next setpoints after those
        setpoints = [codec.decode(Setpoints, d) for t, _, d in after if t == C.SETPOINTS]
        assert len(setpoints) >= 2 and all((s.velocity, s.depth) == (0.2, 0.5) for s in setpoints)
        assert proc.poll() is None  # still running
    finally:
        if client is not None:
            client.close()
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out


def test_the_server_publishes_its_stream_and_refuses_a_taken_port():
    stream = TelemetryStream()
    with FoxgloveServer(stream, port=0) as server:
        assert server.url == f"ws://127.0.0.1:{server.port}"
        client = Client(server.url)
        try:
            client.subscribe(C.BODY_STATE, "foxglove/scene")
            state = BodyState(5.0, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.1, 0.0, 0.0),
                              (0.0, 0.0, 0.0), 3.0)
            got: list = []

            def arrived():
                stream.publish(C.BODY_STATE, state)
                got.extend(client._pump(timeout=0.05))
                return {t for t, _, _ in got} >= {C.BODY_STATE, "foxglove/scene"}

            wait_for(arrived, what="the body state and the scene")
            data = next(d for t, _, d in got if t == C.BODY_STATE)
            assert codec.decode(BodyState, data) == state
            assert next(ns for t, ns, _ in got if t == C.BODY_STATE) == 5 * 10**9
            with pytest.raises(ValueError, match=f"cannot listen on 127.0.0.1:{server.port}"):
                FoxgloveServer(stream, port=server.port)
        finally:
            client.close()


FETCH_ASSET_RESPONSE = 0x04  # binary opcode


def _fetch(client: Client, uri: str, request_id: int) -> tuple[int, str, bytes]:
    """(status, error, data) of a fetchAsset request (the assets capability)."""
    client.ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id}))
    while True:
        frame = client.ws.recv(timeout=30)
        if isinstance(frame, bytes) and frame[0] == FETCH_ASSET_RESPONSE:
            rid, status, n = struct.unpack_from("<IBI", frame, 1)
            if rid == request_id:
                return status, frame[10:10 + n].decode(), frame[10 + n:]


def test_the_server_serves_the_robots_urdf_and_mesh_and_nothing_else():
    from ucat_console.robot import urdf

    with FoxgloveServer(TelemetryStream(), port=0) as server:
        client = Client(server.url)
        try:
            assert "assets" in client.info["capabilities"]
            assert _fetch(client, urdf.URDF_URI, 1) == (0, "", urdf.URDF_PATH.read_bytes())
            assert _fetch(client, urdf.MESH_URI, 2) == (0, "", urdf.MESH_PATH.read_bytes())
            for k, uri in enumerate(("package://ucat_description/urdf/../../urdf.py",
                                     "package://ucat_description/package.xml",
                                     "file:///etc/passwd", "package://ucat_console/config.py"), 3):
                status, error, data = _fetch(client, uri, k)
                assert status == 1 and data == b"", uri
        finally:
            client.close()


def test_the_old_subprotocol_name_is_refused_as_the_sdk_does():
    """foxglove-sdk accepts foxglove.sdk.v1 only (docs/sessions.md): if a release accepts the
    old name, the server should offer it and this test says so."""
    from websockets.exceptions import InvalidStatus

    with FoxgloveServer(TelemetryStream(), port=0) as server:
        with pytest.raises(InvalidStatus, match="400"):
            connect(server.url, subprotocols=["foxglove.websocket.v1"], open_timeout=30)
