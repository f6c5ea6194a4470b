"""A DVL A50 on 127.0.0.1: the same JSON-lines TCP protocol as the device.

Every connected client receives ``velocity`` reports at ``velocity_rate_hz`` (2-15 Hz)
and ``position_local`` reports at ``position_rate_hz`` (about 5 Hz), in the A50's
format (``json_v3.1``, lines ending ``\\r\\n``). Commands are answered with
``{"response_to", "success", "error_message", "result", "format", "type": "response"}``:
``reset_dead_reckoning`` (the current truth position becomes the origin),
``calibrate_gyro``, ``get_config`` and ``set_config`` (known keys only, range-checked).

``source(t)`` (``t``: seconds since :meth:`start`) returns a :class:`DvlTruth` or None
(no report now). Faults: ``silence`` sends nothing and answers nothing; ``corrupt`` sends
broken JSON and bytes that are not UTF-8 in place of reports; ``invalid`` reports
``velocity_valid: false`` (bottom lock lost) with altitude -1; ``implausible`` reports a
valid velocity the A50 never measures, or one the robot does not have
(:meth:`DvlEmulator.set_implausible`, default 5 m/s forward); ``slow`` delays responses
by ``slow_delay_s``.
"""

from __future__ import annotations

import json
import math
import select
import socket
import time
from dataclasses import dataclass
from typing import Any, Callable

from ucat_console.backend.devices.emulator_base import DelayedOutput, EmulatorThread, next_tick
from ucat_console.backend.devices.faults import Fault, FaultSettings, numbers
from ucat_console.backend.devices.lines import LineSplitter, Overlong
from ucat_console.typedconf import Config, param

FORMAT = "json_v3.1"
_BEAM_TILT = math.radians(22.5)  # transducer tilt from the DVL's z axis
_BEAM_AZIMUTHS = tuple(math.radians(a) for a in (45.0, 135.0, 225.0, 315.0))
#: what the ``implausible`` fault reports unless told otherwise: 5 m/s forward
IMPLAUSIBLE_VELOCITY = (5.0, 0.0, 0.0)


@dataclass(frozen=True)
class DvlTruth:
    """What the emulated DVL measures: velocity in its frame, altitude, pose (rad)."""

    vx: float
    vy: float
    vz: float
    altitude: float
    bottom_lock: bool = True
    fom: float = 0.002
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0


@dataclass(frozen=True)
class DvlEmulatorConfig(Config):
    """Endpoint and report rates of the emulated A50."""

    host: str = param("127.0.0.1", choices=("127.0.0.1", "localhost"), doc="listen address (loopback)")
    port: int = param(0, lo=0, hi=65535, doc="listen port (0: any free port)")
    velocity_rate_hz: float = param(8.0, lo=2.0, hi=15.0, unit="Hz", doc="velocity report rate")
    position_rate_hz: float = param(5.0, lo=0.5, hi=20.0, unit="Hz", doc="position_local rate")
    faults: FaultSettings = FaultSettings()


_CONFIG_LIMITS: dict[str, tuple[type, float | None, float | None]] = {
    "speed_of_sound": (float, 1000.0, 2000.0),
    "mounting_rotation_offset": (float, 0.0, 360.0),
    "acoustic_enabled": (bool, None, None),
    "dark_mode_enabled": (bool, None, None),
    "range_mode": (str, None, None),
    "periodic_cycling_enabled": (bool, None, None),
}


class _Client:
    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.lines = LineSplitter(65536)


class DvlEmulator(EmulatorThread):
    """A50 emulator serving any number of clients on 127.0.0.1."""

    _name = "dvl emulator"
    _io_errors = (OSError, ValueError)

    def __init__(
        self,
        source: Callable[[float], DvlTruth | None],
        config: DvlEmulatorConfig = DvlEmulatorConfig(),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(clock, config.faults)
        self.config = config
        self._source = source
        self._server: socket.socket | None = None
        self._clients: list[_Client] = []
        self._delayed: DelayedOutput[tuple[_Client, bytes]] = DelayedOutput()  # held back by 'slow'
        self._next_vel = 0.0
        self._next_pos = 0.0
        self._vel_period = 1.0 / config.velocity_rate_hz
        self._pos_period = 1.0 / config.position_rate_hz
        self._last_velocity_t: float | None = None
        self._origin = (0.0, 0.0, 0.0)
        self._last_truth: DvlTruth | None = None
        self._corrupt_count = 0
        self.port: int = config.port
        self.settings: dict[str, Any] = {
            "speed_of_sound": 1475.0,
            "acoustic_enabled": True,
            "dark_mode_enabled": False,
            "mounting_rotation_offset": 0.0,
            "range_mode": "auto",
            "periodic_cycling_enabled": True,
        }
        self.commands: list[str] = []
        self._implausible = IMPLAUSIBLE_VELOCITY

    def set_implausible(self, velocity: object = None) -> None:
        """The velocity (3 finite numbers, m/s, the DVL's frame) the ``implausible`` fault
        reports with bottom lock; None: 5 m/s forward."""
        self._implausible = IMPLAUSIBLE_VELOCITY if velocity is None else numbers("velocity", velocity, 3)

    # ------------------------------------------------------------ lifecycle

    def _open(self) -> None:
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((self.config.host, self.port))
        srv.listen(8)
        srv.setblocking(False)
        self._server = srv
        self.port = srv.getsockname()[1]

    def _close(self) -> None:
        for c in self._clients:
            _close(c.sock)
        self._clients.clear()
        if self._server is not None:
            _close(self._server)
            self._server = None

    @property
    def address(self) -> tuple[str, int]:
        return (self.config.host, self.port)

    # ------------------------------------------------------------ main loop

    def _begin(self, now: float) -> None:
        self._next_vel = now
        self._next_pos = now
        self._vel_period = 1.0 / self.config.velocity_rate_hz
        self._pos_period = 1.0 / self.config.position_rate_hz

    def _step(self) -> None:
        now = self._clock()
        due = min(self._next_vel, self._next_pos, self._delayed.next_due())
        timeout = min(0.05, max(0.0, due - now))
        socks: list[Any] = [self._server] + [c.sock for c in self._clients]
        readable, _, _ = select.select(socks, [], [], timeout)
        for s in readable:
            if s is self._server:
                self._accept()
            else:
                client = next((c for c in self._clients if c.sock is s), None)
                if client is not None:
                    self._read(client)
        now = self._clock()
        for client, data in self._delayed.pop_due(now):
            self._send(client, data)
        if now >= self._next_vel:
            self._velocity(now)
            self._next_vel = next_tick(self._next_vel, self._vel_period, now)
        if now >= self._next_pos:
            self._position(now)
            self._next_pos = next_tick(self._next_pos, self._pos_period, now)

    def _accept(self) -> None:
        assert self._server is not None
        try:
            sock, _ = self._server.accept()
        except (BlockingIOError, InterruptedError):
            return
        sock.setblocking(True)
        sock.settimeout(1.0)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._clients.append(_Client(sock))

    def _remove(self, client: _Client) -> None:
        if client in self._clients:
            self._clients.remove(client)
        _close(client.sock)

    def _send(self, client: _Client, data: bytes) -> None:
        if client not in self._clients:
            return
        try:
            client.sock.sendall(data)
        except OSError:
            self._remove(client)

    def _broadcast(self, data: bytes) -> None:
        for c in list(self._clients):
            self._send(c, data)

    # ------------------------------------------------------------ reports

    def _truth(self, now: float) -> DvlTruth | None:
        truth = self._source(now - self._t0)
        if truth is not None:
            self._last_truth = truth
        return truth

    def _emit_report(self, msg: dict[str, Any]) -> None:
        if self.faults.active(Fault.SILENCE):
            return
        data = _line(msg)
        if self.faults.active(Fault.CORRUPT):
            self._corrupt_count += 1
            if self._corrupt_count % self.config.faults.corrupt_every == 0:
                half = data[: len(data) // 2]
                data = half + b"\r\n" + b"\xff\xfe{garbage\r\n"
        self._broadcast(data)

    def _velocity(self, now: float) -> None:
        truth = self._truth(now)
        if truth is None or not self.settings["acoustic_enabled"]:
            return
        unix_us = int(time.time() * 1e6)
        since_ms = 0.0 if self._last_velocity_t is None else (now - self._last_velocity_t) * 1e3
        self._last_velocity_t = now
        lock = truth.bottom_lock and not self.faults.active(Fault.INVALID)
        v = (truth.vx, truth.vy, truth.vz) if lock else (0.0, 0.0, 0.0)
        if lock and self.faults.active(Fault.IMPLAUSIBLE):
            v = self._implausible
        fom = truth.fom if lock else 2.707
        altitude = truth.altitude if lock else -1.0
        transducers = []
        for i, az in enumerate(_BEAM_AZIMUTHS):
            b = (
                math.sin(_BEAM_TILT) * math.cos(az),
                math.sin(_BEAM_TILT) * math.sin(az),
                math.cos(_BEAM_TILT),
            )
            transducers.append(
                {
                    "id": i,
                    "velocity": sum(bi * vi for bi, vi in zip(b, v)),
                    "distance": altitude / math.cos(_BEAM_TILT) if lock else -1.0,
                    "rssi": -30.0 if lock else -90.0,
                    "nsd": -90.0,
                    "beam_valid": lock,
                }
            )
        cov = [[fom * fom if r == c else 0.0 for c in range(3)] for r in range(3)]
        self._emit_report(
            {
                "time": since_ms,
                "vx": v[0],
                "vy": v[1],
                "vz": v[2],
                "fom": fom,
                "covariance": cov,
                "altitude": altitude,
                "transducers": transducers,
                "velocity_valid": lock,
                "status": 0,
                "format": FORMAT,
                "type": "velocity",
                "time_of_validity": unix_us - 20000,
                "time_of_transmission": unix_us,
            }
        )

    def _position(self, now: float) -> None:
        truth = self._truth(now)
        if truth is None:
            return
        ox, oy, oz = self._origin
        self._emit_report(
            {
                "ts": time.time(),
                "x": truth.x - ox,
                "y": truth.y - oy,
                "z": truth.z - oz,
                "std": 0.01,
                "roll": math.degrees(truth.roll),
                "pitch": math.degrees(truth.pitch),
                "yaw": math.degrees(truth.yaw),
                "type": "position_local",
                "status": 0,
                "format": FORMAT,
            }
        )

    # ------------------------------------------------------------ commands

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._remove(client)
            return
        for line in client.lines.feed(data):
            if isinstance(line, Overlong):
                continue
            self._command(client, line)

    def _respond(self, client: _Client, to: str, success: bool, error: str = "", result: Any = None) -> None:
        if self.faults.active(Fault.SILENCE):
            return
        data = _line(
            {
                "response_to": to,
                "success": success,
                "error_message": error,
                "result": result,
                "format": FORMAT,
                "type": "response",
            }
        )
        if not self._held_back(self._clock(), (client, data), self._delayed):
            self._send(client, data)

    def _command(self, client: _Client, line: bytes) -> None:
        try:
            msg = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            self._respond(client, "", False, "could not parse command")
            return
        if not isinstance(msg, dict) or not isinstance(msg.get("command"), str):
            self._respond(client, "", False, "missing 'command'")
            return
        name = msg["command"]
        self.commands.append(name)
        if name == "reset_dead_reckoning":
            t = self._last_truth
            self._origin = (t.x, t.y, t.z) if t is not None else (0.0, 0.0, 0.0)
            self._respond(client, name, True)
        elif name == "calibrate_gyro":
            self._respond(client, name, True)
        elif name == "get_config":
            self._respond(client, name, True, result=dict(self.settings))
        elif name == "set_config":
            params = msg.get("parameters")
            error = _check_settings(params)
            if error:
                self._respond(client, name, False, error)
            else:
                assert isinstance(params, dict)
                self.settings.update(params)
                self._respond(client, name, True)
        else:
            self._respond(client, name, False, f"unknown command {name!r}")


def _check_settings(params: Any) -> str:
    if not isinstance(params, dict) or not params:
        return "set_config needs a non-empty 'parameters' object"
    for key, value in params.items():
        if key not in _CONFIG_LIMITS:
            return f"unknown parameter {key!r}"
        kind, lo, hi = _CONFIG_LIMITS[key]
        if kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                return f"{key}: expected a number, got {value!r}"
            if (lo is not None and value < lo) or (hi is not None and value > hi):
                return f"{key}: {value!r} outside [{lo}, {hi}]"
        elif not isinstance(value, kind):
            return f"{key}: expected {kind.__name__}, got {value!r}"
    return ""


def _line(msg: dict[str, Any]) -> bytes:
    return (json.dumps(msg) + "\r\n").encode()


def _close(sock: socket.socket) -> None:
    try:
        sock.close()
    except OSError:
        pass
