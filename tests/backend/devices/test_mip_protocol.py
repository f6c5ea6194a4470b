"""MIP packets: checksum, field codecs and the stream parser, against hand-built bytes."""

from __future__ import annotations

import math
import struct

import pytest

from ucat_console.backend.devices import mip


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# ---------------------------------------------------------------- checksum and packets


def test_fletcher_matches_spec_test_vector() -> None:
    # devices.md: 75 65 0C 02 02 06 F0 F7 (get IMU base rate)
    assert mip.fletcher16(h("75 65 0C 02 02 06")) == h("F0 F7")
    assert mip.get_imu_base_rate() == h("75 65 0C 02 02 06 F0 F7")


def test_fletcher_by_hand_on_ping_ack() -> None:
    # a = 117+101+1+4+4+241+1+0 = 469 -> 0xD5; b = sum of running a = 2410 -> 0x6A
    assert mip.fletcher16(h("75 65 01 04 04 F1 01 00")) == h("D5 6A")


@pytest.mark.parametrize(
    "built, expected",
    [
        (mip.ping(), "75 65 01 02 02 01 E0 C6"),
        (mip.set_idle(), "75 65 01 02 02 02 E1 C7"),
        (mip.resume(), "75 65 01 02 02 06 E5 CB"),
    ],
)
def test_base_commands_are_the_documented_bytes(built: bytes, expected: str) -> None:
    assert built == h(expected)


def test_message_format_command_layout() -> None:
    raw = mip.imu_message_format([0x04, 0x05, 0x0A], 10)
    body = h("75 65 0C 0D 0D 08 01 03 04 00 0A 05 00 0A 0A 00 0A")
    assert raw == body + mip.fletcher16(body)


def test_enable_stream_command_layout() -> None:
    body = h("75 65 0C 05 05 11 01 01 01")
    assert mip.enable_stream(True) == body + mip.fletcher16(body)


def test_parse_packet_rejects_what_is_wrong() -> None:
    good = mip.ping()
    assert mip.parse_packet(good) == mip.Packet(0x01, (mip.Field(0x01, b""),))
    with pytest.raises(mip.MipError, match="checksum"):
        mip.parse_packet(good[:-1] + bytes([good[-1] ^ 1]))
    with pytest.raises(mip.MipError, match="75 65"):
        mip.parse_packet(b"\x75\x66" + good[2:])
    with pytest.raises(mip.MipError, match="length"):
        mip.parse_packet(good[:-3] + good[-2:])
    bad_field = h("75 65 01 02 05 01")  # field claims 5 bytes, payload has 2
    with pytest.raises(mip.MipError, match="field"):
        mip.parse_packet(bad_field + mip.fletcher16(bad_field))


# ---------------------------------------------------------------- field round trips


def test_accel_field_bytes_by_hand() -> None:
    # (0, 0, -1) g: 0.0 is 00000000, -1.0 is BF800000 in big-endian IEEE-754
    assert mip.accel_field((0.0, 0.0, -1.0)).encode() == h("0E 04 00000000 00000000 BF800000")


@pytest.mark.parametrize(
    "make, decode, values",
    [
        (mip.accel_field, mip.decode_vector3, (0.25, -0.5, -1.0)),
        (mip.gyro_field, mip.decode_vector3, (0.125, 1.5, -3.0)),
        (mip.euler_field, mip.decode_vector3, (0.5, -0.25, 3.0)),
        (mip.quaternion_field, mip.decode_quaternion, (0.5, 0.5, -0.5, 0.5)),
    ],
)
def test_float_fields_round_trip_through_a_packet(make, decode, values) -> None:
    field = make(values)
    packet = mip.parse_packet(mip.build_packet(mip.SENSOR_SET, [field]))
    assert decode(packet.fields[0]) == values  # all values exactly representable in float32


def test_sensor_data_round_trip_and_field_descriptors() -> None:
    raw = mip.encode_sensor_data(
        accel=(0.0, 0.0, -1.0), gyro=(0.0, 0.0, 0.5), quaternion=(1.0, 0.0, 0.0, 0.0), euler=(0.0, 0.0, 0.5)
    )
    packet = mip.parse_packet(raw)
    assert [f.descriptor for f in packet.fields] == [0x04, 0x05, 0x0A, 0x0C]
    assert raw[3] == 14 + 14 + 18 + 14  # payload length: three vectors and a quaternion
    data = mip.decode_sensor_data(packet)
    assert data.accel == (0.0, 0.0, -1.0)
    assert data.gyro == (0.0, 0.0, 0.5)
    assert data.quaternion == (1.0, 0.0, 0.0, 0.0)
    assert data.euler == (0.0, 0.0, 0.5)
    assert data.finite()


def test_gps_time_field() -> None:
    field = mip.gps_time_field(345600.5, 2300, 6)
    assert field.encode()[:2] == h("0E 12")
    assert mip.decode_gps_time(field) == (345600.5, 2300, 6)


def test_wrong_field_size_is_an_error() -> None:
    packet = mip.Packet(mip.SENSOR_SET, (mip.Field(mip.FIELD_ACCEL, b"\x00" * 8),))
    with pytest.raises(mip.MipError, match="expected 12"):
        mip.decode_sensor_data(packet)


def test_non_finite_values_are_flagged() -> None:
    packet = mip.parse_packet(mip.encode_sensor_data(accel=(math.nan, 0.0, 0.0), gyro=(0.0, 0.0, 0.0)))
    assert not mip.decode_sensor_data(packet).finite()


@pytest.mark.parametrize("code, ok, name", [(0, True, "ok"), (3, False, "invalid parameter"), (1, False, "unknown command")])
def test_ack_nack_round_trip(code: int, ok: bool, name: str) -> None:
    raw = mip.reply(mip.SET_3DM, mip.CMD_IMU_MESSAGE_FORMAT, code)
    assert raw[4:8] == bytes((0x04, 0xF1, 0x08, code))  # [len, 0xF1, echoed command, code]
    ack = mip.decode_ack(mip.parse_packet(raw).fields[0])
    assert ack == mip.Ack(0x08, code)
    assert ack.ok is ok and ack.name == name


def test_message_format_decoding() -> None:
    data = bytes((1, 2)) + struct.pack(">BHBH", 0x04, 20, 0x05, 20)
    assert mip.decode_imu_message_format(data) == (1, [(0x04, 20), (0x05, 20)])
    with pytest.raises(mip.MipError):
        mip.decode_imu_message_format(bytes((1, 3)) + struct.pack(">BH", 0x04, 20))


# ---------------------------------------------------------------- stream parser


def _packets(items):
    return [i for i in items if isinstance(i, mip.Packet)]


def _issues(items, kind):
    return [i for i in items if isinstance(i, mip.ParseIssue) and i.kind == kind]


def test_parser_resynchronises_after_garbage() -> None:
    p1 = mip.ping()
    p2 = mip.encode_sensor_data(accel=(0.0, 0.0, -1.0), gyro=(0.0, 0.0, 0.0))
    garbage = b"\x00\x01\x75\x02\x65"  # includes a lone sync byte
    items = mip.MipStreamParser().feed(garbage + p1 + garbage + p2)
    assert [p.encode() for p in _packets(items)] == [p1, p2]
    assert sum(i.nbytes for i in _issues(items, "garbage")) == 2 * len(garbage)


def test_parser_joins_split_packets_byte_by_byte() -> None:
    p1 = mip.ping()
    p2 = mip.encode_sensor_data(accel=(1.0, 2.0, 3.0), gyro=(0.0, 0.0, 0.0))
    parser = mip.MipStreamParser()
    items = []
    for b in p1 + p2:
        items += parser.feed(bytes([b]))
    assert [p.encode() for p in _packets(items)] == [p1, p2]
    assert not [i for i in items if isinstance(i, mip.ParseIssue)]


def test_parser_rejects_bad_checksum_and_keeps_the_next_packet() -> None:
    good = mip.encode_sensor_data(accel=(0.0, 0.0, -1.0), gyro=(0.0, 0.0, 0.0))
    bad = bytearray(good)
    bad[10] ^= 0xFF  # corrupt a data byte: the checksum no longer matches
    items = mip.MipStreamParser().feed(bytes(bad) + good)
    assert [p.encode() for p in _packets(items)] == [good]
    assert len(_issues(items, "checksum")) == 1
    assert not _issues(items, "garbage")  # the bad packet's bytes are not also counted as garbage


def test_parser_finds_a_packet_hidden_behind_a_false_sync() -> None:
    good = mip.ping()
    false_start = b"\x75\x65\x80\x0A"  # looks like a header announcing 10 payload bytes
    items = mip.MipStreamParser().feed(false_start + good + b"\x00" * 8)
    assert [p.encode() for p in _packets(items)] == [good]
    assert len(_issues(items, "checksum")) == 1


def test_parser_reports_malformed_fields_with_good_checksum() -> None:
    body = h("75 65 80 03 07 04 00")
    items = mip.MipStreamParser().feed(body + mip.fletcher16(body) + mip.ping())
    assert len(_issues(items, "malformed")) == 1
    assert [p.encode() for p in _packets(items)] == [mip.ping()]
