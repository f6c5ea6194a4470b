"""The live Foxglove server checks the Origin of every websocket handshake: raw websocket
clients sending the headers a browser page, a desktop app and a tool send; refused ones get
HTTP 403 and read nothing."""

from __future__ import annotations

import json
import logging

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from ucat_console.backend.foxglove_live import SUBPROTOCOL, FoxgloveServer, origin_allowed
from ucat_console.config import AppConfig
from ucat_console.telemetry.stream import TelemetryStream

ALLOWED = [None, "file://", "http://localhost:8080", "https://localhost", "http://127.0.0.1:3000",
           "http://[::1]:5173", "HTTP://LOCALHOST:8080/"]
REFUSED = ["https://evil.example", "null", "http://localhost.evil.example", "http://127.0.0.1.nip.io",
           "https://app.foxglove.dev", "http://192.168.1.20:8080", "http://user@localhost", "http://localhost:x",
           "http://localhost/path", "ws://localhost:8765", ""]
FOXGLOVE_APP = "https://app.foxglove.dev"


def opens(url: str, origin: str | None) -> dict:
    """The serverInfo a client with this Origin (None: no header) gets."""
    headers = {"Origin": origin} if origin is not None else None
    with connect(url, subprotocols=[SUBPROTOCOL], additional_headers=headers, open_timeout=30) as ws:
        return json.loads(ws.recv(timeout=30))


def test_the_origin_rules() -> None:
    for origin in ALLOWED:
        assert origin_allowed(origin), origin
    for origin in REFUSED:
        assert not origin_allowed(origin), origin
    assert origin_allowed(FOXGLOVE_APP, [FOXGLOVE_APP]) and origin_allowed(FOXGLOVE_APP + "/", [FOXGLOVE_APP])
    assert not origin_allowed("https://app.foxglove.dev.evil.example", [FOXGLOVE_APP])


def test_pages_of_other_origins_are_refused_with_403_and_this_machines_clients_connect(caplog) -> None:
    with FoxgloveServer(TelemetryStream(), port=0) as server:
        for origin in (None, "file://", "http://localhost:8080", "http://127.0.0.1:3000", "http://[::1]:5173"):
            assert opens(server.url, origin)["op"] == "serverInfo", origin
        with caplog.at_level(logging.WARNING, logger="ucat_console.backend.foxglove_live"):
            for origin in ("https://evil.example", "null", FOXGLOVE_APP, "https://evil.example"):
                with pytest.raises(InvalidStatus) as refused:
                    opens(server.url, origin)
                assert refused.value.response.status_code == 403, origin
        assert server.refused == 4
        logged = [r.getMessage() for r in caplog.records]
        assert len(logged) == 3 and all("refused a connection from Origin" in m for m in logged)  # one per origin
        assert "foxglove.allowed_origins" in logged[0]


def test_a_configured_origin_connects() -> None:
    origins = AppConfig.from_dict({"foxglove": {"allowed_origins": [FOXGLOVE_APP]}}).foxglove.allowed_origins
    with FoxgloveServer(TelemetryStream(), port=0, allowed_origins=origins) as server:
        assert opens(server.url, FOXGLOVE_APP)["op"] == "serverInfo"
        with pytest.raises(InvalidStatus, match="403"):
            opens(server.url, "https://evil.example")


def test_an_allowed_origin_that_is_not_an_origin_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="foxglove.allowed_origins: 'app.foxglove.dev' is not a web origin"):
        AppConfig.from_dict({"foxglove": {"allowed_origins": ["app.foxglove.dev"]}})
    with pytest.raises(ValueError, match="is not a web origin"):
        AppConfig.from_dict({"foxglove": {"allowed_origins": ["https://app.foxglove.dev/studio"]}})
