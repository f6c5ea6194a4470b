# Over 600 lines: the recorder's write path, its parts' rotation and its failure handling share one writer's state and lock.
"""The recorder: one end of the telemetry stream, writing it to MCAP session files.

The recorder subscribes to a :class:`~ucat_console.telemetry.TelemetryStream`. Its
callback only appends to a bounded queue (it never blocks the publisher); a writer thread
encodes the messages and writes them. When the queue is full a message is dropped and
counted, and the writer reports the count as an ``Event`` (source ``"recorder"``, code
``"queue_overflow"``) on the stream and in the log: a drop is never silent.

Crash safety: chunks hold at most ``chunk_size`` bytes (<= 256 KiB) and the open chunk is
also closed and handed to the OS every ``flush_interval`` (0.5 s), so a killed process
loses about the last half second (plus what was queued); ``repair`` re-indexes the rest.

A failed write (a full disk, a removed drive, permissions) stops the recording and is an
alarm: an ``Event`` (source ``"recorder"``, code ``"write_failed"``, level error) on the
stream, which the ``recording`` failsafe and every page show. The part is cut back to the
end of its last complete chunk (each is handed to the OS as it is closed), so it ends on a
whole record and ``repair`` indexes everything up to then (at most ``flush_interval`` or one
chunk before the fault). The recorder then is
``failed`` (not ``recording``) until it is started again (a new session, when there is
space again) or stopped (the failure acknowledged); either publishes an Event with code
``"failure_cleared"``.

A session is split into parts (new file, same session id, next part number) when a part
exceeds ``split_size`` bytes or ``split_duration`` seconds of recorded time. Each part is
self-contained: every channel registered with its schema and every metadata record.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

import mcap
from mcap.writer import CompressionType

import ucat_console
from ucat_console.backend.sessions import codec, files, foxglove, images, writing
from ucat_console.backend.dependencies import require
from ucat_console.backend.sessions.mcap_writer import ChunkedWriter
from ucat_console.backend.sessions.schema import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    json_schema_bytes,
    schema_name,
)
from ucat_console.telemetry.channels import CHANNELS, EVENTS
from ucat_console.telemetry.events import Event, EventSink
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

_COMPRESSION = {
    "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE,
}
#: s, the writer's longest poll period when the queue is empty (half the flush interval
#: when that is shorter): messages may wait this long in memory. Every wake-up costs CPU
#: (about 0.1 ms of a core on a virtual machine), and a message written in a long run of
#: them costs less than one written in a short one (docs/performance.md)
_IDLE_SLEEP = 0.25
_SIZE_CHECK_EVERY = 256  # messages between part-size checks


@dataclass(frozen=True)
class RecorderConfig(Config):
    """Session recording (console.md, Sessions)."""

    chunk_size: int = param(
        64 * 1024, lo=4096, hi=256 * 1024, unit="B",
        doc="largest chunk, uncompressed (a seek decodes about one to three chunks)",
    )
    flush_interval: float = param(
        0.5, lo=0.05, hi=1.0, unit="s", doc="the open chunk is closed and written this often"
    )
    queue_size: int = param(
        200_000, lo=1, hi=10_000_000, doc="messages waiting for the writer thread"
    )
    split_size: int = param(
        2 * 1024**3, lo=64 * 1024, hi=2**40, unit="B", doc="start a new part beyond this size"
    )
    split_duration: float = param(
        3600.0, lo=1.0, hi=7 * 86400.0, unit="s", doc="start a new part after this recorded time"
    )
    compression: str = param("zstd", choices=("zstd", "lz4", "none"), doc="chunk compression")
    foxglove: bool = param(
        True, doc="also write the robot for Foxglove's 3-D panel (transforms, scene) and foxglove.Log"
    )


@dataclass(frozen=True)
class RecorderStats:
    session_id: str
    part: int
    paths: tuple[Path, ...]
    written: int  # messages written (our channels)
    dropped: int  # queue overflows
    rejected: int  # messages that could not be encoded
    queued: int
    error: str  # the writer's failure, "" when none
    kept_until: float  # every message of the open part before this time is in its complete chunks
    image_bytes: int = 0  # the camera's frames written (their compressed bytes, before base64)


class _Part:
    """One open MCAP file."""

    def __init__(self, path: Path, cfg: RecorderConfig) -> None:
        self.path = path
        self.file = open(path, "xb")
        writing.hold(path, self.file)  # until closed: nothing rewrites it meanwhile
        self.writer = ChunkedWriter(
            self.file, chunk_size=cfg.chunk_size, compression=_COMPRESSION[cfg.compression]
        )
        try:
            self.writer.start(
                profile=files.PROFILE,
                library=f"ucat_console {ucat_console.__version__}; mcap {mcap.__version__}",
            )
        except BaseException:
            self.abandon()
            raise
        self.channel_ids: dict[str, int] = {}
        self.sequence: dict[int, int] = collections.defaultdict(int)
        self.log_time = foxglove.LogTimes()
        self.first_ns: int | None = None
        self.dirty = False

    def register(self, foxglove_channels: bool) -> None:
        w = self.writer
        schema_ids: dict[type, int] = {}
        for topic, cls in CHANNELS.items():
            if cls not in schema_ids:
                if images.is_image(cls):  # a Foxglove well-known message (images.py)
                    schema_ids[cls] = w.register_schema(images.TYPES[cls], SCHEMA_ENCODING, images.schema_bytes())
                else:
                    schema_ids[cls] = w.register_schema(
                        schema_name(cls), SCHEMA_ENCODING, json_schema_bytes(cls)
                    )
            self.channel_ids[topic] = w.register_channel(topic, MESSAGE_ENCODING, schema_ids[cls])
        if foxglove_channels:
            names: dict[str, int] = {}
            for topic, name in foxglove.DERIVED:
                if name not in names:  # the transform channels share foxglove.FrameTransform
                    names[name] = w.register_schema(
                        name, SCHEMA_ENCODING, foxglove.official_schema_bytes(name)
                    )
                self.channel_ids[topic] = w.register_channel(topic, MESSAGE_ENCODING, names[name])

    def add(self, topic: str, ns: int, data: bytes) -> None:
        cid = self.channel_ids[topic]
        seq = self.sequence[cid]
        self.sequence[cid] = seq + 1
        self.writer.add_message(cid, log_time=self.log_time(cid, ns), data=data, publish_time=ns,
                                sequence=seq)
        if self.first_ns is None:
            self.first_ns = ns
        self.dirty = True

    def flush(self) -> None:
        if self.dirty:
            self.writer.flush()
            self.dirty = False

    def size(self) -> int:
        return self.file.tell()

    def close(self) -> None:
        try:
            self.writer.finish()
        finally:
            try:
                self.file.close()
            finally:
                writing.let_go(self.path)

    def abandon(self) -> None:
        """After a failed write: close the file without finishing it and cut it back to the
        end of its last complete chunk handed to the OS (``repair`` indexes it up to there).
        The file stays held (its lock on a descriptor of its own) until it is cut back."""
        try:
            keep = os.dup(self.file.fileno())
        except OSError:  # no descriptor left: cut back by name
            keep = -1
        try:
            try:
                self.file.close()  # what is still buffered may not be written: it is cut off below
            except OSError:
                pass
            if keep < 0:
                os.truncate(self.path, self.writer.complete)
            else:
                os.ftruncate(keep, self.writer.complete)
        finally:
            if keep >= 0:
                os.close(keep)
            writing.let_go(self.path)


class Recorder:
    """Records a telemetry stream to session files; ``start()`` and ``stop()`` on demand.

    ``epoch_offset`` (s) is added to the messages' ``t`` to make UNIX time: 0 for a
    wall-clock stream, the run's start time for a headless run in simulated seconds.
    ``event_sink`` also receives the recorder's own events (overflow, write failure).
    ``geometry`` is the robot drawn in Foxglove's 3-D panel (default: the default plant's).
    """

    def __init__(
        self,
        stream: TelemetryStream,
        config: RecorderConfig | None = None,
        directory: str | Path | None = None,
        epoch_offset: float = 0.0,
        event_sink: EventSink | None = None,
        clock: Callable[[], float] = time.monotonic,
        geometry: foxglove.RobotGeometry | None = None,
    ) -> None:
        if not math.isfinite(epoch_offset):
            raise ValueError(f"epoch_offset: {epoch_offset!r} is not finite")
        require("mcap")  # the session files' writer and reader are checked against its range
        self.stream = stream
        self.config = config or RecorderConfig()
        self.directory = files.sessions_dir(directory)
        self.epoch_offset = float(epoch_offset)
        self._event_sink = event_sink
        self._clock = clock
        self._derived = foxglove.Derived(geometry or foxglove.robot_geometry()) \
            if self.config.foxglove else None
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self._stop_listeners: list[Callable[[str, list[Path]], None]] = []
        self._reset()

    def add_stop_listener(self, listener: Callable[[str, list[Path]], None]) -> None:
        """Call ``listener(session_id, parts)`` each time a recording is stopped whole (in the
        thread that stopped it, after the files are closed; not for a recording that failed).
        It should return at once (start a thread for long work); what it raises is logged."""
        self._stop_listeners.append(listener)

    def _reset(self) -> None:
        self._queue: collections.deque = collections.deque()
        self._maxlen = self.config.queue_size
        self._dropped = 0
        self._dropped_reported = 0
        self._drop_lock = threading.Lock()
        self._rejected = 0
        self._rejected_reported = 0
        self._written = 0
        self._image_bytes = 0
        self._stopping = False
        self._wake = threading.Event()  # set by stop(): the writer stops polling at once
        self._error = ""
        self._session_id = ""
        self._part: _Part | None = None
        self._part_no = 0
        self._paths: list[Path] = []
        self._meta: dict[str, dict[str, str]] = {}
        self._last_ns = 0
        self._last_t = 0.0

    # ------------------------------------------------------------------ control
    @property
    def recording(self) -> bool:
        """Recording now (False after a failed write: see ``failed``)."""
        return self._thread is not None and not self._error

    @property
    def failed(self) -> str:
        """Why the recording stopped on its own ("" when it did not): it stays so until
        :meth:`start` or :meth:`stop`."""
        return self._error

    @property
    def session_id(self) -> str:
        return self._session_id

    @property
    def paths(self) -> list[Path]:
        return list(self._paths)

    def stats(self) -> RecorderStats:
        return RecorderStats(
            session_id=self._session_id,
            part=self._part_no,
            paths=tuple(self._paths),
            written=self._written,
            dropped=self._dropped,
            rejected=self._rejected,
            queued=len(self._queue),
            error=self._error,
            kept_until=self._kept_until(),
            image_bytes=self._image_bytes,
        )

    def start(
        self,
        *,
        label: str = "",
        notes: str = "",
        config_toml: str = "",
        weights: Mapping[str, float] | None = None,
        wall_time: float | None = None,
        config_name: str = "",
    ) -> str:
        """Open a new session and start recording; returns the session id.

        ``config_toml`` (the run's configuration) and ``config_name`` (the name it was
        loaded by, "" when none), ``weights`` (the MPC weights in force) and ``notes`` are
        stored as metadata records of every part.
        """
        with self._lock:
            failed = self._error
            if self._thread is not None and not failed:
                raise RuntimeError(f"already recording session {self._session_id}")
            self._end_failed()
            self._reset()
            self.directory.mkdir(parents=True, exist_ok=True)
            wall = time.time() if wall_time is None else wall_time
            base = files.new_session_id(wall, label)
            sid, n = base, 1
            while any(self.directory.glob(f"{sid}_*{files.SUFFIX}")):
                n += 1
                sid = f"{base}-{n}"
            self._session_id = sid
            w = {}
            for k, v in (weights or {}).items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ValueError(f"weights.{k}: expected a finite number, got {v!r}")
                w[str(k)] = repr(float(v))
            for name, text in (("notes", notes), ("config_toml", config_toml), ("config_name", config_name)):
                if not isinstance(text, str):
                    raise ValueError(f"{name}: expected text, got {type(text).__name__}")
            self._meta = {
                files.META_SESSION: {
                    "id": sid,
                    "part": "1",
                    "started_ns": str(int(wall * 1e9)),
                    "epoch_offset": repr(self.epoch_offset),
                    "clock": "wall" if self.epoch_offset == 0.0 else "offset",
                },
                files.META_CONFIG: {"toml": config_toml, **({"name": config_name} if config_name else {})},
                files.META_WEIGHTS: w,
                files.META_VERSION: {
                    "ucat_console": ucat_console.__version__,
                    "mcap": mcap.__version__,
                    "python": sys.version.split()[0],
                },
                files.META_NOTES: {"text": notes},
            }
            if self._derived is not None:
                self._meta[files.META_FRAMES] = dict(foxglove.FRAME_NOTES)
            try:
                self._open_part()  # in this thread: a bad directory fails here, loudly
            except BaseException:
                if self._part is not None:  # opened, then its first records failed
                    self._part.abandon()
                    self._part = None
                raise
            self._unsubscribe = self.stream.subscribe_batches(self._on_messages)
            self._thread = threading.Thread(
                target=self._run, name=f"recorder-{sid}", daemon=True
            )
            self._thread.start()
            log.info("recording session %s to %s", sid, self._paths[-1])
            if failed:
                self._cleared(f"recording again: session {sid} (the last one stopped: {failed})")
            return sid

    def set_notes(self, notes: str) -> None:
        """Replace the operator's notes (written at once as a metadata record)."""
        if not isinstance(notes, str):
            raise ValueError(f"notes: expected text, got {notes!r}")
        if self._thread is None:
            raise RuntimeError("not recording")
        self._queue.append((None, notes))  # commands bypass the bound: they are few

    def stop(self, notes: str | None = None) -> list[Path]:
        """Stop recording, write everything queued, close the file; returns its parts."""
        return self._stop(notes, notify=True)

    def _stop(self, notes: str | None, notify: bool) -> list[Path]:
        with self._lock:
            failed = self._error
            if failed:
                self._end_failed()
                self._error = ""
                self._cleared(f"recording failure acknowledged ({failed}); not recording")
                return list(self._paths)
            if self._thread is None:
                return list(self._paths)
            if notes is not None:
                self._queue.append((None, notes))
            if self._unsubscribe is not None:
                self._unsubscribe()
                self._unsubscribe = None
            self._stopping = True
            self._wake.set()
            self._thread.join()
            self._thread = None
            log.info(
                "session %s stopped: %d messages, %d dropped, %d rejected",
                self._session_id, self._written, self._dropped, self._rejected,
            )
            sid, paths = self._session_id, list(self._paths)
            error = self._error
        if notify and not error:
            for listener in list(self._stop_listeners):
                try:
                    listener(sid, list(paths))
                except Exception:
                    log.exception("a listener of session %s's end failed", sid)
        return paths

    def _end_failed(self) -> None:
        """Let go of a writer thread that stopped on a failure (the lock is held)."""
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join()

    def _cleared(self, message: str) -> None:
        self._report(Event(t=self._last_t, source="recorder", code="failure_cleared", message=message,
                           level="info", data={"session": self._session_id}))

    def discard(self) -> list[Path]:
        """Stop recording and delete the session's files (what a run that never began
        recorded); returns the paths deleted (its stop listeners are not called)."""
        paths = self._stop(None, notify=False)
        for path in paths:
            path.unlink(missing_ok=True)
        if paths:
            log.info("session %s discarded: %s", self._session_id, ", ".join(p.name for p in paths))
        self._paths = []
        return paths

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ publisher side
    def _on_messages(self, items: Any) -> None:
        room = self._maxlen - len(self._queue)
        if len(items) <= room:
            self._queue.extend(items)  # (channel, message) tuples, as the writer takes them
            return
        if room > 0:
            self._queue.extend(items[:room])
        with self._drop_lock:
            self._dropped += len(items) - max(room, 0)

    # ------------------------------------------------------------------ writer thread
    def _open_part(self) -> None:
        self._part_no += 1
        path = self.directory / files.part_name(self._session_id, self._part_no)
        part = _Part(path, self.config)
        self._part = part
        self._paths.append(path)
        self._meta[files.META_SESSION]["part"] = str(self._part_no)
        for name, data in self._meta.items():
            part.writer.add_metadata(name, dict(data))
        part.register(self.config.foxglove)
        part.writer.handed_over()

    def _next_part(self) -> None:
        assert self._part is not None
        self._part.close()
        self._part = None
        self._open_part()
        log.info("session %s: part %d", self._session_id, self._part_no)

    def _run(self) -> None:
        cfg = self.config
        popleft = self._queue.popleft
        split_ns = round(cfg.split_duration * 1e9)
        idle = min(_IDLE_SLEEP, 0.5 * cfg.flush_interval)
        last_flush = self._clock()
        count = 0
        try:
            while True:
                try:
                    channel, msg = popleft()
                except IndexError:
                    last_flush = self._tick(last_flush, force=False)
                    if self._stopping and not self._queue:
                        break
                    self._wake.wait(idle)
                    continue
                if channel is None:
                    self._write_notes(msg)
                    continue
                part = self._part
                assert part is not None
                ns = self._write(part, channel, msg)
                if ns is not None and part.first_ns is not None and ns - part.first_ns >= split_ns:
                    self._next_part()
                count += 1
                if count % _SIZE_CHECK_EVERY == 0:
                    if self._part is not None and self._part.size() >= cfg.split_size:
                        self._next_part()
                    last_flush = self._tick(last_flush, force=False)
            self._tick(last_flush, force=True)
        except Exception as e:  # disk full, permissions ...: an alarm, the recording stops
            self._fail(e)
        finally:
            if self._part is not None:
                try:
                    if self._error:
                        self._part.abandon()
                    else:
                        self._part.close()
                except Exception:
                    log.exception(
                        "session %s: closing %s failed", self._session_id, self._part.path
                    )
                self._part = None

    def _kept_until(self) -> float:
        """The stream time before which every message of the open part is in its complete chunks."""
        part = self._part
        ns = part.writer.kept_ns if part is not None else 0
        return codec.from_ns(ns, self.epoch_offset) if ns else 0.0

    def _fail(self, e: Exception) -> None:
        """The writer failed: stop taking messages, cut the part back to its last complete
        flush, and raise the alarm (an Event on the stream)."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        self._queue.clear()
        part = self._part
        path = part.path if part is not None else self._paths[-1]
        log.error("session %s: writing %s failed", self._session_id, path, exc_info=True)
        kept = self._kept_until()
        cut = ""
        if part is not None:
            try:
                part.abandon()
            except OSError as err:
                cut = f"; cutting it back failed too ({err})"
            self._part = None
        error = f"{type(e).__name__}: {e}"
        self._report(Event(
            t=self._last_t, source="recorder", code="write_failed", level="error",
            message=(f"recording failed: {error}. {path.name} keeps what was recorded up to t={kept:.1f} s"
                     f"{cut}; `ucat-console sessions repair` (or Repair in Review) indexes it, and recording "
                     "starts again with Start recording (or on arming) once there is space"),
            data={"session": self._session_id, "path": str(path), "error": error, "kept_until": kept},
        ))
        self._error = error  # last: whoever sees the failure sees its event already published

    def _write(self, part: _Part, channel: str, msg: Any) -> int | None:
        try:
            t = msg.t
            if images.is_image(type(msg)):
                data = images.encode(msg, codec.to_ns(t, self.epoch_offset))
                self._image_bytes += len(msg.data)
            else:
                data = codec.encode(msg)
        except Exception as e:
            self._rejected += 1
            if self._rejected == 1:
                log.warning("session %s: cannot record a %s message: %s",
                            self._session_id, channel, e)
            return None
        if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t):
            ns = codec.to_ns(t, self.epoch_offset)
            self._last_ns, self._last_t = ns, t
        else:  # no usable time: keep the message at the last time seen
            ns = self._last_ns
        if channel not in part.channel_ids:
            self._rejected += 1
            return None
        derived = self._derived
        if derived is not None and part.first_ns is None:
            for topic, extra in derived.opening(ns):
                part.add(topic, ns, extra)
        part.add(channel, ns, data)
        self._written += 1
        if derived is not None:
            for topic, extra in derived.derive(channel, msg, ns):
                part.add(topic, ns, extra)
        return ns

    def _write_notes(self, notes: str) -> None:
        self._meta[files.META_NOTES] = {"text": notes}
        if self._part is not None:
            self._part.writer.add_metadata(files.META_NOTES, {"text": notes})

    def _tick(self, last_flush: float, force: bool) -> float:
        now = self._clock()
        if not force and now - last_flush < self.config.flush_interval:
            return last_flush
        part = self._part
        if part is not None:
            part.flush()
            if not force and part.size() >= self.config.split_size:
                self._next_part()
        self._report_losses()
        return now

    def _report_losses(self) -> None:
        dropped = self._dropped
        if dropped > self._dropped_reported:
            n = dropped - self._dropped_reported
            self._dropped_reported = dropped
            self._report(Event(
                t=self._last_t, source="recorder", code="queue_overflow",
                message=f"recorder queue full: {n} messages dropped ({dropped} this session)",
                level="error",
                data={"dropped": n, "total": dropped, "queue_size": self._maxlen},
            ))
        rejected = self._rejected
        if rejected > self._rejected_reported:
            n = rejected - self._rejected_reported
            self._rejected_reported = rejected
            self._report(Event(
                t=self._last_t, source="recorder", code="bad_message",
                message=f"{n} messages could not be recorded ({rejected} this session)",
                level="error", data={"rejected": n, "total": rejected},
            ))

    def _report(self, event: Event) -> None:
        log.warning("%s", event.message)
        if self._event_sink is not None:
            try:
                self._event_sink(event)
            except Exception:
                log.exception("recorder event sink failed")
        try:
            self.stream.publish(EVENTS, event)
        except Exception:
            log.exception("publishing the recorder's event failed")
