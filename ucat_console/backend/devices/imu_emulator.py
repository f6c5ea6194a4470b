"""A 3DM-CX5 on a pty: answers MIP commands and streams data set 0x80.

The driver opens :attr:`ImuEmulator.port` (the pty's slave path) as it would open the
real IMU. Commands answered as the device does, each with the ACK/NACK field
``[0x04, 0xF1, command, code]``:

* base set 0x01: ping 0x01, idle 0x02 (streaming pauses), resume 0x06;
* 3DM set 0x0C: IMU base rate 0x06 (reply field 0x83, u16 Hz), IMU message format 0x08
  (apply, read with reply field 0x80, save/load/default), enable stream 0x11;
* anything else: NACK 0x01 (unknown command). Packets with a bad checksum are ignored.

With ``orientation_supported=False`` it behaves as the IMU-only CX5: a message format
naming quaternion 0x0A or Euler 0x0C is NACKed with 0x03 (invalid parameter) and the
previous format stays.

Samples come from ``source(t)`` (``t``: seconds since :meth:`start`), which returns an
object with ``accel`` (m/s^2, sent in standard gravities as the sensor does) and ``gyro``
(and optionally ``quaternion``, ``euler``) such as :class:`ImuReading`, or None for "no sample now". A requested orientation field the truth
does not carry is left out of the packet.

Faults (:mod:`.faults`): ``silence`` sends nothing and answers nothing; ``corrupt`` breaks
the checksum of outgoing packets and puts garbage bytes before them; ``invalid`` streams
NaN accelerations; ``implausible`` streams finite values the sensor never measures in
place of the sample's (:meth:`ImuEmulator.set_implausible`: an acceleration, a rate, a
quaternion; default a yaw rate of 1000 rad/s); ``slow`` delays replies by ``slow_delay_s``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

from ucat_console.backend.devices import mip
from ucat_console.backend.devices.emulator_base import DelayedOutput, EmulatorThread
from ucat_console.backend.devices.faults import Fault, FaultSettings, numbers
from ucat_console.backend.devices.pty_port import PtyPort
from ucat_console.robot.units import GRAVITY
from ucat_console.typedconf import Config, param

_GARBAGE = b"\x00\x75\xff\x13\x65"  # includes a lone sync byte, to exercise resynchronisation
#: what the ``implausible`` fault streams unless told otherwise: a yaw rate of 1000 rad/s
IMPLAUSIBLE_GYRO = (0.0, 0.0, 1000.0)


@dataclass(frozen=True)
class ImuEmulatorConfig(Config):
    """Behaviour of the emulated 3DM-CX5."""

    base_rate_hz: int = param(1000, lo=1, hi=4000, unit="Hz", doc="IMU data base rate")
    orientation_supported: bool = param(
        True, doc="False: the IMU-only CX5, which NACKs quaternion/Euler fields"
    )
    power_up_streaming: bool = param(
        True, doc="stream accel + gyro at power-up (as a device with saved settings does)"
    )
    power_up_decimation: int = param(10, lo=1, hi=65535, doc="decimation of the power-up stream")
    faults: FaultSettings = FaultSettings()


class ImuEmulator(EmulatorThread):
    """3DM-CX5 emulator over a pty pair; use as a context manager or start()/stop()."""

    _name = "imu emulator"

    def __init__(
        self,
        source: Callable[[float], Any],
        config: ImuEmulatorConfig = ImuEmulatorConfig(),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(clock, config.faults)
        self.config = config
        self._source = source
        self._pty = PtyPort()
        self._parser = mip.MipStreamParser()
        self._delayed: DelayedOutput[bytes] = DelayedOutput()  # replies held back by 'slow'
        self._next_sample = 0.0
        self._sent = 0
        # device state
        self.idle = False
        self.stream_enabled = bool(config.power_up_streaming)
        self.message_format: tuple[int, ...] = (
            (mip.FIELD_ACCEL, mip.FIELD_GYRO) if config.power_up_streaming else ()
        )
        self.decimation = config.power_up_decimation
        self.commands: list[tuple[int, int]] = []  # (descriptor set, command) received
        # the fields the 'implausible' fault streams in place of the sample's
        self._implausible: dict[int, tuple[float, ...]] = {mip.FIELD_GYRO: IMPLAUSIBLE_GYRO}

    @property
    def port(self) -> str:
        """Serial port path for the driver."""
        return self._pty.path

    @property
    def rate_hz(self) -> float:
        return self.config.base_rate_hz / self.decimation

    @property
    def streaming(self) -> bool:
        return self.stream_enabled and not self.idle and bool(self.message_format)

    def set_implausible(
        self, accel_g: object = None, gyro: object = None, quaternion: object = None,
    ) -> None:
        """What the ``implausible`` fault streams in place of the sample's values: ``accel_g``
        (3 numbers, g), ``gyro`` (3, rad/s), ``quaternion`` (4, w first), each finite; none
        given: a yaw rate of 1000 rad/s."""
        given = {d: numbers(name, v, n) for d, name, v, n in (
            (mip.FIELD_ACCEL, "accel_g", accel_g, 3), (mip.FIELD_GYRO, "gyro", gyro, 3),
            (mip.FIELD_QUATERNION, "quaternion", quaternion, 4)) if v is not None}
        self._implausible = given or {mip.FIELD_GYRO: IMPLAUSIBLE_GYRO}

    def _close(self) -> None:
        self._pty.close()

    def send_raw(self, data: bytes) -> None:
        """Put arbitrary bytes on the line (line noise, a foreign device)."""
        self._pty.write(data)

    # ------------------------------------------------------------ output

    def _send(self, packet: bytes) -> None:
        if self.faults.active(Fault.SILENCE):
            return
        self._sent += 1
        if self.faults.active(Fault.CORRUPT) and self._sent % self.config.faults.corrupt_every == 0:
            bad = bytearray(packet)
            bad[-1] ^= 0x5A
            packet = _GARBAGE + bytes(bad)
        self._pty.write(packet)

    def _reply(self, packet: bytes) -> None:
        if not self._held_back(self._clock(), packet, self._delayed):
            self._send(packet)

    # ------------------------------------------------------------ main loop

    def _begin(self, now: float) -> None:
        self._next_sample = now

    def _step(self) -> None:
        now = self._clock()
        period = self.decimation / self.config.base_rate_hz
        wait = 0.05
        if self.streaming:
            wait = min(wait, max(0.0, self._next_sample - now))
        wait = min(wait, max(0.0, self._delayed.next_due() - now))
        if self._pty.wait_readable(wait):
            data = self._pty.read()
            if data:
                self._handle_input(data)
        now = self._clock()
        for packet in self._delayed.pop_due(now):
            self._send(packet)
        if self.streaming:
            if now >= self._next_sample:
                self._stream_sample(now)
                self._next_sample += period
                if self._next_sample < now - period:  # fell behind: do not burst
                    self._next_sample = now + period
        else:
            self._next_sample = now

    def _stream_sample(self, now: float) -> None:
        truth = self._source(now - self._t0)
        if truth is None:
            return
        accel = tuple(v / GRAVITY for v in getattr(truth, "accel"))
        gyro = tuple(getattr(truth, "gyro"))
        if self.faults.active(Fault.INVALID):
            accel = (math.nan, math.nan, math.nan)
        values = {
            mip.FIELD_ACCEL: accel,
            mip.FIELD_GYRO: gyro,
            mip.FIELD_QUATERNION: getattr(truth, "quaternion", None),
            mip.FIELD_EULER: getattr(truth, "euler", None),
        }
        if self.faults.active(Fault.IMPLAUSIBLE):
            values.update(self._implausible)
        fields = []
        for d in self.message_format:
            v = values.get(d)
            if v is None:
                continue
            if d == mip.FIELD_QUATERNION:
                fields.append(mip.quaternion_field(v))
            else:
                fields.append(mip.vector3_field(d, v))
        if fields:
            self._send(mip.build_packet(mip.SENSOR_SET, fields))

    # ------------------------------------------------------------ commands

    def _handle_input(self, data: bytes) -> None:
        for item in self._parser.feed(data):
            if isinstance(item, mip.ParseIssue):
                continue  # the device ignores what it cannot read
            if self.faults.active(Fault.SILENCE):
                continue
            for field in item.fields:
                self._command(item.descriptor_set, field)

    def _command(self, dset: int, field: mip.Field) -> None:
        cmd = field.descriptor
        self.commands.append((dset, cmd))
        if dset == mip.BASE_SET:
            if cmd == mip.CMD_PING:
                self._reply(mip.reply(dset, cmd))
            elif cmd == mip.CMD_IDLE:
                self.idle = True
                self._reply(mip.reply(dset, cmd))
            elif cmd == mip.CMD_RESUME:
                self.idle = False
                self._reply(mip.reply(dset, cmd))
            else:
                self._reply(mip.reply(dset, cmd, mip.NACK_UNKNOWN_COMMAND))
        elif dset == mip.SET_3DM:
            if cmd == mip.CMD_IMU_BASE_RATE:
                rate = mip.Field(mip.FIELD_IMU_BASE_RATE, self.config.base_rate_hz.to_bytes(2, "big"))
                self._reply(mip.reply(dset, cmd, extra=[rate]))
            elif cmd == mip.CMD_IMU_MESSAGE_FORMAT:
                self._reply(mip.reply(dset, cmd, *self._message_format(field.data)))
            elif cmd == mip.CMD_ENABLE_STREAM:
                self._reply(mip.reply(dset, cmd, *self._enable_stream(field.data)))
            else:
                self._reply(mip.reply(dset, cmd, mip.NACK_UNKNOWN_COMMAND))
        else:
            self._reply(mip.reply(dset, cmd, mip.NACK_UNKNOWN_COMMAND))

    def _message_format(self, data: bytes) -> tuple[int, list[mip.Field]]:
        try:
            function, entries = mip.decode_imu_message_format(data)
        except mip.MipError:
            return mip.NACK_INVALID_PARAM, []
        if function == mip.FUNCTION_READ:
            body = bytes((len(self.message_format),)) + b"".join(
                bytes((d,)) + self.decimation.to_bytes(2, "big") for d in self.message_format
            )
            return mip.ACK_OK, [mip.Field(mip.FIELD_IMU_MESSAGE_FORMAT, body)]
        if function in (mip.FUNCTION_SAVE, mip.FUNCTION_LOAD, mip.FUNCTION_DEFAULT):
            return mip.ACK_OK, []
        if function != mip.FUNCTION_APPLY:
            return mip.NACK_INVALID_PARAM, []
        supported = {mip.FIELD_ACCEL, mip.FIELD_GYRO, mip.FIELD_GPS_TIME}
        if self.config.orientation_supported:
            supported |= set(mip.ORIENTATION_FIELDS)
        decimations = {r for _, r in entries}
        if any(d not in supported for d, _ in entries) or any(r < 1 for r in decimations):
            return mip.NACK_INVALID_PARAM, []
        if len(decimations) > 1:  # the emulator streams all fields in one packet
            return mip.NACK_INVALID_PARAM, []
        self.message_format = tuple(d for d, _ in entries)
        if decimations:
            self.decimation = decimations.pop()
        return mip.ACK_OK, []

    def _enable_stream(self, data: bytes) -> tuple[int, list[mip.Field]]:
        if len(data) < 2:
            return mip.NACK_INVALID_PARAM, []
        function, device = data[0], data[1]
        if device not in (mip.STREAM_DEVICE_IMU, mip.SENSOR_SET):
            return mip.NACK_INVALID_PARAM, []
        if function == mip.FUNCTION_READ:
            state = bytes((device, 1 if self.stream_enabled else 0))
            return mip.ACK_OK, [mip.Field(mip.FIELD_STREAM_ENABLED, state)]
        if function == mip.FUNCTION_APPLY:
            if len(data) != 3:
                return mip.NACK_INVALID_PARAM, []
            self.stream_enabled = bool(data[2])
            return mip.ACK_OK, []
        if function in (mip.FUNCTION_SAVE, mip.FUNCTION_LOAD, mip.FUNCTION_DEFAULT):
            return mip.ACK_OK, []
        return mip.NACK_INVALID_PARAM, []
