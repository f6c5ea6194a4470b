"""``ucat-console devices probe {epos,imu,dvl,pressure}``: talk to one device and show it.

The probe connects, configures the device as the supervisor does, prints each decoded
message and fault for ``--duration`` seconds and, with ``--json FILE``, writes one JSON
object per line: ``{"kind": ..., "t": ...}`` plus the device's fields, and
``{"kind": "fault", "reason": <event code>, ...}`` for each fault Event (``"event"`` for
informational ones). With ``--emulate`` the matching emulator runs with a synthetic
source (the EPOS2 node on python-can's in-process ``virtual`` bus, the IMU and the
pressure ADC on a pty, the DVL on 127.0.0.1), so the command works without hardware.
The exit status is 0 when the device delivered data, 1 when it never did (2 for bad
arguments).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import IO, Any, Callable, Protocol, TypeVar

from ucat_console.telemetry.events import Event

Emit = Callable[[dict[str, Any]], None]


class _Emulator(Protocol):
    def start(self) -> Any: ...
    def stop(self) -> None: ...


_E = TypeVar("_E", bound=_Emulator)


def register(subparsers: argparse._SubParsersAction) -> None:
    from ucat_console.backend.devices.dvl import DvlConfig
    from ucat_console.backend.devices.imu import ImuConfig
    from ucat_console.backend.devices.pressure import PressureConfig
    from ucat_console.backend.devices.serial_link import BAUD_RATES

    devices = subparsers.add_parser("devices", help="device tools (probe a device)")
    dsub = devices.add_subparsers(dest="devices_command", required=True, metavar="ACTION")
    probe = dsub.add_parser(
        "probe", help="connect to one device, configure it and print what it sends"
    )
    psub = probe.add_subparsers(dest="device", required=True, metavar="DEVICE")

    def common(p: argparse.ArgumentParser, emulate: bool = True) -> None:
        p.add_argument("--duration", type=float, default=3.0, metavar="S",
                       help="seconds to listen (default 3)")
        p.add_argument("--json", type=Path, default=None, metavar="FILE",
                       help="write one JSON object per message/fault to FILE ('-': stdout)")
        p.add_argument("--quiet", action="store_true", help="do not print each message")
        if emulate:
            p.add_argument("--emulate", action="store_true",
                           help="probe a local emulator with a synthetic source instead of hardware")
        p.set_defaults(func=run_probe)

    def serial_port(p: argparse.ArgumentParser, defaults: ImuConfig | PressureConfig) -> None:
        p.add_argument("--port", default=defaults.port, help=f"serial port (default {defaults.port})")
        p.add_argument("--baud", type=int, default=defaults.baud, choices=BAUD_RATES, metavar="BAUD",
                       help=f"line rate (default {defaults.baud})")
        common(p)

    epos = psub.add_parser("epos", help="Maxon EPOS2 over CANopen")
    epos.add_argument("--interface", default="socketcan", help="python-can interface (default socketcan)")
    epos.add_argument("--channel", default="can0", help="CAN channel (default can0)")
    epos.add_argument("--node", type=int, default=1, help="CANopen node id (default 1)")
    epos.add_argument("--bitrate", type=int, default=None, help="CAN bitrate (interface default if omitted)")
    common(epos)

    serial_port(psub.add_parser("imu", help="Microstrain 3DM-CX5 (MIP over serial)"), ImuConfig())

    dvl_defaults = DvlConfig()
    dvl = psub.add_parser("dvl", help="Water Linked DVL A50 (JSON over TCP)")
    dvl.add_argument("--host", default=dvl_defaults.host, help=f"DVL address (default {dvl_defaults.host})")
    dvl.add_argument("--port", type=int, default=dvl_defaults.port,
                     help=f"TCP port (default {dvl_defaults.port})")
    common(dvl)

    serial_port(psub.add_parser("pressure", help="Gems 3101P through the serial ADC"), PressureConfig())


# ---------------------------------------------------------------- output


def _clean(value: Any) -> Any:
    """JSON-safe: NaN/inf become null (missing data), tuples become lists."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    return value


class _Output:
    """Thread-safe sink for records: printed lines and JSON lines."""

    def __init__(self, json_file: IO[str] | None, quiet: bool) -> None:
        self._json = json_file
        self._quiet = quiet
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}

    def __call__(self, record: dict[str, Any]) -> None:
        record = _clean(record)
        with self._lock:
            kind = str(record.get("kind"))
            self.counts[kind] = self.counts.get(kind, 0) + 1
            if self._json is not None:
                self._json.write(json.dumps(record, allow_nan=False) + "\n")
                self._json.flush()
            if not self._quiet:
                fields = " ".join(f"{k}={_fmt(v)}" for k, v in record.items() if k not in ("kind", "t"))
                t = record.get("t")
                stamp = f"{t:10.3f}" if isinstance(t, (int, float)) else " " * 10
                print(f"{stamp} {kind:<13} {fields}", flush=True)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ",".join(_fmt(x) for x in v) + "]"
    return str(v)


def event_record(event: Event) -> dict[str, Any]:
    fault = event.level in ("warning", "error", "fatal")
    return {
        "kind": "fault" if fault else "event",
        "t": event.t,
        "source": event.source,
        "reason": event.code,
        "message": event.message,
        "level": event.level,
        "data": event.data,
    }


def _event_sink(emit: Emit) -> Callable[[Event], None]:
    return lambda event: emit(event_record(event))


# ---------------------------------------------------------------- probes


def run_probe(args: argparse.Namespace) -> int:
    if not args.duration >= 0.0 or not math.isfinite(args.duration):
        raise ValueError(f"--duration: {args.duration!r} must be a non-negative number of seconds")
    with ExitStack() as stack:
        json_file: IO[str] | None = None
        if args.json is not None:
            if str(args.json) == "-":
                json_file = sys.stdout
            else:
                json_file = stack.enter_context(open(args.json, "w", encoding="utf-8"))
        out = _Output(json_file, args.quiet or str(args.json) == "-")
        probe = {"epos": _probe_epos, "imu": _probe_imu, "dvl": _probe_dvl, "pressure": _probe_pressure}
        status = probe[args.device](args, out, stack)
        if not (args.quiet or str(args.json) == "-"):
            summary = ", ".join(f"{n} {k}" for k, n in sorted(out.counts.items())) or "nothing"
            print(f"{args.device}: received {summary}", file=sys.stderr)
        return status


def _probe_epos(args: argparse.Namespace, out: _Output, stack: ExitStack) -> int:
    try:
        from ucat_console.backend.devices.epos2_probe import probe
    except ImportError as e:
        print(f"ucat-console: error: the EPOS2 driver is not available: {e}", file=sys.stderr)
        return 2

    interface = args.interface
    if getattr(args, "emulate", False):
        from ucat_console.backend.devices.epos2_emulator import start_emulated_nodes

        interface = "virtual"  # the emulated node lives on the in-process bus
        nodes = start_emulated_nodes(args.channel, [args.node], interface=interface)
        stack.callback(nodes.close)
    return int(
        probe(
            interface=interface, channel=args.channel, node=args.node,
            bitrate=args.bitrate, duration=args.duration, emit=out,
        )
    )


def _probe_imu(args: argparse.Namespace, out: _Output, stack: ExitStack) -> int:
    from ucat_console.backend.devices.imu import ImuConfig, ImuDriver
    from ucat_console.robot.readings import ImuReading

    port = args.port
    if args.emulate:
        from ucat_console.backend.devices.imu_emulator import ImuEmulator

        port = _started(ImuEmulator(synthetic_imu), stack).port

    def on_reading(r: ImuReading) -> None:
        record: dict[str, Any] = {"kind": "imu", "t": r.t, "accel": list(r.accel), "gyro": list(r.gyro)}
        if r.quaternion is not None:
            record["quaternion"] = list(r.quaternion)
        if r.euler is not None:
            record["euler"] = list(r.euler)
        out(record)

    return _listen(ImuDriver(ImuConfig(port=port, baud=args.baud), on_reading, _event_sink(out)), args, stack)


def _probe_dvl(args: argparse.Namespace, out: _Output, stack: ExitStack) -> int:
    from ucat_console.backend.devices.dvl import DvlClient, DvlConfig
    from ucat_console.robot.readings import DvlPosition, DvlVelocity

    host, port = args.host, args.port
    if args.emulate:
        from ucat_console.backend.devices.dvl_emulator import DvlEmulator

        host, port = _started(DvlEmulator(synthetic_dvl), stack).address

    def on_velocity(v: DvlVelocity) -> None:
        out({"kind": "dvl_velocity", "t": v.t, "vx": v.vx, "vy": v.vy, "vz": v.vz,
             "velocity_valid": v.valid, "altitude": v.altitude, "fom": v.fom})

    def on_position(p: DvlPosition) -> None:
        out({"kind": "dvl_position", "t": p.t, "x": p.x, "y": p.y, "z": p.z,
             "roll": p.roll, "pitch": p.pitch, "yaw": p.yaw, "std": p.std})

    client = DvlClient(DvlConfig(host=host, port=port), on_velocity, on_position, _event_sink(out))
    stack.callback(client.stop)
    client.start()
    deadline = time.monotonic() + args.duration
    if client.wait_connected(max(0.0, args.duration)):
        response = client.get_config()
        if response.success:
            out({"kind": "dvl_config", "t": time.monotonic(), **(response.result or {})})
    time.sleep(max(0.0, deadline - time.monotonic()))
    return 0 if client.messages else 1


def _probe_pressure(args: argparse.Namespace, out: _Output, stack: ExitStack) -> int:
    from ucat_console.backend.devices.pressure import PressureConfig, PressureDriver
    from ucat_console.robot.readings import DepthReading

    port = args.port
    if args.emulate:
        from ucat_console.backend.devices.pressure_emulator import PressureEmulator

        port = _started(PressureEmulator(synthetic_depth), stack).port

    def on_reading(r: DepthReading) -> None:
        out({"kind": "pressure", "t": r.t, "depth_m": r.depth_m, "pressure_pa": r.pressure_pa})

    driver = PressureDriver(PressureConfig(port=port, baud=args.baud), on_reading, _event_sink(out))
    return _listen(driver, args, stack)


def _started(emulator: _E, stack: ExitStack) -> _E:
    """Start an emulator and stop it when the probe ends."""
    emulator.start()
    stack.callback(emulator.stop)
    return emulator


def _listen(driver: Any, args: argparse.Namespace, stack: ExitStack) -> int:
    """Start a serial driver, listen for ``--duration`` seconds: 0 when it delivered readings."""
    stack.callback(driver.stop)
    driver.start()
    time.sleep(args.duration)
    return 0 if driver.readings else 1


# ---------------------------------------------------------------- synthetic sources


def synthetic_imu(t: float) -> Any:
    """Level, at rest, turning at 0.1 rad/s about the vertical."""
    from ucat_console.robot.readings import ImuReading
    from ucat_console.robot.rotations import quaternion_from_euler, quaternion_normalize
    from ucat_console.robot.units import GRAVITY

    yaw = math.remainder(0.1 * t, 2.0 * math.pi)
    return ImuReading(
        t=t, accel=(0.0, 0.0, -GRAVITY), gyro=(0.0, 0.0, 0.1),
        quaternion=quaternion_normalize(quaternion_from_euler(0.0, 0.0, yaw)), euler=(0.0, 0.0, yaw),
    )


def synthetic_dvl(t: float) -> Any:
    """Straight ahead at 0.3 m/s, 2 m above the bottom."""
    from ucat_console.backend.devices.dvl_emulator import DvlTruth

    return DvlTruth(vx=0.3, vy=0.0, vz=0.0, altitude=2.0, x=0.3 * t)


def synthetic_depth(t: float) -> float:
    """1 m deep, bobbing 0.2 m with a 10 s period."""
    return 1.0 + 0.2 * math.sin(2.0 * math.pi * t / 10.0)
