"""Session benchmarks: recorder throughput and seek latency (figures, never test assertions).

- Throughput: messages published as fast as one thread can into a :class:`Recorder`
  whose queue holds them all; the rate counts from the first publish until ``stop()``
  returns with the file closed, and the run reports the drops (the target is >= 20,000
  messages/s with none).
- Seek latency: a synthetic session of ``hours`` at a realistic channel mix
  (:data:`MIX`, about 400 messages/s) is recorded, then ``state_at`` is timed at random
  times (the target is <= 50 ms in a one-hour session).
- Real time (``--realtime`` s): the :data:`MIX` published at its own rates, as the loop
  does, into a recorder of the console's default settings, with ``--camera FPS`` the
  emulated camera's frames too (its default size and quality, 640x360 at JPEG quality 75,
  encoded beforehand: the camera's own thread encodes them in the console); the messages dropped, the bytes written
  a second and the process's CPU. With ``--camera`` the throughput run carries the frames
  as well, at their share of the mix. The target: the camera at up to 30 fps recorded
  with no telemetry dropped.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

from ucat_console.robot.readings import DepthReading, DvlVelocity, ImuReading
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import (
    BodyCommand,
    BodyState,
    FinPlan,
    FinState,
    CameraImage,
    Power,
    Setpoints,
    Status,
)
from ucat_console.telemetry.stream import TelemetryStream


def _body(t: float) -> BodyState:
    return BodyState(t, (0.3 * t, 0.01 * t, 1.0), (1.0, 0.0, 0.0, 0.0), (0.3, 0.0, 0.0),
                     (0.0, 0.0, 0.01), 1.0)


def _fin_state(fin: int) -> Callable[[float], FinState]:
    return lambda t: FinState(t, fin, math.sin(t), math.cos(t), 0.5, 2.0)


def _fin_plan(fin: int) -> Callable[[float], FinPlan]:
    return lambda t: FinPlan(t, fin, "mpc", (-0.5, 0.2), 0.3, 0.1, (0.5, -0.5, 2.0, 2.0),
                             (0.6, -0.6, 2.5, 2.5), (0.7, 2.5, 0.1, 2.5), 1.2, 0.1, 0.2, 0.0,
                             0.05, 0.31, (-0.45, 0.18), 0.004, False)


#: channel -> (rate Hz, message factory of t)
MIX: dict[str, tuple[float, Callable[[float], Any]]] = {
    C.BODY_STATE: (50.0, _body),
    **{C.fin_state(i): (50.0, _fin_state(i)) for i in range(C.N_FINS)},
    **{C.fin_plan(i): (2.0, _fin_plan(i)) for i in range(C.N_FINS)},
    C.POWER: (10.0, lambda t: Power(t, (0.1, 0.1, 0.1, 0.1), 0.4, 0.4, 0.4 * t, 0.3 * t, 1.3)),
    C.SETPOINTS: (1.0, lambda t: Setpoints(t, 0.3, 1.0, 0.0)),
    C.BODY_COMMAND: (10.0, lambda t: BodyCommand(t, -0.5, 0.1, 0.0)),
    C.STATUS: (1.0, lambda t: Status(t, True, "mpc", "pilot", (), 0, "sim")),
    C.IMU: (100.0, lambda t: ImuReading(t, (0.0, 0.0, -1.0), (0.0, 0.0, 0.01))),
    C.DVL: (5.0, lambda t: DvlVelocity(t, 0.3, 0.0, 0.0, True, 2.0, 0.01)),
    C.DEPTH: (20.0, lambda t: DepthReading(t, 1.0, 110_000.0)),
    C.EVENTS: (1 / 60.0, lambda t: Event(t, "operator", "marker", "every minute", "info")),
}


def record_synthetic(directory: Path, duration: float, epoch_offset: float = 1.7e9) -> Path:
    """Record :func:`synthetic_messages` of ``duration`` s into ``directory``; the file."""
    stream = TelemetryStream(validate=False)
    n_total = sum(math.ceil(duration * rate) for rate, _ in MIX.values())
    cfg = RecorderConfig(queue_size=200_000, split_duration=max(1.0, duration + 1.0))
    rec = Recorder(stream, cfg, directory=directory, epoch_offset=epoch_offset)
    rec.start(label="synthetic", notes=f"synthetic {duration:.0f} s session")
    publish = stream.publish
    k = 0
    for start in range(0, int(math.ceil(duration)), 60):
        for _, channel, msg in synthetic_messages_between(start, min(duration, start + 60)):
            publish(channel, msg)
            k += 1
        while rec.stats().queued > cfg.queue_size // 2:  # let the writer catch up: no drops
            time.sleep(0.01)
    paths = rec.stop()
    stats = rec.stats()
    if stats.dropped or len(paths) != 1:
        raise RuntimeError(f"synthetic session: {stats.dropped} dropped, {len(paths)} parts")
    assert k <= n_total
    return paths[0]


def synthetic_messages_between(t0: float, t1: float) -> list[tuple[float, str, Any]]:
    """(t, channel, message) of the :data:`MIX` with ``t0 <= t < t1``, in time order."""
    out = []
    for channel, (rate, make) in MIX.items():
        k0, k1 = math.ceil(t0 * rate), math.ceil(t1 * rate)
        out += [(k / rate, channel, make(k / rate)) for k in range(k0, k1)]
    out.sort(key=lambda x: x[0])
    return out


def camera_frames(fps: float, seconds: float) -> list[tuple[float, str, Any]]:
    """(t, channel, message) of the emulated camera at ``fps`` for ``seconds`` (the default
    camera's size and quality; each picture its own, with its time burned in)."""
    from ucat_console.backend.camera.config import CameraConfig
    from ucat_console.backend.camera.emulated import EmulatedCamera

    cam = EmulatedCamera(CameraConfig(source="emulated", fps=fps))
    return [(k / fps, C.CAMERA_IMAGE, CameraImage(k / fps, "camera", "jpeg", cam.frame(k / fps)))
            for k in range(int(seconds * fps))]


def recorder_throughput(n: int = 100_000, directory: Path | None = None, camera: float | None = None) -> dict[str, Any]:
    """Messages/s through a recorder whose queue holds them all (drops reported); with
    ``camera`` (fps) the camera's frames among them at that rate."""
    per_s = sum(rate for rate, _ in MIX.values()) + (camera or 0.0)
    msgs = synthetic_messages_between(0.0, n / per_s + 1.0)
    if camera:
        msgs = sorted([*msgs, *camera_frames(camera, n / per_s + 1.0)], key=lambda m: m[0])
    msgs = msgs[:n]
    tmp = Path(tempfile.mkdtemp(prefix="bench-sessions-", dir=directory))
    try:
        stream = TelemetryStream()
        rec = Recorder(stream, RecorderConfig(queue_size=max(1, n)), directory=tmp,
                       epoch_offset=1.7e9)
        rec.start(label="throughput")
        t0 = time.perf_counter()
        for _, channel, msg in msgs:
            stream.publish(channel, msg)
        t1 = time.perf_counter()
        paths = rec.stop()
        t2 = time.perf_counter()
        stats = rec.stats()
        size = sum(p.stat().st_size for p in paths)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "messages": len(msgs),
        "written": stats.written,
        "dropped": stats.dropped,
        "rejected": stats.rejected,
        "rate_msgs_per_s": len(msgs) / (t2 - t0),
        "publish_us_per_msg": (t1 - t0) / len(msgs) * 1e6,
        "bytes": size,
        "camera_fps": camera,
        "frames": sum(1 for _, c, _m in msgs if c == C.CAMERA_IMAGE),
        "megabytes_per_s": size / (t2 - t0) / 1e6,
    }


def realtime_recording(seconds: float = 20.0, camera: float | None = None,
                       directory: Path | None = None) -> dict[str, Any]:
    """The :data:`MIX` (and with ``camera``, frames at that fps) published in real time into
    a recorder of the default settings for ``seconds``: drops, bytes and CPU."""
    import os

    msgs = synthetic_messages_between(0.0, seconds)
    if camera:
        msgs = sorted([*msgs, *camera_frames(camera, seconds)], key=lambda m: m[0])
    tmp = Path(tempfile.mkdtemp(prefix="bench-sessions-rt-", dir=directory))
    try:
        stream = TelemetryStream()
        rec = Recorder(stream, RecorderConfig(), directory=tmp, epoch_offset=1.7e9)
        rec.start(label="realtime")
        most_queued = 0
        cpu0, t0 = os.times(), time.perf_counter()
        k = 0
        while k < len(msgs):
            now = time.perf_counter() - t0
            while k < len(msgs) and msgs[k][0] <= now:
                _, channel, msg = msgs[k]
                stream.publish(channel, msg)
                k += 1
            most_queued = max(most_queued, rec.stats().queued)
            time.sleep(0.005)
        paths = rec.stop()
        elapsed = time.perf_counter() - t0
        cpu1 = os.times()
        stats = rec.stats()
        size = sum(p.stat().st_size for p in paths)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    frames = sum(1 for _, c, _m in msgs if c == C.CAMERA_IMAGE)
    return {
        "seconds": seconds,
        "camera_fps": camera,
        "telemetry_messages": len(msgs) - frames,
        "frames": frames,
        "written": stats.written,
        "dropped": stats.dropped,
        "rejected": stats.rejected,
        "most_queued": most_queued,
        "image_bytes": stats.image_bytes,
        "bytes": size,
        "megabytes_per_s": size / elapsed / 1e6,
        "cpu_percent": 100.0 * ((cpu1.user - cpu0.user) + (cpu1.system - cpu0.system)) / elapsed,
    }


def mcap_append(n: int = 50_000, rounds: int = 5) -> dict[str, Any]:
    """us per message of ``add_message`` into an in-memory MCAP file, mcap's ``Writer``
    against the recorder's ``ChunkedWriter`` (mcap's ``Writer`` with its hand-over points: the same bytes, their test), the :data:`MIX`'s
    first ``n`` messages encoded beforehand; each writer ``rounds`` times, in turns, the
    median of each and their ratio."""
    import io

    from mcap.writer import CompressionType, Writer

    from ucat_console.backend.sessions import codec
    from ucat_console.backend.sessions.mcap_writer import ChunkedWriter

    per_s = sum(rate for rate, _ in MIX.values())
    msgs = synthetic_messages_between(0.0, n / per_s + 1.0)[:n]
    order = {channel: k for k, channel in enumerate(MIX)}
    records = [(order[channel], codec.to_ns(t, 1.7e9), codec.encode(msg)) for t, channel, msg in msgs]

    def once(writer_class: type) -> float:
        w = writer_class(io.BytesIO(), chunk_size=RecorderConfig().chunk_size, compression=CompressionType.NONE)
        w.start(profile="ucat", library="bench")
        schema = w.register_schema("s", "jsonschema", b"{}")
        ids = [w.register_channel(channel, "json", schema) for channel in MIX]
        add = w.add_message
        t0 = time.perf_counter()
        for k, ns, data in records:
            add(ids[k], log_time=ns, data=data, publish_time=ns)
        t1 = time.perf_counter()
        w.finish()
        return (t1 - t0) / len(records) * 1e6

    theirs, ours = [], []
    for _ in range(rounds):
        theirs.append(once(Writer))
        ours.append(once(ChunkedWriter))
    mcap_us, chunked_us = statistics.median(theirs), statistics.median(ours)
    return {"messages": len(records), "rounds": rounds, "mcap_writer_us": mcap_us,
            "chunked_writer_us": chunked_us, "ratio": chunked_us / mcap_us}


def seek_latency(
    hours: float = 1.0, seeks: int = 50, seed: int = 0, directory: Path | None = None,
    keep: bool = False,
) -> dict[str, Any]:
    """``state_at`` latency at random times in a synthetic session of ``hours``."""
    tmp = Path(tempfile.mkdtemp(prefix="bench-sessions-", dir=directory))
    try:
        t0 = time.perf_counter()
        path = record_synthetic(tmp, hours * 3600.0)
        t_record = time.perf_counter() - t0
        t0 = time.perf_counter()
        reader = SessionReader(path, tmp)
        t_open = time.perf_counter() - t0
        rng = random.Random(seed)
        lat = []
        with reader:
            for _ in range(seeks):
                t = rng.uniform(reader.start, reader.end)
                t0 = time.perf_counter()
                state = reader.state_at(t)
                lat.append(time.perf_counter() - t0)
                if C.BODY_STATE not in state:
                    raise RuntimeError(f"state_at({t}) has no body state")
            chunks = len(reader._summary.chunk_indexes)
            n = reader.message_count
        size = path.stat().st_size
    finally:
        if not keep:
            shutil.rmtree(tmp, ignore_errors=True)
    lat.sort()
    return {
        "hours": hours,
        "messages": n,
        "bytes": size,
        "chunks": chunks,
        "record_s": t_record,
        "open_s": t_open,
        "seeks": seeks,
        "median_ms": statistics.median(lat) * 1e3,
        "p95_ms": lat[min(len(lat) - 1, int(0.95 * len(lat)))] * 1e3,
        "max_ms": lat[-1] * 1e3,
    }


# ---------------------------------------------------------------------- command line
def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``bench sessions`` to the ``bench`` command's sub-commands."""
    p = kinds.add_parser("sessions", help="recorder throughput, MCAP append, seek latency")
    p.add_argument("--messages", type=int, default=100_000, help="throughput run length")
    p.add_argument("--hours", type=float, default=1.0, help="synthetic session length")
    p.add_argument("--seeks", type=int, default=50, help="state_at calls timed")
    p.add_argument("--realtime", type=float, default=20.0,
                   help="seconds of the live mix recorded in real time (0: none)")
    p.add_argument("--camera", type=float, nargs="?", const=30.0, default=None, metavar="FPS",
                   help="with the emulated camera's frames at FPS (default 30) in the throughput and real-time runs")
    p.add_argument("--dir", type=Path, default=None, help="scratch directory (default: /tmp)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.messages < 1:
        raise ValueError(f"--messages: {args.messages} must be at least 1")
    if not 0.0 < args.hours <= 24.0:
        raise ValueError(f"--hours: {args.hours} must be in (0, 24]")
    if args.seeks < 1:
        raise ValueError(f"--seeks: {args.seeks} must be at least 1")
    if not 0.0 <= args.realtime <= 600.0:
        raise ValueError(f"--realtime: {args.realtime} must be in [0, 600] s")
    if args.camera is not None and not 0.1 <= args.camera <= 30.0:
        raise ValueError(f"--camera: {args.camera} fps must be in [0.1, 30] (camera.fps' range)")
    thr = recorder_throughput(args.messages, args.dir, args.camera)
    with_camera = f", {thr['frames']} camera frames at {args.camera:g} fps among them" if args.camera else ""
    print(f"recorder: {thr['rate_msgs_per_s']:,.0f} messages/s, {thr['megabytes_per_s']:.1f} MB/s "
          f"({thr['messages']} messages{with_camera}, {thr['dropped']} dropped, "
          f"{thr['publish_us_per_msg']:.1f} us per publish)")
    realtime = None
    if args.realtime > 0.0:
        realtime = realtime_recording(args.realtime, args.camera, args.dir)
        cam = (f" and {realtime['frames']} camera frames at {args.camera:g} fps "
               f"({realtime['image_bytes'] / 1e6:.1f} MB of JPEG)") if args.camera else " (no camera)"
        print(f"real time, {realtime['seconds']:g} s: {realtime['telemetry_messages']:,} telemetry messages{cam}; "
              f"{realtime['dropped']} dropped, at most {realtime['most_queued']} queued; "
              f"{realtime['megabytes_per_s']:.2f} MB/s written; process CPU {realtime['cpu_percent']:.0f} % of a core")
    append = mcap_append()
    print(f"MCAP append (in memory, uncompressed chunks, {append['messages']:,} messages, median of "
          f"{append['rounds']}): mcap's Writer {append['mcap_writer_us']:.2f} us, the recorder's "
          f"ChunkedWriter {append['chunked_writer_us']:.2f} us a message ({append['ratio']:.2f} times)")
    seek = seek_latency(args.hours, args.seeks, directory=args.dir)
    print(f"seek: {seek['hours']} h, {seek['messages']:,} messages, {seek['chunks']} chunks, "
          f"{seek['bytes'] / 1e6:.1f} MB; open {seek['open_s'] * 1e3:.0f} ms; state_at median "
          f"{seek['median_ms']:.1f} ms, p95 {seek['p95_ms']:.1f} ms, max {seek['max_ms']:.1f} ms")
    from ucat_console.bench.machine import machine_info, speed_line

    machine = machine_info(None)
    print(speed_line(machine))
    if args.json:
        args.json.write_text(json.dumps({"throughput": thr, "realtime": realtime, "mcap_append": append, "seek": seek,
                                              "machine": machine}, indent=2))
        print(f"wrote {args.json}")
    return 0
