"""The commands the closed loop takes, from any thread (:meth:`ClosedLoop.submit`).

Each command is a frozen dataclass that checks its own values once, when it is made (a bad
one raises :class:`CommandRefused`, a ValueError naming the field, and nothing changes):
:class:`SetSetpoints`, :class:`SetMode`, :class:`SetBlock` (a tunable block of
``blocks``: the MPC, a body-frame PID, the baseline, ...), :class:`Restart`, and
:class:`LoopWork` (the supervisor's work that must run in the loop's thread: arming, drive
resets). At submission (``command_channel``) a command is resolved against what is
commanded (:meth:`LoopCommand.resolve`: the setpoints left as they are where None, then
checked against the envelope), recorded as commanded (:meth:`LoopCommand.commanded`: what
the supervisor and the page read back), and queued; the loop's thread applies it at its
next event (:meth:`LoopCommand.apply`) through the narrow :class:`CommandTarget` the loop
gives it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol

from ucat_console.backend.loop import blocks as tunable
from ucat_console.backend.loop.blocks import PID_LOOPS
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import MODES
from ucat_console.control.allocation import BodySetpoints

#: the setpoints the operator sets
SETPOINTS = ("velocity", "depth", "yaw_rate")


class CommandRefused(ValueError):
    """A command refused because of its value or the present state (the message says why)."""


def number(key: str, value: Any, integer: bool) -> float | int:
    """``value`` as a finite number of the right kind, or CommandRefused naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        kind = "an integer" if integer else "a number"
        raise CommandRefused(f"{key}: expected {kind}, got {value!r}")
    if not math.isfinite(value):
        raise CommandRefused(f"{key}: {value!r} is not a finite number")
    if integer:
        if float(value) != int(value):
            raise CommandRefused(f"{key}: expected an integer, got {value!r}")
        return int(value)
    return float(value)


def check_setpoints(cfg: LoopConfig, sp: BodySetpoints) -> BodySetpoints:
    """``sp`` if it lies inside the envelope of ``cfg``, else ValueError naming the value."""
    return sp.within(cfg.max_velocity, cfg.max_depth, cfg.max_yaw_rate)


@dataclass(frozen=True)
class Commanded:
    """What the loop is commanded to do (in force from its next event)."""

    mode: str
    setpoints: BodySetpoints
    blocks: Mapping[str, Any]  # tunable block (``blocks``) -> its config

    @classmethod
    def of(cls, cfg: LoopConfig, setpoints: BodySetpoints) -> Commanded:
        return cls(mode=cfg.mode, setpoints=check_setpoints(cfg, setpoints), blocks=tunable.initial_blocks(cfg))


class CommandTarget(Protocol):
    """What the loop's thread does with each command (at loop time ``t``)."""

    def apply_setpoints(self, sp: BodySetpoints, t: float) -> BodySetpoints: ...
    def apply_mode(self, mode: str, t: float, who: str) -> str: ...
    def apply_block(self, block: str, cfg: Any, t: float, who: str) -> None: ...
    def apply_restart(self, t: float) -> None: ...


class LoopCommand:
    """A command of the loop (module docstring); values checked when it is made."""

    def resolve(self, now: Commanded, cfg: LoopConfig) -> LoopCommand:
        """The command as it will apply, given what is commanded ``now``; CommandRefused
        when it does not fit the configuration."""
        return self

    def commanded(self, now: Commanded) -> Commanded:
        """What is commanded once this (resolved) command is submitted."""
        return now

    def apply(self, target: CommandTarget, t: float) -> Any:
        """Carry it out in the loop's thread at loop time ``t``; its answer (the Future's result)."""
        raise NotImplementedError


@dataclass(frozen=True)
class SetSetpoints(LoopCommand):
    """New setpoints, unchanged where None; applied, the setpoints in force before."""

    velocity: float | None = None
    depth: float | None = None
    yaw_rate: float | None = None

    def __post_init__(self) -> None:
        for k in SETPOINTS:
            v = getattr(self, k)
            if v is not None:
                object.__setattr__(self, k, number(k, v, False))

    def resolve(self, now: Commanded, cfg: LoopConfig) -> SetSetpoints:
        cur = now.setpoints
        try:
            sp = check_setpoints(cfg, BodySetpoints(
                velocity=cur.velocity if self.velocity is None else self.velocity,
                depth=cur.depth if self.depth is None else self.depth,
                yaw_rate=cur.yaw_rate if self.yaw_rate is None else self.yaw_rate,
            ))
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        return SetSetpoints(sp.velocity, sp.depth, sp.yaw_rate)

    @property
    def setpoints(self) -> BodySetpoints:
        """The setpoints of a resolved command (every one given)."""
        assert self.velocity is not None and self.depth is not None and self.yaw_rate is not None
        return BodySetpoints(self.velocity, self.depth, self.yaw_rate)

    def commanded(self, now: Commanded) -> Commanded:
        return dataclasses.replace(now, setpoints=self.setpoints)

    def apply(self, target: CommandTarget, t: float) -> BodySetpoints:
        return target.apply_setpoints(self.setpoints, t)


@dataclass(frozen=True)
class SetMode(LoopCommand):
    """Switch the fin controller while swimming (bumpless; an Event with code "mode"
    naming ``who``); applied, the mode in force before."""

    name: str
    who: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or self.name not in MODES:
            raise CommandRefused(f"mode: {self.name!r} is not one of {', '.join(MODES)}")

    def commanded(self, now: Commanded) -> Commanded:
        return dataclasses.replace(now, mode=self.name)

    def apply(self, target: CommandTarget, t: float) -> str:
        return target.apply_mode(self.name, t, self.who)


@dataclass(frozen=True)
class SetBlock(LoopCommand):
    """A new configuration of a tunable block (``blocks``: "mpc", "pid.depth", "baseline",
    ...), in force from the loop's next event (the MPC: from the next plan); one of the
    wrong type, or one the block's own check refuses (an MPC configuration the planner does
    not accept), is refused here."""

    block: str
    cfg: Any
    who: str = ""

    def __post_init__(self) -> None:
        try:
            entry = tunable.block(self.block)
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        if not isinstance(self.cfg, entry.config):
            raise CommandRefused(f"{self.block} config: expected a {entry.config.__name__}, "
                                 f"got {type(self.cfg).__name__}")
        if entry.check is not None:
            try:
                entry.check(self.cfg)
            except ValueError as e:
                raise CommandRefused(f"{self.block}: {e}") from None

    def commanded(self, now: Commanded) -> Commanded:
        return dataclasses.replace(now, blocks={**now.blocks, self.block: self.cfg})

    def apply(self, target: CommandTarget, t: float) -> None:
        target.apply_block(self.block, self.cfg, t, self.who)


@dataclass(frozen=True)
class Restart(LoopCommand):
    """Start the body loops and every fin afresh, as at start-up (ClosedLoop.apply_restart)."""

    def apply(self, target: CommandTarget, t: float) -> None:
        target.apply_restart(t)


@dataclass(frozen=True)
class LoopWork(LoopCommand):
    """``fn()`` in the loop's thread, between two of its events (the supervisor's arming,
    drive resets, a stall injected); applied, what ``fn`` returns."""

    fn: Callable[[], Any]
    what: str = ""

    def __post_init__(self) -> None:
        if not callable(self.fn):
            raise CommandRefused(f"loop work {self.what!r}: expected a callable, got {self.fn!r}")

    def apply(self, target: CommandTarget, t: float) -> Any:
        return self.fn()


def pid_loop(loop: str) -> str:
    """``loop`` if it names a body-frame PID, else CommandRefused naming them."""
    if loop not in PID_LOOPS:
        raise CommandRefused(f"loop: {loop!r} is not one of {', '.join(PID_LOOPS)}")
    return loop
