"""Execution module (control.md section 8, paper Algorithm 2) as a pure state machine.

One :class:`FinExecutor` per logical actuator. It takes plans ``[theta_1, w_1, theta_2, w_2]``
(absolute target angle and mean rate of each stroke), sends one stroke at a time to the
servo and watches encoder feedback to decide when the stroke is over::

    a      = (w_fb - w_prev) / (t_fb - t_prev)        (rate change between feedback samples)
    w_pred = w_fb + a (t_now - t_fb)                   (rate extrapolated to now)
    finished when  s * w_pred < w_th                   (s = +-1, the stroke direction;
                                                        |w_pred| < w_th when it is unknown)

Guards beyond Algorithm 2, all from :class:`ExecutorConfig`:

* a stroke cannot finish before ``min_stroke_time`` has passed since it was sent, nor before
  a feedback sample taken after the send has shown the fin moving in the stroke direction
  faster than ``w_th`` (so a servo that has not started yet is not mistaken for one that has
  stopped; strokes shorter than ``w_th * min_stroke_time`` skip this);
* a stroke is over in any case after ``max(stroke_timeout_min, stroke_timeout_factor *
  planned duration)`` (planned duration ``|theta_ref - theta_start| / w_ref``, or ``pi / w_ref``
  when the start angle is unknown), reported as :class:`StrokeTimeout`, so a stuck servo
  never stalls the loop. :meth:`FinExecutor.tick` checks this without feedback.

Signalling. When the last stroke of a plan is sent, :class:`PlanRequest` tells the planner
to plan the next cycle from that stroke's target angle (planning overlaps execution). When
that stroke is finished, :class:`CycleComplete` is emitted once (Algorithm 2's completion
signal); if a plan was loaded meanwhile it starts at once, otherwise the fin goes idle and
the next plan to arrive is late: it is counted (``late_plans``), its lateness (arrival time
minus the moment the fin went idle) is reported as :class:`LatePlan`, and it starts on
arrival. A plan loaded while another is still running waits as the pending plan; a newer
one replaces it (counted in ``superseded_plans``).

Sync mode: an executor built with two fins (:meth:`FinExecutor.synced`) drives both with
the same plan and starts every stroke on both fins together, once both have finished the
previous stroke.

The per-sample part (feeding a sample, checking for a stroke's end) is the compiled
:mod:`ucat_console.control.stroke_watch`; the closed loop runs it over all fins at once
and calls :meth:`FinExecutor.stroke_checked` when a stroke ended, so this class acts only
a few times a second per fin.

Fin ids are whatever the caller uses (e.g. ``FinFeedback.fin``). Time is always an argument.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ucat_console.control.argcheck import finite, in_range
from ucat_console.control.params import ExecutorConfig
from ucat_console.control.stroke_watch import TIMEOUT, StrokeWatches

#: largest accepted stroke rate in a plan (rad/s), a sanity bound on the input
MAX_PLAN_RATE = 100.0


@dataclass(frozen=True)
class SendToServo:
    """Profile-position command: move ``fin`` to ``theta_ref`` (rad) at ``w_ref`` (rad/s)."""

    t: float
    fin: int
    theta_ref: float
    w_ref: float
    plan: int  # sequence number of the plan (1 = first loaded)
    stroke: int  # 0-based stroke index within the plan


@dataclass(frozen=True)
class PlanRequest:
    """The last stroke of the plan has been sent: plan the next cycle from ``theta_start``."""

    t: float
    fins: tuple[int, ...]
    theta_start: float


@dataclass(frozen=True)
class CycleComplete:
    """The plan's last stroke is finished (Algorithm 2's completion signal).

    ``idle`` is True when no next plan was ready, so the fin stops and waits.
    """

    t: float
    fins: tuple[int, ...]
    idle: bool


@dataclass(frozen=True)
class LatePlan:
    """A plan arrived after the fin had gone idle; ``lateness`` in seconds."""

    t: float
    fins: tuple[int, ...]
    lateness: float


@dataclass(frozen=True)
class StrokeTimeout:
    """A stroke was ended by its timeout, not by the fin stopping."""

    t: float
    fin: int
    elapsed: float
    planned: float


Action = SendToServo | PlanRequest | CycleComplete | LatePlan | StrokeTimeout


def _check_commands(commands: Sequence[float]) -> tuple[tuple[float, float], ...]:
    if len(commands) % 2 or len(commands) == 0:
        raise ValueError(
            f"commands: expected [theta_1, w_1, theta_2, w_2, ...], got {len(commands)} values"
        )
    strokes = []
    for k in range(0, len(commands), 2):
        theta = finite(f"commands[{k}]", commands[k])
        w = in_range(
            f"commands[{k + 1}]", commands[k + 1], 0.0, MAX_PLAN_RATE, lo_open=True, unit="rad/s"
        )
        strokes.append((theta, w))
    return tuple(strokes)


class FinExecutor:
    """Algorithm 2 for one fin, or for a synchronised pair (see :meth:`synced`).

    The per-sample stroke-end detection lives in a :class:`StrokeWatches` table: the
    executor's own (one row per fin), or ``watches`` shared by every executor of a loop, in
    which fin ``f`` is row ``f``; an executor given a shared table drives its rows only from
    :meth:`take_over` on (until then another executor may still be finishing on them).
    """

    def __init__(self, cfg: ExecutorConfig, fins: int | tuple[int, ...] = 0, *,
                 watches: StrokeWatches | None = None) -> None:
        fins_t = (fins,) if isinstance(fins, int) else tuple(fins)
        if not fins_t or len(set(fins_t)) != len(fins_t):
            raise ValueError(f"fins: expected distinct fin ids, got {fins!r}")
        self.cfg = cfg
        self.fins = fins_t
        if watches is None:
            self.watches = StrokeWatches(cfg, len(fins_t))
            self.rows = tuple(range(len(fins_t)))
        else:
            n = watches.table.shape[0]
            if not all(isinstance(f, int) and 0 <= f < n for f in fins_t):
                raise ValueError(f"fins: {fins!r} are not rows of the shared table (0..{n - 1})")
            self.watches = watches
            self.rows = fins_t
        self._row = dict(zip(fins_t, self.rows))
        self._reset_plans()

    @classmethod
    def synced(cls, cfg: ExecutorConfig, fins: tuple[int, int] = (2, 3), *,
               watches: StrokeWatches | None = None) -> FinExecutor:
        """One executor driving a fin pair that starts every stroke together (sync mode)."""
        if len(fins) != 2:
            raise ValueError(f"fins: a synchronised pair needs 2 fins, got {fins!r}")
        return cls(cfg, tuple(fins), watches=watches)

    @property
    def sync(self) -> bool:
        return len(self.fins) > 1

    def take_over(self) -> None:
        """Start driving the fins: their rows of the table are fresh (no feedback, no stroke)."""
        self.watches.clear(self.rows)

    def reset(self) -> None:
        """Forget plans, strokes and counters (a fresh executor: the next plan is not late)."""
        self.watches.clear(self.rows)
        self._reset_plans()

    def _reset_plans(self) -> None:
        self._queue: list[tuple[float, float]] = []
        self._pending: tuple[tuple[float, float], ...] | None = None
        self._running = False
        self.idle_since: float | None = None
        self.plan_id = 0
        self.stroke_index = -1
        self.plans_loaded = 0
        self.late_plans = 0
        self.lateness_total = 0.0
        self.lateness_max = 0.0
        self.superseded_plans = 0
        self.strokes_done = 0
        self.timeouts = 0
        self.cycles_done = 0

    # -- state ---------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """A stroke is being executed."""
        return self._running

    @property
    def waiting(self) -> bool:
        """The fin finished its last plan and no plan was ready: the next one will be late."""
        return not self._running and self.idle_since is not None

    @property
    def has_pending(self) -> bool:
        return self._pending is not None

    def angle(self, fin: int | None = None) -> float | None:
        """Last feedback angle of ``fin`` (the only fin by default)."""
        return self.watches.angle(self._row[self._fin(fin)])

    # -- inputs --------------------------------------------------------------------------
    def load(
        self, commands: Sequence[float], t: float, theta_start: float | None = None
    ) -> list[Action]:
        """Hand over a plan ``[theta_1, w_1, theta_2, w_2]`` at time ``t``.

        ``theta_start`` is the fin angle the plan starts from, used for the first stroke's
        planned duration when the executor has no earlier target (else the previous target,
        else the last feedback angle).
        """
        strokes = _check_commands(commands)
        t = finite("t", t)
        if theta_start is not None:
            theta_start = finite("theta_start", theta_start)
        self.plans_loaded += 1
        if self._running:
            if self._pending is not None:
                self.superseded_plans += 1
            self._pending = strokes
            return []
        actions: list[Action] = []
        if self.idle_since is not None and t > self.idle_since:
            lateness = t - self.idle_since
            self.late_plans += 1
            self.lateness_total += lateness
            self.lateness_max = max(self.lateness_max, lateness)
            actions.append(LatePlan(t=t, fins=self.fins, lateness=lateness))
        self._begin_plan(strokes, t, theta_start, actions)
        return actions

    def on_feedback(
        self,
        t_fb: float,
        w_fb: float,
        t_now: float,
        *,
        fin: int | None = None,
        theta_fb: float | None = None,
    ) -> list[Action]:
        """Encoder feedback of ``fin`` sampled at ``t_fb`` (rate ``w_fb``), evaluated at ``t_now``."""
        fin = self._fin(fin)
        t_fb = finite("t_fb", t_fb)
        w_fb = finite("w_fb", w_fb)
        t_now = finite("t_now", t_now)
        if theta_fb is not None:
            theta_fb = finite("theta_fb", theta_fb)
        if t_now < t_fb:
            raise ValueError(f"t_now: {t_now!r} is earlier than the feedback time t_fb={t_fb!r}")
        self.watches.feed(self._row[fin], t_fb, w_fb, theta_fb)
        return self._advance(t_now, predict=True)

    def tick(self, t_now: float) -> list[Action]:
        """Check stroke timeouts at ``t_now`` without new feedback (no extrapolation)."""
        return self._advance(finite("t_now", t_now), predict=False)

    # -- internals -----------------------------------------------------------------------
    def _fin(self, fin: int | None) -> int:
        if fin is None:
            if len(self.fins) != 1:
                raise ValueError(f"fin: required for a synchronised pair {self.fins}")
            return self.fins[0]
        if fin not in self._row:
            raise ValueError(
                f"fin: {fin!r} is not driven by this executor; allowed: {self.fins}"
            )
        return fin

    def _begin_plan(
        self,
        strokes: tuple[tuple[float, float], ...],
        t: float,
        theta_start: float | None,
        actions: list[Action],
    ) -> None:
        self.plan_id += 1
        self.stroke_index = -1
        self._queue = list(strokes)
        self.idle_since = None
        self._send_next(t, theta_start, actions)

    def _send_next(self, t: float, theta_from: float | None, actions: list[Action]) -> None:
        theta_ref, w_ref = self._queue.pop(0)
        self.stroke_index += 1
        self._running = True
        for fin, row in zip(self.fins, self.rows):
            self.watches.start(row, t, theta_from, theta_ref, w_ref)
            actions.append(SendToServo(t, fin, theta_ref, w_ref, self.plan_id, self.stroke_index))
        if not self._queue:
            actions.append(PlanRequest(t=t, fins=self.fins, theta_start=theta_ref))

    def _advance(self, t_now: float, predict: bool) -> list[Action]:
        if not self._running:
            return []
        return self.stroke_checked(t_now, [self.watches.check(r, t_now, predict) for r in self.rows])

    def stroke_checked(self, t_now: float, found: Sequence[int]) -> list[Action]:
        """Act on the check of each fin's row at ``t_now`` (``found[k]`` for ``fins[k]``: the
        table's NOTHING, STOPPED or TIMEOUT): the loop calls this when its compiled feedback
        pass saw one of this executor's strokes end."""
        actions: list[Action] = []
        if not self._running:
            return actions
        w = self.watches
        for fin, row, code in zip(self.fins, self.rows, found):
            if code == TIMEOUT:
                self.timeouts += 1
                actions.append(StrokeTimeout(t_now, fin, t_now - w.started(row), w.planned(row)))
        if not all(w.done(r) for r in self.rows):
            return actions
        self.strokes_done += 1
        self._running = False
        if self._queue:
            self._send_next(t_now, None, actions)
            return actions
        self.cycles_done += 1
        pending, self._pending = self._pending, None
        actions.append(CycleComplete(t=t_now, fins=self.fins, idle=pending is None))
        if pending is not None:
            self._begin_plan(pending, t_now, None, actions)
        else:
            self.idle_since = t_now
        return actions
