"""``ucat-console devices probe epos``: bring one EPOS2 node up and stream its feedback."""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from typing import Any


from ucat_console.backend.devices.canbus import CanBusError
from ucat_console.telemetry.events import Event

from ucat_console.backend.devices.epos2 import Epos2Config, Epos2Error, Epos2NoAnswer, check_node_id
from ucat_console.backend.devices.fin_drives import FinDrives


def probe(
    interface: str,
    channel: str,
    node: int,
    bitrate: int | None,
    duration: float,
    emit: Callable[[dict], None],
) -> int:
    """Bring one node to operation enabled (profile position) and stream it for ``duration`` s.

    Emits ``{"kind": "feedback", "t", "position_rad", "velocity_rad_s", "state"}`` per
    feedback TPDO and ``{"kind": "fault", "t", "reason"}`` per warning or error event
    (``t`` in seconds since the probe started), then disables the node. Returns 0 on
    success, 1 when the node never answered, 2 when it answered but could not be brought
    to operation enabled (or the bus could not be opened). With ``interface="virtual"``
    start emulated nodes on the same channel first (``epos2_emulator.start_emulated_nodes``).
    """
    check_node_id(node, "node")
    if not duration >= 0.0:
        raise ValueError(f"duration: must be >= 0, got {duration!r}")
    settings: dict[str, Any] = {"interface": interface, "channel": channel}
    if bitrate is not None:
        settings["bitrate"] = bitrate
    config = Epos2Config(**settings)
    items: queue.Queue[tuple[str, Any]] = queue.Queue()
    t0 = time.monotonic()

    def on_event(event: Event) -> None:
        if event.level in ("warning", "error", "fatal"):
            items.put(("fault", event))

    def flush() -> None:
        while True:
            try:
                kind, item = items.get_nowait()
            except queue.Empty:
                return
            _emit_probe_item(kind, item, t0, emit)

    drives = FinDrives(config, lambda fb: items.put(("feedback", fb)), on_event,
                       fins={0: node}, clock=time.monotonic)
    try:
        drives.connect()
    except Epos2NoAnswer as e:
        flush()
        emit({"kind": "fault", "t": time.monotonic() - t0, "reason": f"no_answer: {e}"})
        return 1
    except (Epos2Error, CanBusError) as e:
        flush()
        emit({"kind": "fault", "t": time.monotonic() - t0, "reason": f"start_failed: {e}"})
        return 2
    result = 0
    try:
        if not drives.enable_all():
            result = 2
        deadline = time.monotonic() + duration
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                break
            try:
                kind, item = items.get(timeout=remaining)
            except queue.Empty:
                break
            _emit_probe_item(kind, item, t0, emit)
        drives.disable_all()
    finally:
        drives.close()
        flush()
    return result


def _emit_probe_item(kind: str, item: Any, t0: float, emit: Callable[[dict], None]) -> None:
    if kind == "feedback":
        emit({"kind": "feedback", "t": item.t - t0, "position_rad": item.position_rad,
              "velocity_rad_s": item.velocity_rad_s, "state": item.state})
    else:
        emit({"kind": "fault", "t": item.t - t0, "reason": f"{item.code}: {item.message}"})
