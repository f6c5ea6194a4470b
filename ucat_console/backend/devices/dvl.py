"""Water Linked DVL A50 client: JSON lines over TCP (port 16171).

The A50 sends one JSON object per line (``\\n`` or ``\\r\\n``): ``velocity`` reports at
2-15 Hz, ``position_local`` (dead reckoning) at about 5 Hz, and ``response`` objects
answering commands ``{"command": ..., "parameters": {...}}``; a response names its
command in ``response_to``.

Decoding rules:

* ``velocity`` -> :class:`DvlVelocity` in the DVL frame. ``velocity_valid: false`` (bottom
  lock lost) is missing data: ``valid=False`` and vx, vy, vz, altitude NaN, never zero.
  A negative altitude (the A50 sends -1 without lock) is NaN.
* ``position_local`` -> :class:`DvlPosition`; the A50 gives roll, pitch and yaw in degrees,
  delivered in rad. A report with ``status`` other than 0 is not delivered (the position
  is not valid) and is reported as ``invalid_data``.
* a line that is not JSON, not an object, or lacks a field is an Event, not a crash.

The client connects, reconnects with exponential backoff after any loss, and reports
``connected``, ``disconnected``, ``reconnected``, ``connect_failed``, ``silence`` (and
``recovered``), ``malformed_json``, ``invalid_data``, ``overlong_line``,
``device_status`` (a velocity report with a non-zero ``status``, e.g. high temperature),
``command_timeout`` and ``command_failed`` as Events with source ``"dvl"``. It does not
know whether the socket reaches an A50 or the emulator.
"""

from __future__ import annotations

import collections
import json
import logging
import math
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Literal

from ucat_console.backend.devices.lines import LineSplitter, Overlong
from ucat_console.robot.readings import DvlPosition, DvlVelocity
from ucat_console.backend.devices.reporting import EventReporter, SilenceWatch
from ucat_console.telemetry.events import EventSink
from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

SOURCE = "dvl"
DEFAULT_PORT = 16171
COMMANDS = ("reset_dead_reckoning", "calibrate_gyro", "get_config", "set_config")


@dataclass(frozen=True)
class DvlConfig(Config):
    """Network endpoint and timing of the DVL client."""

    host: str = param("192.168.194.95", doc="DVL address (the A50's factory fallback address)")
    port: int = param(DEFAULT_PORT, lo=1, hi=65535, doc="TCP port of the JSON protocol")
    connect_timeout_s: float = param(2.0, lo=0.01, hi=60.0, unit="s", doc="TCP connect timeout")
    command_timeout_s: float = param(
        3.0, lo=0.01, hi=60.0, unit="s", doc="wait for a command's response this long"
    )
    silence_timeout_s: float = param(
        1.5, lo=0.05, hi=60.0, unit="s", doc="report silence after this long without a message"
    )
    silence_reconnect_s: float = param(
        5.0, lo=0.0, hi=600.0, unit="s", doc="reconnect after this long without a message (0: never)"
    )
    reconnect_min_s: float = param(0.2, lo=0.01, hi=60.0, unit="s", doc="first reconnect delay")
    reconnect_max_s: float = param(5.0, lo=0.01, hi=600.0, unit="s", doc="longest reconnect delay")
    max_line_bytes: int = param(65536, lo=256, hi=16_777_216, unit="B", doc="longest accepted line")

    def _check(self) -> None:
        if self.reconnect_min_s > self.reconnect_max_s:
            raise ValueError(
                f"reconnect_min_s/reconnect_max_s: need min <= max, got "
                f"{self.reconnect_min_s} > {self.reconnect_max_s}"
            )


class DvlFormatError(ValueError):
    """A DVL message that lacks a field or carries a value of the wrong kind."""


@dataclass(frozen=True)
class DvlResponse:
    """A command's outcome. ``timed_out``: no response arrived; ``success`` is then False."""

    response_to: str
    success: bool
    error_message: str = ""
    result: Any = None
    timed_out: bool = False


@dataclass(frozen=True)
class LineIssue:
    """A line the parser could not turn into a JSON object."""

    kind: Literal["malformed_json", "not_object", "overlong_line"]
    detail: str


# ---------------------------------------------------------------- pure decoding


class DvlLineParser:
    """Incremental: ``feed(bytes)`` returns decoded JSON objects and :class:`LineIssue`."""

    def __init__(self, max_line_bytes: int = 65536) -> None:
        self._lines = LineSplitter(max_line_bytes)

    def reset(self) -> None:
        self._lines.reset()

    def feed(self, data: bytes) -> list[dict[str, Any] | LineIssue]:
        out: list[dict[str, Any] | LineIssue] = []
        for line in self._lines.feed(data):
            if isinstance(line, Overlong):
                out.append(LineIssue("overlong_line", f"line longer than {line.nbytes - 1} bytes dropped"))
                continue
            try:
                obj = json.loads(line.decode("utf-8"))
            except (UnicodeDecodeError, ValueError, RecursionError) as e:
                out.append(LineIssue("malformed_json", f"{e}; line starts {line[:60]!r}"))
                continue
            if not isinstance(obj, dict):
                out.append(LineIssue("not_object", f"JSON {type(obj).__name__}, not an object"))
                continue
            out.append(obj)
        return out


def _number(msg: dict[str, Any], key: str) -> float:
    if key not in msg:
        raise DvlFormatError(f"{msg.get('type', 'message')}: field {key!r} missing")
    v = msg[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DvlFormatError(f"{msg.get('type', 'message')}: field {key!r} is {v!r}, not a number")
    return float(v)


def _finite(msg: dict[str, Any], key: str) -> float:
    v = _number(msg, key)
    if not math.isfinite(v):
        raise DvlFormatError(f"{msg.get('type', 'message')}: field {key!r} is {v!r}, not finite")
    return v


def parse_velocity(msg: dict[str, Any], t: float) -> DvlVelocity:
    """A ``velocity`` report; raises DvlFormatError naming a missing or bad field."""
    if "velocity_valid" not in msg:
        raise DvlFormatError("velocity: field 'velocity_valid' missing")
    valid = msg["velocity_valid"]
    if not isinstance(valid, bool):
        raise DvlFormatError(f"velocity: field 'velocity_valid' is {valid!r}, not true/false")
    fom = _number(msg, "fom")
    altitude = _number(msg, "altitude")
    if not valid:
        nan = math.nan
        return DvlVelocity(t=t, vx=nan, vy=nan, vz=nan, valid=False, altitude=nan, fom=fom)
    vx, vy, vz = (_finite(msg, k) for k in ("vx", "vy", "vz"))
    if not (math.isfinite(altitude) and altitude >= 0.0):
        altitude = math.nan
    return DvlVelocity(t=t, vx=vx, vy=vy, vz=vz, valid=True, altitude=altitude, fom=fom)


def parse_position(msg: dict[str, Any], t: float) -> DvlPosition:
    """A ``position_local`` report (angles converted from degrees to rad)."""
    x, y, z = (_finite(msg, k) for k in ("x", "y", "z"))
    roll, pitch, yaw = (math.radians(_finite(msg, k)) for k in ("roll", "pitch", "yaw"))
    return DvlPosition(t=t, x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw, std=_number(msg, "std"))


def parse_response(msg: dict[str, Any]) -> DvlResponse:
    to = msg.get("response_to")
    if not isinstance(to, str):
        raise DvlFormatError(f"response: field 'response_to' is {to!r}, not a command name")
    success = msg.get("success")
    if not isinstance(success, bool):
        raise DvlFormatError(f"response: field 'success' is {success!r}, not true/false")
    err = msg.get("error_message") or ""
    return DvlResponse(response_to=to, success=success, error_message=str(err), result=msg.get("result"))


def encode_command(command: str, parameters: dict[str, Any] | None = None) -> bytes:
    msg: dict[str, Any] = {"command": command}
    if parameters is not None:
        msg["parameters"] = parameters
    return (json.dumps(msg, separators=(",", ":")) + "\n").encode()


# ---------------------------------------------------------------- client


class _Pending:
    def __init__(self) -> None:
        self.done = threading.Event()
        self.response: DvlResponse | None = None


class DvlClient:
    """Connects to the DVL and delivers velocity and position reports to callbacks."""

    def __init__(
        self,
        config: DvlConfig,
        on_velocity: Callable[[DvlVelocity], None],
        on_position: Callable[[DvlPosition], None],
        on_event: EventSink,
        clock: Callable[[], float] = time.monotonic,
        device_time: Callable[[], float] | None = None,
    ) -> None:
        """``device_time``: the time an in-process DVL (the simulated rig's emulator) has
        run to, on ``clock``, against which its silence is judged (``reporting.SilenceWatch``)."""
        self.config = config
        self._on_velocity = on_velocity
        self._on_position = on_position
        self._clock = clock
        self.events = EventReporter(SOURCE, on_event, clock)
        self._parser = DvlLineParser(config.max_line_bytes)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._send_lock = threading.Lock()
        self._pending_lock = threading.Lock()
        self._pending: dict[str, collections.deque[_Pending]] = {}
        self._connected = threading.Event()
        self._ever_connected = False
        self._silence = SilenceWatch(self.events, clock, config.silence_timeout_s, "message", "messages",
                                     device_time=device_time)
        self.connections = 0
        self.messages = 0

    # ------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start connecting in the background (returns at once)."""
        if self._thread is not None:
            raise RuntimeError("DvlClient already started")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="dvl-client", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._drop_socket()
        if self._thread is not None:
            self._thread.join(timeout=3.0)
            self._thread = None
        self._fail_pending("client stopped")

    def __enter__(self) -> "DvlClient":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def wait_connected(self, timeout: float) -> bool:
        return self._connected.wait(timeout)

    # ------------------------------------------------------------ commands

    def command(
        self, command: str, parameters: dict[str, Any] | None = None, timeout_s: float | None = None
    ) -> DvlResponse:
        """Send a command and wait for the response with the same ``response_to``.

        Never raises for device faults: no connection, a timeout or a refusal come back
        as a response with ``success=False`` (and an Event).
        """
        timeout = self.config.command_timeout_s if timeout_s is None else timeout_s
        pending = _Pending()
        with self._pending_lock:
            self._pending.setdefault(command, collections.deque()).append(pending)
        sent = self._send(encode_command(command, parameters))
        if not sent:
            self._forget(command, pending)
            self.events.emit("command_failed", f"{command}: not connected", "warning", command=command)
            return DvlResponse(command, False, "not connected")
        if not pending.done.wait(timeout):
            self._forget(command, pending)
            self.events.emit(
                "command_timeout", f"{command}: no response within {timeout:g} s", "warning",
                command=command, timeout_s=timeout,
            )
            return DvlResponse(command, False, f"no response within {timeout:g} s", timed_out=True)
        response = pending.response or DvlResponse(command, False, "connection lost")
        if not response.success:
            self.events.emit(
                "command_failed", f"{command}: {response.error_message or 'refused'}", "warning",
                command=command,
            )
        return response

    def reset_dead_reckoning(self) -> DvlResponse:
        return self.command("reset_dead_reckoning")

    def calibrate_gyro(self) -> DvlResponse:
        return self.command("calibrate_gyro")

    def get_config(self) -> DvlResponse:
        return self.command("get_config")

    def set_config(self, **parameters: Any) -> DvlResponse:
        return self.command("set_config", parameters)

    def _forget(self, command: str, pending: _Pending) -> None:
        with self._pending_lock:
            queue = self._pending.get(command)
            if queue is not None and pending in queue:
                queue.remove(pending)

    def _fail_pending(self, why: str) -> None:
        with self._pending_lock:
            queues, self._pending = self._pending, {}
        for command, queue in queues.items():
            for p in queue:
                p.response = DvlResponse(command, False, why)
                p.done.set()

    def _send(self, data: bytes) -> bool:
        with self._send_lock:
            sock = self._sock
            if sock is None:
                return False
            try:
                sock.sendall(data)
                return True
            except OSError as e:
                log.debug("dvl: send failed: %s", e)
                return False

    # ------------------------------------------------------------ connection thread

    def _drop_socket(self) -> None:
        with self._send_lock:
            sock, self._sock = self._sock, None
        self._connected.clear()
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def _run(self) -> None:
        delay = self.config.reconnect_min_s
        outage_reported = False
        while not self._stop.is_set():
            try:
                sock = socket.create_connection(
                    (self.config.host, self.config.port), timeout=self.config.connect_timeout_s
                )
            except OSError as e:
                if not outage_reported:
                    self.events.emit(
                        "connect_failed",
                        f"cannot connect to {self.config.host}:{self.config.port}: {e}; retrying",
                        "error", host=self.config.host, port=self.config.port,
                    )
                    outage_reported = True
                self._stop.wait(delay)
                delay = min(2.0 * delay, self.config.reconnect_max_s)
                continue
            delay = self.config.reconnect_min_s
            outage_reported = False
            sock.settimeout(0.1)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._send_lock:
                self._sock = sock
            self._parser.reset()
            self._silence.reset()
            self.connections += 1
            self._connected.set()
            if self._ever_connected:
                self.events.emit("reconnected", f"reconnected to {self.config.host}:{self.config.port}", "info")
            else:
                self.events.emit("connected", f"connected to {self.config.host}:{self.config.port}", "info")
            self._ever_connected = True
            why = self._read_loop(sock)
            self._drop_socket()
            self._fail_pending(f"connection lost: {why}")
            if self._stop.is_set():
                break
            self.events.emit("disconnected", f"connection lost: {why}", "warning")
            self._stop.wait(delay)

    def _read_loop(self, sock: socket.socket) -> str:
        while not self._stop.is_set():
            self._silence.reading()
            try:
                data = sock.recv(65536)
            except socket.timeout:
                data = None
            except OSError as e:
                return str(e)
            if data == b"":
                return "closed by the DVL"
            if data:
                self._silence.received(self._clock())
                try:
                    self._handle(data)
                except Exception:
                    log.exception("dvl: unexpected error while handling input")
                    self.events.throttled("internal_error", "unexpected error handling input", "error")
            quiet = self._silence.check()
            if self.config.silence_reconnect_s > 0 and quiet > self.config.silence_reconnect_s:
                return f"silent for {quiet:.1f} s"
        return "stopped"

    def _handle(self, data: bytes) -> None:
        now = self._clock()
        for item in self._parser.feed(data):
            if isinstance(item, LineIssue):
                self.events.throttled(
                    "overlong_line" if item.kind == "overlong_line" else "malformed_json",
                    item.detail,
                )
                continue
            self.messages += 1
            self._dispatch(item, now)

    def _dispatch(self, msg: dict[str, Any], now: float) -> None:
        kind = msg.get("type")
        try:
            if kind == "velocity":
                reading = parse_velocity(msg, now)
                status = msg.get("status", 0)
                self.events.condition(
                    "device_status", status not in (0, None), f"velocity report status {status!r}",
                    "warning", status=status,
                )
                self._deliver(self._on_velocity, reading)
            elif kind == "position_local":
                status = msg.get("status", 0)
                if status not in (0, None):
                    self.events.throttled(
                        "invalid_data", f"position_local with status {status!r} dropped", status=status
                    )
                    return
                self._deliver(self._on_position, parse_position(msg, now))
            elif kind == "response" or "response_to" in msg:
                self._resolve(parse_response(msg))
            else:
                log.debug("dvl: message of type %r ignored", kind)
        except DvlFormatError as e:
            self.events.throttled("invalid_data", str(e))

    def _deliver(self, callback: Callable[[Any], None], value: Any) -> None:
        try:
            callback(value)
        except Exception:
            log.exception("dvl: reading callback failed")

    def _resolve(self, response: DvlResponse) -> None:
        with self._pending_lock:
            queue = self._pending.get(response.response_to)
            pending = queue.popleft() if queue else None
        if pending is None:
            log.debug("dvl: response to %r with no command waiting", response.response_to)
            return
        pending.response = response
        pending.done.set()
