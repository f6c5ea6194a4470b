"""MIP, the binary protocol of the Microstrain 3DM-CX5: packets, fields, checksum, parser.

A packet is ``0x75 0x65``, the descriptor set, the payload length, the payload (a run of
fields ``[length incl. the 2-byte header, descriptor, data]``) and a Fletcher-16 checksum
over every byte before it. Numbers are big-endian; floats are IEEE-754 single precision.

Only what the console uses is defined here: the base command set (ping, idle, resume),
the 3DM set (IMU base rate, IMU message format, enable stream), the ACK/NACK reply field
and the sensor data set 0x80 (scaled accel, scaled gyro, quaternion, Euler angles, GPS
timestamp). Both the driver and the emulator build and read packets with these functions.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Iterable, Literal, Sequence

SYNC1 = 0x75
SYNC2 = 0x65
SYNC = bytes((SYNC1, SYNC2))
HEADER_LEN = 4  # sync1, sync2, descriptor set, payload length
CHECKSUM_LEN = 2
MAX_PACKET_LEN = HEADER_LEN + 255 + CHECKSUM_LEN

# descriptor sets
BASE_SET = 0x01
SET_3DM = 0x0C
SENSOR_SET = 0x80

# base command set
CMD_PING = 0x01
CMD_IDLE = 0x02
CMD_RESUME = 0x06

# 3DM command set
CMD_IMU_BASE_RATE = 0x06
CMD_IMU_MESSAGE_FORMAT = 0x08
CMD_ENABLE_STREAM = 0x11

# reply fields
FIELD_ACK = 0xF1
FIELD_IMU_MESSAGE_FORMAT = 0x80
FIELD_IMU_BASE_RATE = 0x83
FIELD_STREAM_ENABLED = 0x85

# sensor data set 0x80 fields
FIELD_ACCEL = 0x04  # scaled accelerometer, 3 floats, g
FIELD_GYRO = 0x05  # scaled gyro, 3 floats, rad/s
FIELD_QUATERNION = 0x0A  # w, x, y, z
FIELD_EULER = 0x0C  # roll, pitch, yaw, rad
FIELD_GPS_TIME = 0x12  # time of week (double, s), week (u16), flags (u16)

ORIENTATION_FIELDS = (FIELD_QUATERNION, FIELD_EULER)

# function selectors of settings commands
FUNCTION_APPLY = 0x01
FUNCTION_READ = 0x02
FUNCTION_SAVE = 0x03
FUNCTION_LOAD = 0x04
FUNCTION_DEFAULT = 0x05

# device selector of the enable-stream command
STREAM_DEVICE_IMU = 0x01

# ACK/NACK codes
ACK_OK = 0x00
NACK_UNKNOWN_COMMAND = 0x01
NACK_INVALID_CHECKSUM = 0x02
NACK_INVALID_PARAM = 0x03
NACK_COMMAND_FAILED = 0x04
NACK_COMMAND_TIMEOUT = 0x05

ACK_NAMES = {
    ACK_OK: "ok",
    NACK_UNKNOWN_COMMAND: "unknown command",
    NACK_INVALID_CHECKSUM: "invalid checksum",
    NACK_INVALID_PARAM: "invalid parameter",
    NACK_COMMAND_FAILED: "command failed",
    NACK_COMMAND_TIMEOUT: "command timeout",
}

_FLOAT3 = struct.Struct(">3f")
_FLOAT4 = struct.Struct(">4f")
_GPS_TIME = struct.Struct(">dHH")


class MipError(ValueError):
    """A packet or field that does not follow the MIP format."""


def fletcher16(data: bytes | bytearray | memoryview) -> bytes:
    """MIP checksum: ``a += byte; b += a`` (both mod 256); returns ``bytes((a, b))``."""
    a = b = 0
    for byte in bytes(data):
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes((a, b))


@dataclass(frozen=True)
class Field:
    """One MIP field: descriptor and data (the length byte is derived)."""

    descriptor: int
    data: bytes = b""

    def __post_init__(self) -> None:
        if not 0 <= self.descriptor <= 0xFF:
            raise MipError(f"field descriptor {self.descriptor!r} is not a byte")
        if len(self.data) > 253:
            raise MipError(f"field 0x{self.descriptor:02X}: {len(self.data)} data bytes, at most 253")

    def encode(self) -> bytes:
        return bytes((len(self.data) + 2, self.descriptor)) + bytes(self.data)


@dataclass(frozen=True)
class Packet:
    """A decoded MIP packet."""

    descriptor_set: int
    fields: tuple[Field, ...]

    def encode(self) -> bytes:
        return build_packet(self.descriptor_set, self.fields)

    def field(self, descriptor: int) -> Field | None:
        """The first field with this descriptor, or None."""
        for f in self.fields:
            if f.descriptor == descriptor:
                return f
        return None


def build_packet(descriptor_set: int, fields: Iterable[Field]) -> bytes:
    """Complete packet bytes (sync, header, fields, checksum)."""
    if not 0 <= descriptor_set <= 0xFF:
        raise MipError(f"descriptor set {descriptor_set!r} is not a byte")
    payload = b"".join(f.encode() for f in fields)
    if len(payload) > 255:
        raise MipError(f"payload of {len(payload)} bytes exceeds 255")
    body = SYNC + bytes((descriptor_set, len(payload))) + payload
    return body + fletcher16(body)


def parse_fields(payload: bytes) -> tuple[Field, ...]:
    """Split a payload into fields; raises MipError when the field lengths do not add up."""
    fields: list[Field] = []
    i = 0
    while i < len(payload):
        if len(payload) - i < 2:
            raise MipError(f"payload ends inside a field header at byte {i}")
        flen = payload[i]
        if flen < 2:
            raise MipError(f"field at byte {i} has length {flen}, less than its 2-byte header")
        if i + flen > len(payload):
            raise MipError(
                f"field at byte {i} (0x{payload[i + 1]:02X}) is {flen} bytes long, "
                f"only {len(payload) - i} remain"
            )
        fields.append(Field(payload[i + 1], bytes(payload[i + 2 : i + flen])))
        i += flen
    return tuple(fields)


def parse_packet(raw: bytes) -> Packet:
    """Decode one complete packet; raises MipError naming what is wrong."""
    raw = bytes(raw)
    if len(raw) < HEADER_LEN + CHECKSUM_LEN:
        raise MipError(f"packet of {len(raw)} bytes is shorter than the 6-byte minimum")
    if raw[:2] != SYNC:
        raise MipError(f"packet starts with {raw[:2].hex(' ')}, not 75 65")
    plen = raw[3]
    if len(raw) != HEADER_LEN + plen + CHECKSUM_LEN:
        raise MipError(
            f"payload length byte says {plen}, packet holds {len(raw) - HEADER_LEN - CHECKSUM_LEN}"
        )
    expected = fletcher16(raw[:-2])
    if raw[-2:] != expected:
        raise MipError(f"checksum {raw[-2:].hex(' ')} != computed {expected.hex(' ')}")
    return Packet(raw[2], parse_fields(raw[HEADER_LEN:-CHECKSUM_LEN]))


# ---------------------------------------------------------------- field codecs


def _floats(values: Sequence[float], n: int, what: str) -> tuple[float, ...]:
    vals = tuple(float(v) for v in values)
    if len(vals) != n:
        raise MipError(f"{what}: expected {n} values, got {len(vals)}")
    return vals


def vector3_field(descriptor: int, xyz: Sequence[float]) -> Field:
    return Field(descriptor, _FLOAT3.pack(*_floats(xyz, 3, f"field 0x{descriptor:02X}")))


def accel_field(xyz_g: Sequence[float]) -> Field:
    return vector3_field(FIELD_ACCEL, xyz_g)


def gyro_field(xyz_rad_s: Sequence[float]) -> Field:
    return vector3_field(FIELD_GYRO, xyz_rad_s)


def euler_field(rpy_rad: Sequence[float]) -> Field:
    return vector3_field(FIELD_EULER, rpy_rad)


def quaternion_field(wxyz: Sequence[float]) -> Field:
    return Field(FIELD_QUATERNION, _FLOAT4.pack(*_floats(wxyz, 4, "quaternion")))


def decode_vector3(field: Field) -> tuple[float, float, float]:
    if len(field.data) != _FLOAT3.size:
        raise MipError(
            f"field 0x{field.descriptor:02X}: {len(field.data)} data bytes, expected {_FLOAT3.size}"
        )
    x, y, z = _FLOAT3.unpack(field.data)
    return (x, y, z)


def decode_quaternion(field: Field) -> tuple[float, float, float, float]:
    if len(field.data) != _FLOAT4.size:
        raise MipError(f"quaternion field: {len(field.data)} data bytes, expected {_FLOAT4.size}")
    w, x, y, z = _FLOAT4.unpack(field.data)
    return (w, x, y, z)


def gps_time_field(tow_s: float, week: int, flags: int = 0) -> Field:
    return Field(FIELD_GPS_TIME, _GPS_TIME.pack(float(tow_s), int(week), int(flags)))


def decode_gps_time(field: Field) -> tuple[float, int, int]:
    if len(field.data) != _GPS_TIME.size:
        raise MipError(f"GPS time field: {len(field.data)} data bytes, expected {_GPS_TIME.size}")
    tow, week, flags = _GPS_TIME.unpack(field.data)
    return (tow, week, flags)


@dataclass(frozen=True)
class Ack:
    """The ACK/NACK reply field: the echoed command descriptor and the code (0 = ACK)."""

    command: int
    code: int

    @property
    def ok(self) -> bool:
        return self.code == ACK_OK

    @property
    def name(self) -> str:
        return ACK_NAMES.get(self.code, f"code 0x{self.code:02X}")


def ack_field(command: int, code: int = ACK_OK) -> Field:
    return Field(FIELD_ACK, bytes((command & 0xFF, code & 0xFF)))


def decode_ack(field: Field) -> Ack:
    if field.descriptor != FIELD_ACK:
        raise MipError(f"field 0x{field.descriptor:02X} is not an ACK/NACK field (0xF1)")
    if len(field.data) != 2:
        raise MipError(f"ACK/NACK field: {len(field.data)} data bytes, expected 2")
    return Ack(field.data[0], field.data[1])


# ---------------------------------------------------------------- commands


def ping() -> bytes:
    return build_packet(BASE_SET, [Field(CMD_PING)])


def set_idle() -> bytes:
    return build_packet(BASE_SET, [Field(CMD_IDLE)])


def resume() -> bytes:
    return build_packet(BASE_SET, [Field(CMD_RESUME)])


def get_imu_base_rate() -> bytes:
    return build_packet(SET_3DM, [Field(CMD_IMU_BASE_RATE)])


def imu_message_format(descriptors: Sequence[int], decimation: int) -> bytes:
    """Apply a new format for data set 0x80: each field at ``base rate / decimation``."""
    if not 1 <= decimation <= 0xFFFF:
        raise MipError(f"decimation {decimation!r} must be in [1, 65535]")
    data = bytes((FUNCTION_APPLY, len(descriptors)))
    for d in descriptors:
        data += struct.pack(">BH", d, decimation)
    return build_packet(SET_3DM, [Field(CMD_IMU_MESSAGE_FORMAT, data)])


def decode_imu_message_format(data: bytes) -> tuple[int, list[tuple[int, int]]]:
    """(function, [(descriptor, decimation), ...]) from the command's data."""
    if len(data) < 1:
        raise MipError("IMU message format: no function selector")
    function = data[0]
    if function != FUNCTION_APPLY:
        return function, []
    if len(data) < 2:
        raise MipError("IMU message format: no descriptor count")
    count = data[1]
    if len(data) != 2 + 3 * count:
        raise MipError(
            f"IMU message format: {count} descriptors need {2 + 3 * count} bytes, got {len(data)}"
        )
    entries = [struct.unpack_from(">BH", data, 2 + 3 * i) for i in range(count)]
    return function, [(int(d), int(r)) for d, r in entries]


def enable_stream(enable: bool, device: int = STREAM_DEVICE_IMU) -> bytes:
    data = bytes((FUNCTION_APPLY, device, 1 if enable else 0))
    return build_packet(SET_3DM, [Field(CMD_ENABLE_STREAM, data)])


def reply(descriptor_set: int, command: int, code: int = ACK_OK, extra: Iterable[Field] = ()) -> bytes:
    """A device reply: the ACK/NACK field first, then any data fields."""
    return build_packet(descriptor_set, [ack_field(command, code), *extra])


# ---------------------------------------------------------------- sensor data set 0x80


@dataclass(frozen=True)
class SensorData:
    """Fields of one data set 0x80 packet (None when the packet lacks the field)."""

    accel: tuple[float, float, float] | None = None
    gyro: tuple[float, float, float] | None = None
    quaternion: tuple[float, float, float, float] | None = None
    euler: tuple[float, float, float] | None = None
    gps_time: tuple[float, int, int] | None = None
    unknown: tuple[int, ...] = ()

    def finite(self) -> bool:
        """True when every float present is finite."""
        for vec in (self.accel, self.gyro, self.quaternion, self.euler):
            if vec is not None and not all(math.isfinite(v) for v in vec):
                return False
        return True


def encode_sensor_data(
    accel: Sequence[float] | None = None,
    gyro: Sequence[float] | None = None,
    quaternion: Sequence[float] | None = None,
    euler: Sequence[float] | None = None,
    order: Sequence[int] = (FIELD_ACCEL, FIELD_GYRO, FIELD_QUATERNION, FIELD_EULER),
) -> bytes:
    """A data set 0x80 packet with the given fields, in ``order``."""
    makers = {
        FIELD_ACCEL: (accel, accel_field),
        FIELD_GYRO: (gyro, gyro_field),
        FIELD_QUATERNION: (quaternion, quaternion_field),
        FIELD_EULER: (euler, euler_field),
    }
    fields = []
    for d in order:
        value, make = makers[d]
        if value is not None:
            fields.append(make(value))
    return build_packet(SENSOR_SET, fields)


def decode_sensor_data(packet: Packet) -> SensorData:
    """Read data set 0x80; raises MipError on a wrong set or a field of the wrong size."""
    if packet.descriptor_set != SENSOR_SET:
        raise MipError(f"descriptor set 0x{packet.descriptor_set:02X} is not sensor data (0x80)")
    values: dict[str, object] = {}
    unknown: list[int] = []
    for f in packet.fields:
        if f.descriptor == FIELD_ACCEL:
            values["accel"] = decode_vector3(f)
        elif f.descriptor == FIELD_GYRO:
            values["gyro"] = decode_vector3(f)
        elif f.descriptor == FIELD_QUATERNION:
            values["quaternion"] = decode_quaternion(f)
        elif f.descriptor == FIELD_EULER:
            values["euler"] = decode_vector3(f)
        elif f.descriptor == FIELD_GPS_TIME:
            values["gps_time"] = decode_gps_time(f)
        else:
            unknown.append(f.descriptor)
    return SensorData(unknown=tuple(unknown), **values)  # type: ignore[arg-type]


# ---------------------------------------------------------------- stream parser


@dataclass(frozen=True)
class ParseIssue:
    """Something the stream parser skipped.

    ``garbage``: bytes outside any packet; ``checksum``: a packet-shaped run whose
    checksum failed (the parser then resynchronises one byte later); ``malformed``: a
    packet with a good checksum whose fields do not add up.
    """

    kind: Literal["garbage", "checksum", "malformed"]
    nbytes: int
    detail: str = ""


class MipStreamParser:
    """Incremental MIP parser: ``feed(bytes)`` returns packets and issues in stream order."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._garbage = 0
        self._quiet = 0  # bytes of a rejected packet: skipped without counting as garbage

    def reset(self) -> None:
        self._buf.clear()
        self._garbage = 0
        self._quiet = 0

    def _skip(self, n: int) -> None:
        if n <= 0:
            return
        del self._buf[:n]
        counted = max(0, n - self._quiet)
        self._quiet = max(0, self._quiet - n)
        self._garbage += counted

    def _flush_garbage(self, out: list[Packet | ParseIssue]) -> None:
        if self._garbage:
            out.append(ParseIssue("garbage", self._garbage))
            self._garbage = 0

    def feed(self, data: bytes) -> list[Packet | ParseIssue]:
        self._buf += data
        out: list[Packet | ParseIssue] = []
        buf = self._buf
        while True:
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf and buf[-1] == SYNC1 else 0
                self._skip(len(buf) - keep)
                break
            self._skip(i)
            if len(buf) < HEADER_LEN:
                break
            total = HEADER_LEN + buf[3] + CHECKSUM_LEN
            if len(buf) < total:
                break
            raw = bytes(buf[:total])
            if fletcher16(raw[:-2]) != raw[-2:]:
                self._flush_garbage(out)
                out.append(
                    ParseIssue("checksum", total, f"set 0x{raw[2]:02X}, {total} bytes")
                )
                del buf[:1]  # resynchronise: look for the next sync after this one
                self._quiet = total - 1
                continue
            self._flush_garbage(out)
            try:
                packet = parse_packet(raw)
            except MipError as e:
                out.append(ParseIssue("malformed", total, str(e)))
            else:
                out.append(packet)
            del buf[:total]
            self._quiet = 0
        self._flush_garbage(out)
        return out
