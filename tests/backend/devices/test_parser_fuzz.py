"""Random bytes into every stream parser: nothing escapes, good messages still come through."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from ucat_console.backend.devices import mip
from ucat_console.backend.devices.dvl import DvlLineParser, LineIssue
from ucat_console.backend.devices.lines import LineSplitter
from ucat_console.backend.devices.pressure import AdcIssue, AdcLineParser

chunks = st.lists(st.binary(max_size=300), max_size=20)


@settings(max_examples=150, deadline=None)
@given(chunks)
def test_mip_parser_survives_random_bytes(parts: list[bytes]) -> None:
    parser = mip.MipStreamParser()
    for part in parts:
        for item in parser.feed(part):
            assert isinstance(item, (mip.Packet, mip.ParseIssue))
            if isinstance(item, mip.Packet):  # anything accepted re-encodes to valid bytes
                assert mip.parse_packet(item.encode()) == item


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200), st.binary(max_size=200), st.integers(min_value=1, max_value=64))
def test_mip_parser_recovers_a_packet_after_random_bytes(before: bytes, after: bytes, chunk: int) -> None:
    good = mip.encode_sensor_data(accel=(0.0, 0.0, -1.0), gyro=(0.5, 0.0, 0.0))
    stream = before + good + good + after
    parser = mip.MipStreamParser()
    items = []
    for i in range(0, len(stream), chunk):
        items += parser.feed(stream[i : i + chunk])
    packets = [p.encode() for p in items if isinstance(p, mip.Packet)]
    # random prefix may swallow at most the first copy (a false header spanning it);
    # the parser resynchronises byte by byte, so the second copy always survives
    assert packets.count(good) >= 1


@settings(max_examples=150, deadline=None)
@given(chunks)
def test_dvl_line_parser_survives_random_bytes(parts: list[bytes]) -> None:
    parser = DvlLineParser(max_line_bytes=512)
    for part in parts:
        for item in parser.feed(part):
            assert isinstance(item, (dict, LineIssue))


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200).filter(lambda b: b"\n" not in b), st.integers(min_value=1, max_value=50))
def test_dvl_line_parser_gets_the_next_line_after_garbage(garbage: bytes, chunk: int) -> None:
    msg = {"type": "velocity", "vx": 0.5}
    stream = garbage + b"\r\n" + json.dumps(msg).encode() + b"\n"
    parser = DvlLineParser()
    items = []
    for i in range(0, len(stream), chunk):
        items += parser.feed(stream[i : i + chunk])
    assert items[-1] == msg


@settings(max_examples=150, deadline=None)
@given(chunks)
def test_pressure_line_parser_survives_random_bytes(parts: list[bytes]) -> None:
    parser = AdcLineParser()
    for part in parts:
        for item in parser.feed(part):
            assert isinstance(item, (float, AdcIssue))
            if isinstance(item, float):
                assert item == item  # never NaN


@settings(max_examples=100, deadline=None)
@given(st.lists(st.binary(max_size=40).filter(lambda b: b"\n" not in b and b"\r" not in b), max_size=10),
       st.integers(min_value=1, max_value=17))
def test_line_splitter_returns_the_lines_in_any_chunking(lines: list[bytes], chunk: int) -> None:
    stream = b"".join(line + (b"\r\n" if i % 2 else b"\n") for i, line in enumerate(lines))
    splitter = LineSplitter(1000)
    out = []
    for i in range(0, len(stream), chunk):
        out += splitter.feed(stream[i : i + chunk])
    assert out == [line for line in lines if line]
