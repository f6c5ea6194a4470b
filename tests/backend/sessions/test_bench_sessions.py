"""``ucat-console bench sessions``' MCAP append part: both writers time the same messages."""

from __future__ import annotations

from ucat_console.bench.sessions import mcap_append


def test_the_mcap_append_part_times_both_writers_over_the_mix() -> None:
    r = mcap_append(n=400, rounds=2)
    assert r["messages"] == 400 and r["rounds"] == 2
    assert r["mcap_writer_us"] > 0 and r["chunked_writer_us"] > 0
    assert r["ratio"] == r["chunked_writer_us"] / r["mcap_writer_us"]
