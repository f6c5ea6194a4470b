"""The telemetry stream: who receives what, in which order, and what it refuses."""

from __future__ import annotations

import logging

import pytest

from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import FinState, Setpoints
from ucat_console.telemetry.stream import TelemetryStream


def _fin(fin: int = 0) -> FinState:
    return FinState(1.0, fin, 0.1, 0.2, 0.3, 0.4)


def test_each_subscriber_receives_its_channels_in_subscription_order():
    stream = TelemetryStream()
    got = []
    stream.subscribe(lambda c, m: got.append(("all", c)))
    stream.subscribe(lambda c, m: got.append(("fins", c)), [ch.fin_state(0), ch.fin_state(1)])
    stream.subscribe(lambda c, m: got.append(("setpoints", c)), [ch.SETPOINTS])
    stream.subscribe(lambda c, m: got.append(("all 2", c)))
    stream.publish(ch.fin_state(1), _fin(1))
    stream.publish(ch.SETPOINTS, Setpoints(1.0, 0.2, 0.5, 0.0))
    stream.publish(ch.fin_state(2), _fin(2))
    assert got == [
        ("all", "fin/1/state"), ("fins", "fin/1/state"), ("all 2", "fin/1/state"),
        ("all", "body/setpoints"), ("setpoints", "body/setpoints"), ("all 2", "body/setpoints"),
        ("all", "fin/2/state"), ("all 2", "fin/2/state"),
    ]


def test_unsubscribing_stops_delivery_and_updates_what_is_wanted():
    stream = TelemetryStream()
    a, b = [], []
    off_a = stream.subscribe(lambda c, m: a.append(m), [ch.fin_state(0)])
    off_b = stream.subscribe(lambda c, m: b.append(m), [ch.fin_state(0), ch.POWER])
    assert stream.wanted == {ch.fin_state(0), ch.POWER}
    off_a()
    stream.publish(ch.fin_state(0), _fin())
    assert a == [] and len(b) == 1
    assert stream.wants(ch.POWER) and not stream.wants(ch.BODY_STATE)
    off_b()
    stream.publish(ch.fin_state(0), _fin())
    assert len(b) == 1 and stream.wanted == frozenset()
    stream.subscribe(lambda c, m: None)
    assert stream.wanted == frozenset(ch.CHANNELS)


def test_a_failing_subscriber_is_logged_and_the_others_still_receive(caplog):
    stream = TelemetryStream()
    got = []

    def broken(c, m):
        raise RuntimeError("boom")

    stream.subscribe(broken)
    stream.subscribe(lambda c, m: got.append(m))
    with caplog.at_level(logging.ERROR):
        stream.publish(ch.fin_state(0), _fin())
        stream.publish(ch.fin_state(0), _fin())
    assert len(got) == 2
    assert sum("failed on fin/0/state" in r.getMessage() for r in caplog.records) == 2


def test_a_message_of_the_wrong_type_or_channel_is_refused_by_a_validating_stream():
    stream = TelemetryStream()
    got = []
    stream.subscribe(lambda c, m: got.append(m))
    with pytest.raises(TypeError, match="channel 'fin/0/state' carries FinState, got Setpoints"):
        stream.publish(ch.fin_state(0), Setpoints(1.0, 0.2, 0.5, 0.0))
    with pytest.raises(ValueError, match="unknown telemetry channel 'fin/9/state'"):
        stream.publish("fin/9/state", _fin())
    with pytest.raises(ValueError, match="unknown telemetry channel 'nope'"):
        stream.subscribe(lambda c, m: None, ["nope"])
    assert got == []


def test_an_unvalidated_stream_hands_an_unknown_channel_to_the_subscribers_of_all():
    stream = TelemetryStream(validate=False)
    every, some = [], []
    stream.subscribe(lambda c, m: every.append(c))
    stream.subscribe(lambda c, m: some.append(c), [ch.POWER])
    stream.publish("private/extra", object())
    assert every == ["private/extra"] and some == []


def test_published_at_once_each_subscriber_gets_its_channels_in_order_and_a_batch_one_call():
    """publish_many: subscribers in subscription order, each with the items of its channels in
    their order; one that takes batches gets them as one list (none when it has none)."""
    stream = TelemetryStream()
    got = []
    stream.subscribe(lambda c, m: got.append(("one", c)), [ch.fin_state(0), ch.SETPOINTS])
    stream.subscribe_batches(lambda items: got.append(("batch", [c for c, _ in items])), [ch.fin_state(1), ch.SETPOINTS])
    stream.subscribe_batches(lambda items: got.append(("power", [c for c, _ in items])), [ch.POWER])
    stream.subscribe_batches(lambda items: got.append(("all", [c for c, _ in items])))
    sp = Setpoints(1.0, 0.2, 0.5, 0.0)
    stream.publish_many([(ch.fin_state(1), _fin(1)), (ch.SETPOINTS, sp), (ch.fin_state(0), _fin(0))])
    assert got == [
        ("one", "body/setpoints"), ("one", "fin/0/state"),
        ("batch", ["fin/1/state", "body/setpoints"]),
        ("all", ["fin/1/state", "body/setpoints", "fin/0/state"]),
    ]
    got.clear()
    stream.publish(ch.SETPOINTS, sp)  # one message: a one-item list for a batch subscriber
    assert got == [("one", "body/setpoints"), ("batch", ["body/setpoints"]), ("all", ["body/setpoints"])]
    got.clear()
    stream.publish_many([])
    assert got == []


def test_published_at_once_one_bad_item_publishes_none():
    stream = TelemetryStream()
    got = []
    stream.subscribe(lambda c, m: got.append(m))
    stream.subscribe_batches(got.extend)
    with pytest.raises(TypeError, match="channel 'fin/0/state' carries FinState, got Setpoints"):
        stream.publish_many([(ch.fin_state(1), _fin(1)), (ch.fin_state(0), Setpoints(1.0, 0.2, 0.5, 0.0))])
    with pytest.raises(ValueError, match="unknown telemetry channel 'fin/9/state'"):
        stream.publish_many([(ch.fin_state(1), _fin(1)), ("fin/9/state", _fin())])
    assert got == []


def test_a_failing_batch_subscriber_is_logged_and_the_others_still_receive(caplog):
    stream = TelemetryStream()
    got = []

    def broken(items):
        raise RuntimeError("boom")

    stream.subscribe_batches(broken)
    stream.subscribe_batches(got.extend)
    off = stream.subscribe(lambda c, m: got.append(c))
    with caplog.at_level(logging.ERROR):
        stream.publish_many([(ch.fin_state(0), _fin()), (ch.fin_state(1), _fin(1))])
        stream.publish(ch.fin_state(0), _fin())
    assert len(got) == 2 + 2 + 1 + 1
    assert sum("failed on 2 messages" in r.getMessage() for r in caplog.records) == 1
    assert sum("failed on fin/0/state" in r.getMessage() for r in caplog.records) == 1
    off()
    assert stream.wanted == frozenset(ch.CHANNELS)  # the batch subscribers take every channel
