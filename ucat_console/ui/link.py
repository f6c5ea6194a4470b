"""How much of what the console sent one page has not yet reached it, and whether its link is slow.

The page guard asks every page for a heartbeat (a request the page's script answers when it
reads it, :mod:`ucat_console.ui.guard`). Frames reach a page in the order they were sent, so
an answer to a request says that the page has read every byte sent before that request: the
bytes in flight are those sent since the last answered request. They sit in the server's
socket buffers, the network and the page's receive buffers, where nothing can overtake them;
a heartbeat request sent now is read only after them. :class:`PageLink` counts them, and the
console sends a page more telemetry only while they are under the page's budget
(:meth:`PageLink.room`): a page that reads slowly gets less (its poses and plots coalesce in
viser's buffers, the newest value of each kept), and its heartbeat waits behind at most its
budget, so a slow link is not a silent page.

* **Base round trip.** A link's own latency (a link 0.6 s each way: 1.2 s) is not a queue: a
  round trip is late when it is longer than :data:`TARGET_RTT` or, where that is longer,
  twice the least round trip the page has answered (``base_rtt``, over the whole
  connection, so that a queue that never drains does not pass for latency; a link whose
  latency grows later is treated as queued, its telemetry going after each answer, until
  the page reconnects): :attr:`PageLink.rtt_limit`.
* **Budget.** Adjusted at each answer by the request's round trip and by how much the
  budget held the telemetry back, to keep the round trips short and the budget no larger
  than the page needs: one that was late shrinks the budget by
  :data:`SHRINK`; a quick one while the telemetry was held back at least
  :data:`GROW_HELD` of the last :data:`SLOW_WINDOW` s (the budget is what limits the page)
  grows it by the bytes it acknowledged (about doubling it each round trip); a quick one
  while the telemetry was hardly held back (under :data:`DECAY_HELD`) lets it decay by
  :data:`DECAY` down to :data:`START_BUDGET`, so a page on a fast link keeps little in
  flight (what a link that suddenly slows down has to drain). Always between
  :data:`MIN_BUDGET` and :data:`MAX_BUDGET`. And
  while a request is out for longer than that the page is behind: nothing more is
  sent until it answers. A page reading 50 kB/s settles at a few tens of kB in flight (a
  heartbeat reaches it within about half a second); a page whose answers come late for
  another reason than its link (a browser busy rendering) grows its budget while they
  still come within TARGET_RTT.
* **Slow.** A link is slow when its bytes in flight were over the budget (the console held
  telemetry back) for at least :data:`SLOW_ON` of the last :data:`SLOW_WINDOW` s; it is no
  longer slow when that share falls under :data:`SLOW_OFF`. The page shows it ("link slow").

Time is an argument of every method (seconds on any monotonic clock); nothing here reads a
clock, sleeps or sends.
"""

from __future__ import annotations

import collections

#: the least a page may have in flight (bytes): a large plot update and a heartbeat
MIN_BUDGET = 16 * 1024
#: the budget of a new page (bytes), and the most
START_BUDGET = 32 * 1024
MAX_BUDGET = 16 * 1024 * 1024
#: the round trip a heartbeat request should take at most (s), or twice the link's base
#: round trip (its latency, the least round trip answered) where that is longer
TARGET_RTT = 0.5
#: the budget's factor after a slow round trip, and after one with the budget not in use
SHRINK = 0.7
DECAY = 0.9
#: held back at least this share of the last SLOW_WINDOW s: the budget limits the page;
#: under DECAY_HELD: it does not
GROW_HELD = 0.25
DECAY_HELD = 0.05
#: the window over which the time held back is measured (s)
SLOW_WINDOW = 2.0
#: share of SLOW_WINDOW held back from which a link is slow, and under which it is not
SLOW_ON = 0.5
SLOW_OFF = 0.1


class PageLink:
    """The bytes in flight to one page and its budget (module docstring)."""

    def __init__(self, now: float) -> None:
        self.sent_bytes = 0  # every byte written to the page's socket
        self.read_bytes = 0  # bytes the page has read, as its last answer tells
        self.rtt = 0.0  # round trip of the last answered request (s)
        self.answers = 0
        self.budget = START_BUDGET  # bytes the page may have in flight before telemetry is held back
        self._probes: dict[int, tuple[int, float]] = {}  # request -> (bytes sent with it, time)
        self.base_rtt = 0.0  # the least round trip answered (0 before any answer)
        self._held: collections.deque[tuple[float, float]] = collections.deque()  # (from, to)
        self._held_since: float | None = None
        self.slow = False

    # ------------------------------------------------------------------ events
    def sent(self, nbytes: int, now: float) -> None:
        """``nbytes`` written to the page's socket at ``now``."""
        self.sent_bytes += int(nbytes)
        self._update(now)

    def probe(self, seq: int, now: float) -> None:
        """Request ``seq`` has just been written (after its own bytes were counted)."""
        self._probes[seq] = (self.sent_bytes, now)

    def answered(self, seq: int, now: float) -> bool:
        """The page answered request ``seq`` at ``now``; False when no such request is
        outstanding (an answer the console did not ask for tells nothing)."""
        probe = self._probes.get(seq)
        if probe is None:
            return False
        for s in [s for s in self._probes if s <= seq]:
            del self._probes[s]
        read, t_sent = probe
        acknowledged = max(0, read - self.read_bytes)
        self.read_bytes = max(self.read_bytes, read)
        self.rtt = max(0.0, now - t_sent)
        held = self.held_share(now)
        if self.rtt > self.rtt_limit:  # judged by the earlier answers' base (a first one's may be a queue)
            self.budget = max(MIN_BUDGET, int(self.budget * SHRINK))
        elif held >= GROW_HELD:
            self.budget = min(MAX_BUDGET, self.budget + acknowledged)
        elif held < DECAY_HELD:
            self.budget = max(min(self.budget, START_BUDGET), int(self.budget * DECAY))
        self.base_rtt = self.rtt if self.answers == 0 else min(self.base_rtt, self.rtt)
        self.answers += 1
        self._update(now)
        return True

    # ------------------------------------------------------------------ state
    @property
    def in_flight(self) -> int:
        """Bytes sent that the page has not been seen to read."""
        return self.sent_bytes - self.read_bytes

    @property
    def outstanding(self) -> int:
        """Requests sent and not answered."""
        return len(self._probes)

    @property
    def rtt_limit(self) -> float:
        """The longest round trip that is not late: TARGET_RTT, or twice the base round trip."""
        return max(TARGET_RTT, 2.0 * self.base_rtt)

    def late(self, now: float) -> bool:
        """Whether a request has been out for longer than :attr:`rtt_limit` (the page is behind)."""
        limit = self.rtt_limit
        return any(now - t > limit for _, t in self._probes.values())

    def room(self, now: float) -> bool:
        """Whether more telemetry may be sent at ``now``."""
        return self.in_flight < self.budget and not self.late(now)

    @property
    def split(self) -> bool:
        """Whether the page's batches go in parts (the page's sender): on a slow link, one
        whose last round trip took longer than TARGET_RTT, or one not yet measured, so that
        a heartbeat waits behind the budget and one part, not a whole batch. Any other page
        gets each batch whole (one encoding, shared with the other pages in step; a browser
        works per frame)."""
        return self.answers == 0 or self.slow or self.rtt > TARGET_RTT

    def held_share(self, now: float) -> float:
        """Share of the last SLOW_WINDOW s during which telemetry was held back."""
        start = now - SLOW_WINDOW
        total = sum(min(b, now) - max(a, start) for a, b in self._held if b > start)
        if self._held_since is not None:
            total += now - max(self._held_since, start)
        return max(0.0, min(1.0, total / SLOW_WINDOW))

    def _update(self, now: float) -> None:
        over = not self.room(now)
        if over and self._held_since is None:
            self._held_since = now
        elif not over and self._held_since is not None:
            self._held.append((self._held_since, now))
            self._held_since = None
        while self._held and self._held[0][1] < now - SLOW_WINDOW:
            self._held.popleft()
        self.update_slow(now)

    def update_slow(self, now: float) -> bool:
        """Whether the link is slow at ``now`` (with hysteresis: SLOW_ON, SLOW_OFF)."""
        share = self.held_share(now)
        if self.slow and share < SLOW_OFF:
            self.slow = False
        elif not self.slow and share >= SLOW_ON:
            self.slow = True
        return self.slow
