"""Microstrain 3DM-CX5 driver: MIP over a serial port (pyserial), readings to a callback.

Configuration follows the console's start-up sequence: idle, ask the IMU base rate, set
the IMU message format of data set 0x80 (scaled accel 0x04, scaled gyro 0x05 and, when
asked for, quaternion 0x0A or Euler 0x0C) at ``base rate / decimation``, enable the IMU
stream, resume. The IMU-only CX5 NACKs orientation fields; the driver then reports the
NACK and falls back to accel + gyro, and attitude comes from the core's estimator
(:mod:`ucat_console.control.estimation`, run by the closed loop).

A reader thread parses the stream and delivers :class:`ImuReading`. Every fault is an
:class:`Event` with source ``"imu"``: ``checksum``, ``garbage``, ``malformed``,
``invalid_data`` (non-finite values, missing accel or gyro), ``nack``,
``orientation_unavailable``, ``no_reply``, ``base_rate_unknown``, ``silence`` (and
``recovered``), ``port_error``, ``reconnected``; ``configured`` (info) when streaming is
set up. None of them raises out
of the reader thread and none becomes a zero reading. The driver opens a serial port by
path and does not know whether a 3DM-CX5 or the emulator is at the other end.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

from ucat_console.backend.devices import mip
from ucat_console.robot.readings import ImuReading
from ucat_console.robot.units import GRAVITY
from ucat_console.backend.devices.serial_link import BAUD_RATES, SERIAL_ERRORS
from ucat_console.backend.devices.serial_reader import SerialReader
from ucat_console.telemetry.events import EventSink
from ucat_console.typedconf import Config, param

log = logging.getLogger(__name__)

SOURCE = "imu"
_ORIENTATION_DESCRIPTORS = {"quaternion": mip.FIELD_QUATERNION, "euler": mip.FIELD_EULER}


@dataclass(frozen=True)
class ImuConfig(Config):
    """Serial link and streaming set-up of the 3DM-CX5."""

    port: str = param("/dev/ttyACM0", doc="serial device of the IMU")
    baud: int = param(115200, choices=BAUD_RATES, unit="baud", doc="serial line rate")
    rate_hz: float = param(100.0, lo=1.0, hi=1000.0, unit="Hz", doc="data set 0x80 rate")
    orientation: str = param(
        "quaternion", choices=("quaternion", "euler", "none"),
        doc="orientation field to request; a NACK falls back to accel + gyro",
    )
    fallback_base_rate_hz: int = param(
        1000, lo=1, hi=10000, unit="Hz", doc="IMU base rate assumed when the device does not say"
    )
    command_timeout_s: float = param(
        0.5, lo=0.01, hi=10.0, unit="s", doc="wait for an ACK/NACK this long"
    )
    command_retries: int = param(2, lo=0, hi=10, doc="resend an unanswered command this often")
    silence_timeout_s: float = param(
        0.5, lo=0.01, hi=60.0, unit="s", doc="report silence after this long without a packet"
    )
    reopen_interval_s: float = param(
        1.0, lo=0.05, hi=60.0, unit="s", doc="retry opening a failed port this often"
    )
    read_timeout_s: float = param(
        0.02, lo=0.001, hi=1.0, unit="s", doc="serial read timeout of the reader thread"
    )


@dataclass(frozen=True)
class CommandReply:
    """The device's answer to one command: the ACK/NACK and any data fields after it."""

    ack: mip.Ack
    fields: tuple[mip.Field, ...]

    @property
    def ok(self) -> bool:
        return self.ack.ok


class _Waiter:
    def __init__(self, key: tuple[int, int]) -> None:
        self.key = key
        self.done = threading.Event()
        self.reply: CommandReply | None = None


class ImuDriver(SerialReader[ImuReading]):
    """3DM-CX5 over a serial port; ``start()`` opens, configures and streams."""

    config: ImuConfig

    def __init__(
        self,
        config: ImuConfig,
        on_reading: Callable[[ImuReading], None],
        on_event: EventSink,
        clock: Callable[[], float] = time.monotonic,
        device_time: Callable[[], float] | None = None,
    ) -> None:
        super().__init__(config, SOURCE, on_reading, on_event, clock, ("packet", "packets"), device_time)
        self._silence.disarm()  # watched once streaming is configured
        self._parser = mip.MipStreamParser()
        self._command_lock = threading.Lock()  # one command in flight
        self._waiter: _Waiter | None = None
        self._configured = False
        self.streamed_fields: tuple[int, ...] = ()
        self.decimation: int | None = None

    # ------------------------------------------------------------ lifecycle

    def start(self) -> bool:
        """Open the port, start the reader and configure streaming.

        Returns True when the device accepted the configuration. Failures (port missing,
        no reply, NACK) are reported as events; the reader keeps running and reopens the
        port, so a device that appears later is picked up.
        """
        if not super().start():
            return False
        return self.configure()

    @property
    def configured(self) -> bool:
        return self._configured

    @property
    def orientation_streamed(self) -> str | None:
        """``"quaternion"``, ``"euler"`` or None (attitude from the estimator)."""
        for name, d in _ORIENTATION_DESCRIPTORS.items():
            if d in self.streamed_fields:
                return name
        return None

    # ------------------------------------------------------------ serial port

    def _reopened(self) -> None:
        threading.Thread(target=self.configure, name="imu-configure", daemon=True).start()

    def _write(self, data: bytes) -> bool:
        with self._serial_lock:
            ser = self._serial
            if ser is None:
                return False
            try:
                ser.write(data)
                return True
            except SERIAL_ERRORS as e:
                self.events.throttled("port_error", f"write to {self.config.port} failed: {e}", "error")
                return False

    # ------------------------------------------------------------ commands

    def command(self, packet: bytes, descriptor_set: int, command: int) -> CommandReply | None:
        """Send a command and wait for its ACK/NACK; None when the device never answers."""
        key = (descriptor_set, command)
        with self._command_lock:
            for _attempt in range(self.config.command_retries + 1):
                waiter = _Waiter(key)
                self._waiter = waiter
                if not self._write(packet):
                    self._waiter = None
                    return None
                answered = waiter.done.wait(self.config.command_timeout_s)
                self._waiter = None
                if answered and waiter.reply is not None:
                    return waiter.reply
                if self._stop.is_set():
                    return None
        self.events.emit(
            "no_reply",
            f"no reply to command 0x{descriptor_set:02X}/0x{command:02X} after "
            f"{self.config.command_retries + 1} tries",
            "error", descriptor_set=descriptor_set, command=command,
        )
        return None

    def _expect_ack(self, packet: bytes, descriptor_set: int, command: int, what: str) -> CommandReply | None:
        reply = self.command(packet, descriptor_set, command)
        if reply is not None and not reply.ok:
            self.events.emit(
                "nack", f"{what} refused: {reply.ack.name}", "warning",
                descriptor_set=descriptor_set, command=command, nack_code=reply.ack.code,
            )
        return reply

    def configure(self) -> bool:
        """Idle, read the base rate, set the message format, enable the stream, resume."""
        self._configured = False
        self._silence.disarm()
        if self._expect_ack(mip.set_idle(), mip.BASE_SET, mip.CMD_IDLE, "idle") is None:
            return False
        base = self._base_rate()
        decimation = max(1, min(0xFFFF, round(base / self.config.rate_hz)))
        wanted = [mip.FIELD_ACCEL, mip.FIELD_GYRO]
        orientation = _ORIENTATION_DESCRIPTORS.get(self.config.orientation)
        formats = [wanted + [orientation], wanted] if orientation is not None else [wanted]
        accepted: list[int] | None = None
        for fields in formats:
            reply = self._expect_ack(
                mip.imu_message_format(fields, decimation), mip.SET_3DM,
                mip.CMD_IMU_MESSAGE_FORMAT, f"IMU message format {[hex(f) for f in fields]}",
            )
            if reply is None:
                return False
            if reply.ok:
                accepted = fields
                break
        if accepted is None:
            return False
        if orientation is not None and orientation not in accepted:
            self.events.emit(
                "orientation_unavailable",
                "device refused orientation fields; streaming accel + gyro only "
                "(attitude from the console's estimator)",
                "warning",
            )
        for packet, dset, cmd, what in (
            (mip.enable_stream(True), mip.SET_3DM, mip.CMD_ENABLE_STREAM, "enable stream"),
            (mip.resume(), mip.BASE_SET, mip.CMD_RESUME, "resume"),
        ):
            reply = self._expect_ack(packet, dset, cmd, what)
            if reply is None or not reply.ok:
                return False
        self.streamed_fields = tuple(accepted)
        self.decimation = decimation
        self._silence.arm()
        self._configured = True
        self.events.emit(
            "configured",
            f"streaming {base / decimation:g} Hz with fields {[hex(f) for f in accepted]}",
            "info", rate_hz=base / decimation, fields=list(accepted),
        )
        return True

    def _base_rate(self) -> int:
        reply = self.command(mip.get_imu_base_rate(), mip.SET_3DM, mip.CMD_IMU_BASE_RATE)
        if reply is not None and reply.ok:
            for f in reply.fields:
                if f.descriptor == mip.FIELD_IMU_BASE_RATE and len(f.data) == 2:
                    rate = int.from_bytes(f.data, "big")
                    if rate > 0:
                        return rate
        self.events.emit(
            "base_rate_unknown",
            f"IMU base rate not reported; assuming {self.config.fallback_base_rate_hz} Hz",
            "warning",
        )
        return self.config.fallback_base_rate_hz

    # ------------------------------------------------------------ reader

    def _handle(self, data: bytes) -> None:
        items = self._parser.feed(data)
        now = self._clock()
        for item in items:
            if isinstance(item, mip.ParseIssue):
                self._report_issue(item)
                continue
            self._silence.received(now)
            if item.descriptor_set == mip.SENSOR_SET:
                self._handle_data(item, now)
            else:
                self._handle_reply(item)

    def _report_issue(self, issue: mip.ParseIssue) -> None:
        if issue.kind == "checksum":
            self.events.throttled(
                "checksum", f"packet with a bad checksum dropped ({issue.detail})",
                nbytes=issue.nbytes,
            )
        elif issue.kind == "garbage":
            self.events.throttled(
                "garbage", f"{issue.nbytes} bytes outside any packet skipped", nbytes=issue.nbytes
            )
        else:
            self.events.throttled("malformed", f"malformed packet dropped: {issue.detail}")

    def _handle_data(self, packet: mip.Packet, now: float) -> None:
        try:
            data = mip.decode_sensor_data(packet)
        except mip.MipError as e:
            self.events.throttled("invalid_data", f"data packet dropped: {e}")
            return
        if data.accel is None or data.gyro is None:
            self.events.throttled("invalid_data", "data packet without accel or gyro dropped")
            return
        if not data.finite():
            self.events.throttled("invalid_data", "data packet with non-finite values dropped")
            return
        reading = ImuReading(
            t=now, accel=tuple(v * GRAVITY for v in data.accel),  # the sensor's g_n -> m/s^2
            gyro=data.gyro, quaternion=data.quaternion, euler=data.euler
        )
        self._deliver(reading)

    def _handle_reply(self, packet: mip.Packet) -> None:
        ack_at = next((i for i, f in enumerate(packet.fields) if f.descriptor == mip.FIELD_ACK), None)
        if ack_at is None:
            log.debug("imu: reply without ACK field in set 0x%02X", packet.descriptor_set)
            return
        try:
            ack = mip.decode_ack(packet.fields[ack_at])
        except mip.MipError as e:
            self.events.throttled("malformed", f"bad ACK field: {e}")
            return
        waiter = self._waiter
        if waiter is None or waiter.key != (packet.descriptor_set, ack.command):
            log.debug("imu: unexpected reply to 0x%02X/0x%02X", packet.descriptor_set, ack.command)
            return
        waiter.reply = CommandReply(ack, packet.fields[ack_at + 1 :])
        waiter.done.set()
