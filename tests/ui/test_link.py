"""A page's link: the bytes in flight, the budget, "slow"; and a pilot on a 50 kB/s link
through the console's real page guard, sender and viser's buffer, on a simulated clock.

The simulation (:class:`SlowLink`) runs the guard's heartbeats (``tick``), its frames sent
ahead and its pacing of the telemetry (the console's sender, ``viser_compat._pacing_producer``,
on viser's broadcast buffer) in an event loop driven step by step; the network is a pipe
that delivers 50 kB per simulated second to a page that answers every heartbeat request as
soon as it has read it. The live view's traffic is imitated: the robot's pose 40 times a
second and five plots of 600 points 12 times a second (about 0.9 MB/s).
"""

from __future__ import annotations

import asyncio
import collections
import math
from typing import Any

import numpy as np
import pytest
import viser._messages as vm
from support import FakeClock
from viser.infra._async_message_buffer import AsyncMessageBuffer

from ucat_console.bench.raw_page import decode_batch
from ucat_console.ui import link as link_mod
from ucat_console.ui import viser_compat
from ucat_console.ui.guard import PageGuard
from ucat_console.ui.link import MIN_BUDGET, PageLink


# ---------------------------------------------------------------------- the link alone
def test_bytes_in_flight_are_those_sent_after_the_last_answered_request() -> None:
    link = PageLink(0.0)
    link.sent(10_000, 0.0)
    link.probe(1, 0.0)  # the page has read 10 kB once it answers 1
    link.sent(5_000, 0.1)
    link.probe(2, 0.1)
    link.sent(7_000, 0.2)
    assert link.in_flight == 22_000 and link.outstanding == 2
    assert link.answered(1, 0.5) and link.in_flight == 12_000 and link.rtt == pytest.approx(0.5)
    assert not link.answered(1, 0.6)  # answered already
    assert not link.answered(7, 0.6)  # never asked
    assert link.answered(2, 0.7) and link.in_flight == 7_000 and link.outstanding == 0


def test_the_budget_grows_while_it_holds_back_a_page_that_answers_in_time_and_shrinks_otherwise() -> None:
    link = PageLink(0.0)
    assert link.budget == link_mod.START_BUDGET and link.room(0.0)
    t, seq = 0.0, 0

    def round_trip(nbytes: int, rtt: float) -> None:
        nonlocal t, seq
        seq += 1
        link.sent(nbytes, t)
        link.probe(seq, t)
        t += rtt
        assert link.answered(seq, t)

    round_trip(100, 0.01)  # quick, the telemetry not held back: no reason to grow
    assert link.budget == link_mod.START_BUDGET
    budget = link.budget
    for _ in range(10):  # the budget full each time (held back), answers within the target: it grows
        round_trip(link.budget, 0.4)
    assert link.budget > 100 * budget
    for _ in range(100):
        round_trip(link.budget, 0.4)
    assert link.budget == link_mod.MAX_BUDGET
    for _ in range(500):  # then hardly held back (after the last 2 s held): it decays, to the start's budget
        round_trip(100, 0.01)
    assert link.budget == link_mod.START_BUDGET
    for _ in range(100):  # a slow round trip, whatever was in flight: it shrinks, to the minimum
        round_trip(1000, link_mod.TARGET_RTT + 0.1)
    assert link.budget == MIN_BUDGET
    assert link.in_flight == 0 and link.room(t)
    for _ in range(100):  # quick again, not held back: it stays
        round_trip(100, 0.01)
    assert link.budget == MIN_BUDGET
    link.sent(MIN_BUDGET, t)
    assert not link.room(t)  # over the budget


def test_a_request_out_for_longer_than_the_target_holds_the_telemetry_back() -> None:
    link = PageLink(0.0)
    link.sent(1000, 0.0)
    link.probe(1, 0.0)
    assert link.room(link_mod.TARGET_RTT)
    assert not link.room(link_mod.TARGET_RTT + 0.01)  # the page is behind: nothing more
    assert link.answered(1, 0.6) and link.room(0.6)
    link.probe(2, 1.0)
    assert link.answered(2, 1.05)  # a quick round trip: the link's own latency is 0.05 s
    link.sent(1000, 2.0)
    link.probe(3, 2.0)
    assert not link.room(2.0 + link_mod.TARGET_RTT + 0.01)
    budget = link.budget
    assert link.answered(3, 2.7) and link.budget < budget  # and a slow round trip shrinks the budget


def test_a_link_slow_by_its_latency_alone_is_not_held_back() -> None:
    # 0.6 s each way, ample bandwidth: a heartbeat request every 0.3 s, each answered 1.2 s
    # later; the link's own latency is no queue, so telemetry goes on between the answers
    link = PageLink(0.0)
    answers: collections.deque[tuple[float, int]] = collections.deque()
    held = 0
    for step in range(400):  # 40 s in steps of 0.1 s
        now = step * 0.1
        while answers and answers[0][0] <= now + 1e-9:
            link.answered(answers.popleft()[1], now)
        if step % 3 == 0:
            link.probe(step, now)
            answers.append((now + 1.2, step))
        if link.room(now):
            link.sent(2000, now)
        elif now > 5.0:  # after the first answers
            held += 1
    assert link.base_rtt == pytest.approx(1.2, abs=0.11) and link.rtt_limit == pytest.approx(2.4, abs=0.21)
    assert held == 0 and not link.slow


def test_a_link_held_back_most_of_the_time_is_slow_and_recovers_with_hysteresis() -> None:
    link = PageLink(0.0)
    seq = 0
    t = 0.0
    # held back 80 % of the time: over budget for 0.8 s, then read, each second
    while t < 3.0:
        seq += 1
        link.sent(link.budget + 1, t)
        link.probe(seq, t)
        link.answered(seq, t + 0.8)
        t += 1.0
        link.update_slow(t)
    assert link.slow
    # then held back 20 % of the time: still slow (over SLOW_OFF), then fast: not slow
    for held in (0.2, 0.0, 0.0, 0.0):
        seq += 1
        link.sent(link.budget + 1 if held else 100, t)
        link.probe(seq, t)
        assert link.answered(seq, t + max(held, 0.001))
        t += 1.0
        link.update_slow(t)
        if held:
            assert link.slow
    assert not link.slow


# ---------------------------------------------------------------------- a pilot on a slow link
class FakeSocket:
    """The page's websocket on the server side: what is sent goes into the network pipe."""

    def __init__(self) -> None:
        self.server = object()  # the key under which the guard is found
        self.pipe: collections.deque[bytearray] = collections.deque()
        self.queued = 0  # bytes in the pipe
        self.remote_address = ("127.0.0.1", 1)
        self.transport = self  # the guard aborts a gone page's transport
        self.aborted = False

    def abort(self) -> None:
        self.aborted = True

    async def send(self, data: bytes) -> None:
        self.pipe.append(bytearray(data))
        self.queued += len(data)


class SlowLink:
    """The simulation of the module docstring; ``rate`` in bytes per simulated second."""

    POSE_RATE = 40.0
    PLOT_RATE = 12.0
    DT = 0.01

    def __init__(self, rate: float, pilot_timeout: float = 2.0, heartbeat_period: float = 0.25) -> None:
        viser_compat.install()
        self.rate = rate
        self.clock = FakeClock()
        self.gone: list[tuple[int, float]] = []
        self.guard = PageGuard(is_pilot=lambda c: True, pilot_timeout=lambda: pilot_timeout, page_timeout=10.0,
                               heartbeat_period=heartbeat_period, on_gone=lambda c, s: self.gone.append((c, s)),
                               clock=self.clock)
        self.loop = asyncio.new_event_loop()
        self.guard.loop = self.loop  # the heartbeat thread is not started: the test ticks
        self.ws = FakeSocket()
        viser_compat._GUARDS[self.ws.server] = self.guard
        self.guard.page_opened(0, None, self.ws)
        self.buffer = AsyncMessageBuffer(self.loop, persistent_messages=True)
        self.producer = self.loop.create_task(viser_compat._pacing_producer(self.ws, self.buffer, 0))
        self.answering = True
        self.reading = True
        self.pose_sent = 0.0  # the newest pose pushed (its x is the time it was pushed)
        self.pose_seen = -math.inf  # the newest pose the page has
        self.received = 0  # bytes the page read
        self.rtts: list[float] = []
        self.asked: dict[str, float] = {}  # heartbeat request -> when it was sent
        self.max_in_flight = 0
        self.slow_seen = False
        self._partial = 0  # bytes of the pipe's first frame already read
        self._next = {"pose": 0.0, "plot": 0.0, "hb": 0.0}
        self._plot = 0
        self._rng = np.random.default_rng(1)

    def close(self) -> None:
        self.producer.cancel()
        self._drive()
        self.loop.close()
        viser_compat._GUARDS.pop(self.ws.server, None)

    def _drive(self) -> None:
        """Let the event loop run until its tasks wait (a few turns)."""
        async def turns() -> None:
            for _ in range(6):
                await asyncio.sleep(0)

        self.loop.run_until_complete(turns())

    def _telemetry(self, t: float) -> None:
        if t >= self._next["pose"]:
            self._next["pose"] += 1.0 / self.POSE_RATE
            self.buffer.push(vm.SetPositionMessage(name="/live/robot", position=(t, 0.0, 0.0)))
            self.buffer.push(vm.SetOrientationMessage(name="/live/robot", wxyz=(1.0, 0.0, 0.0, 0.0)))
            self.pose_sent = t
        if t >= self._next["plot"]:
            self._next["plot"] += 1.0 / self.PLOT_RATE
            for k in range(5):  # five plots, three series of 600 points each
                data = tuple(self._rng.standard_normal(600) for _ in range(3))
                self.buffer.push(vm.GuiUpdateMessage(uuid=f"plot-{k}", updates={"data": data}))
        self.buffer.flush()  # as the live view does after each pass (``ui.app._sent_at_once``)

    def _read(self, nbytes: float) -> None:
        """The page reads up to ``nbytes``; each frame it completes is applied."""
        budget = int(nbytes)
        ws = self.ws
        while budget > 0 and ws.pipe:
            frame = ws.pipe[0]
            take = min(budget, len(frame) - self._partial)
            self._partial += take
            budget -= take
            self.received += take
            if self._partial < len(frame):
                break
            ws.pipe.popleft()
            ws.queued -= len(frame)
            self._partial = 0
            self._apply(decode_batch(bytes(frame)))

    def _apply(self, messages: list[dict[str, Any]]) -> None:
        for m in messages:
            tp = m["type"]
            if tp == "SetPositionMessage":
                self.pose_seen = max(self.pose_seen, m["position"][0])
            elif tp == "LocalStorageGetItemRequestMessage":
                uid = m["request_uuid"]
                if uid in self.asked:
                    self.rtts.append(self.clock.now - self.asked.pop(uid))
                if self.answering:
                    self.guard.admit(0, vm.LocalStorageGetItemResponseMessage(value=None, error=None, request_uuid=uid))

    def _note_requests(self) -> None:
        page = self.guard.flow(0)
        if page is not None:
            self.asked.setdefault(f"ucat-hb-{page.seq}", self.clock.now)

    def run(self, seconds: float, telemetry: bool = True) -> None:
        period = self.guard.heartbeat_period
        end = self.clock.now + seconds
        while self.clock.now < end and not self.gone:
            self.clock.advance(self.DT)
            t = self.clock.now
            if telemetry:
                self._telemetry(t)
            if t >= self._next["hb"]:
                self._next["hb"] += period
                self.guard.tick()
            self._drive()
            self._note_requests()
            if self.reading:
                self._read(self.rate * self.DT)
            self._drive()
            self._note_requests()
            state = self.guard.link_state(0)
            if state is not None:
                self.max_in_flight = max(self.max_in_flight, state["in_flight"])
                self.slow_seen |= bool(state["slow"])


@pytest.fixture
def slow_link() -> Any:
    sim = SlowLink(rate=50_000.0)
    yield sim
    sim.close()


def test_a_pilot_on_a_50_kb_s_link_stays_the_pilot_for_a_minute_of_traffic(slow_link: SlowLink) -> None:
    sim = slow_link
    sim.run(60.0)
    assert not sim.gone, f"declared gone: {sim.gone}"
    assert sim.clock.now >= 60.0
    # the page got about what its link carries, not a growing backlog: what waits for it is
    # bounded by its budget and one message, and its heartbeats come back in time
    assert sim.received >= 0.9 * 60.0 * sim.rate
    link = sim.guard.flow(0).link
    assert sim.max_in_flight <= link_mod.MIN_BUDGET + 60_000
    assert len(sim.rtts) > 100 and max(sim.rtts) < 1.5
    # newest first: the robot the page shows is at most about a second old
    assert sim.pose_sent - sim.pose_seen < 1.5
    # and the page is told its link is slow
    assert sim.slow_seen and link.slow
    print(f"50 kB/s: max heartbeat round trip {max(sim.rtts):.2f} s, pose {sim.pose_sent - sim.pose_seen:.2f} s old, "
          f"max in flight {sim.max_in_flight} B, budget {link.budget} B")


def test_a_pilot_on_a_slow_link_that_stops_answering_is_still_declared_gone(slow_link: SlowLink) -> None:
    sim = slow_link
    sim.run(10.0)
    assert not sim.gone
    sim.answering = False  # frozen: it still reads, it no longer answers
    t0 = sim.clock.now
    sim.run(10.0)
    assert sim.gone and sim.gone[0][0] == 0
    assert 2.0 <= sim.gone[0][1] < 2.5  # its silence when it was declared gone
    assert sim.clock.now - t0 < 2.5
    sim._drive()
    assert sim.ws.aborted  # and its socket closed


def test_a_pilot_that_stops_reading_is_declared_gone(slow_link: SlowLink) -> None:
    sim = slow_link
    sim.run(5.0)
    sim.reading = False
    t0 = sim.clock.now
    sim.run(10.0)
    assert sim.gone and sim.clock.now - t0 < 2.5


def test_a_pilot_whose_link_drops_to_50_kb_s_stays_the_pilot(slow_link: SlowLink) -> None:
    sim = slow_link
    sim.rate = 10e6  # a fast link first: the page keeps up, its budget is what it uses
    sim.run(10.0)
    assert not sim.slow_seen
    sim.rate = 50_000.0
    sim.run(30.0)
    assert not sim.gone and max(sim.rtts) < 1.5 and sim.guard.flow(0).link.slow


def test_a_fast_page_gets_the_newest_pose_at_once_and_is_not_slow() -> None:
    sim = SlowLink(rate=10e6)  # 10 MB/s: more than the telemetry needs
    try:
        sim.run(10.0)
        assert not sim.gone and not sim.slow_seen
        assert sim.pose_sent - sim.pose_seen < 0.05
        # a batch over the budget waits for a request's answer at times: a few a second
        assert sim.guard.flow(0).link.answers < 50 * 10.0
    finally:
        sim.close()
