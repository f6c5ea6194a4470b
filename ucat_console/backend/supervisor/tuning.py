"""Live tuning and its journal: the tuning in force, the saved tuning to revert to, and who
changed what when.

What the operator may tune is the loop's registry of tunable blocks
(``backend.loop.blocks``: ``mpc``, ``pid.<loop>``, ``baseline`` and any block registered
there), read at each use. :class:`Tuning` reads the commanded tuning (block -> frozen config)
from the loop. A change is checked whole before anything changes (:meth:`Tuning.check`:
every key a tunable field of a registered block, every value of its field's kind and range,
then each changed block made into the loop's command, which refuses a configuration its
block's own check refuses, e.g. an MPC configuration the planner does not accept), then
submitted to the closed loop, which applies it from its next event, and journalled
(:class:`Journal`).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping

from ucat_console.backend.loop import blocks as tunable
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import CommandRefused, SetBlock, number
from ucat_console.config import AppConfig
from ucat_console.typedconf import check_value, choices_of

_JOURNAL_KEEP = 500


def fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


@dataclass(frozen=True)
class JournalEntry:
    """One operator or failsafe change: who, when (wall clock and stream time), old -> new."""

    wall: float
    t: float
    who: str
    key: str
    old: Any
    new: Any

    def text(self) -> str:
        stamp = time.strftime("%H:%M:%S", time.localtime(self.wall))
        return f"{stamp} {self.who}: {self.key} {fmt(self.old)} -> {fmt(self.new)}"


class Journal:
    """The last changes (any thread)."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock  # stream time
        self._lock = threading.Lock()
        self._entries: list[JournalEntry] = []

    def add(self, who: str, key: str, old: Any, new: Any) -> JournalEntry:
        e = JournalEntry(time.time(), self._clock(), who, key, old, new)
        with self._lock:
            self._entries.append(e)
            if len(self._entries) > _JOURNAL_KEEP:
                del self._entries[: len(self._entries) - _JOURNAL_KEEP]
        return e

    def last(self, n: int | None = None) -> list[JournalEntry]:
        with self._lock:
            return list(self._entries if n is None else self._entries[-n:])


def split_key(key: object) -> tuple[str, str]:
    """``"pid.depth.kp"`` -> ``("pid.depth", "kp")``, or CommandRefused."""
    if not isinstance(key, str) or "." not in key:
        raise CommandRefused(f"parameter: {key!r} is not a tunable parameter")
    block, _, name = key.rpartition(".")
    entry = tunable.BLOCKS.get(block)
    if entry is None or name not in entry.fields:
        raise CommandRefused(f"{key}: not a tunable parameter (the tunable blocks: "
                             f"{', '.join(tunable.block_names())})")
    return block, name


def is_tuning_key(key: str) -> bool:
    """Whether journal key ``key`` is a tunable parameter's (``"pid.depth.kp"``)."""
    return key.rpartition(".")[0] in tunable.BLOCKS


def tuning_blocks(cfg: AppConfig) -> dict[str, Any]:
    """The tunable blocks of a configuration: block -> frozen config."""
    return tunable.initial_blocks(cfg.loop)


def configured(cfg: AppConfig, blocks: Mapping[str, Any]) -> AppConfig:
    """``cfg`` with the tunable blocks ``blocks`` (block -> config) in its loop configuration
    (a block that is not part of it, as its entry says, is left out)."""
    loop = cfg.loop
    for name, value in blocks.items():
        configure = tunable.block(name).configure
        if configure is not None:
            loop = configure(loop, value)
    return cfg.replace(loop=loop)


class Tuning:
    """The commanded tuning of one closed loop (module docstring)."""

    def __init__(self, cfg: AppConfig, loop: ClosedLoop, journal: Journal,
                 planner_ready: Callable[[str], bool] = lambda f: True) -> None:
        self.loop = loop
        self.journal = journal
        self.planner_ready = planner_ready
        self._lock = threading.Lock()
        self._saved = tuning_blocks(cfg)

    def blocks(self) -> dict[str, Any]:
        """The tuning commanded now (held by the loop, its one owner)."""
        return {name: self.loop.block_config(name) for name in tunable.block_names()}

    def saved(self) -> dict[str, Any]:
        """The tuning to revert to, of each registered block (one registered since it was
        saved: where the loop started it)."""
        with self._lock:
            saved = dict(self._saved)
        start = tunable.initial_blocks(self.loop.cfg)
        return {name: saved.get(name, value) for name, value in start.items()}

    def value(self, key: str) -> Any:
        block, name = split_key(key)
        return getattr(self.blocks()[block], name)

    def check(self, changes: Mapping[str, object], who: str = "") -> dict[str, SetBlock]:
        """The loop's commands giving the tuning blocks ``changes`` asks (block -> command),
        or CommandRefused; changes nothing."""
        if not isinstance(changes, Mapping) or not changes:
            raise CommandRefused("tuning: no changes given")
        current = self.blocks()
        per_block: dict[str, dict[str, Any]] = {}
        for key, value in changes.items():
            block, name = split_key(key)
            cfg = current[block]
            f = next(f for f in fields(cfg) if f.name == name)
            allowed = choices_of(f)
            if allowed is not None:
                if not isinstance(value, str):
                    raise CommandRefused(f"{key}: expected a name, one of {', '.join(map(str, allowed))}; "
                                         f"got {value!r}")
                v: Any = value
            else:
                v = number(key, value, isinstance(getattr(cfg, name), int))
            try:
                check_value(f, v, prefix=f"{block}.")
            except ValueError as e:
                raise CommandRefused(str(e)) from None
            per_block.setdefault(block, {})[name] = v
        out: dict[str, SetBlock] = {}
        for block, vals in per_block.items():
            try:
                new = dataclasses.replace(current[block], **vals)
            except ValueError as e:
                raise CommandRefused(f"{block}.{e}" if not str(e).startswith(block) else str(e)) from None
            out[block] = SetBlock(block, new, who)  # an MPC configuration the planner refuses fails here
            if block == "mpc":
                f = new.formulation
                if f != current["mpc"].formulation and not self.planner_ready(f):
                    raise CommandRefused(
                        f"mpc.formulation: the {f} planner is still being compiled in the background "
                        "(a compile here would hold the loop for a minute); try again when the "
                        "console's terminal says it is compiled")
        return out

    def commands(self, blocks: Mapping[str, Any], who: str) -> dict[str, SetBlock]:
        """The loop's commands giving ``blocks`` (block -> config, e.g. the saved tuning)."""
        return {block: SetBlock(block, cfg, who) for block, cfg in blocks.items()}

    def apply(self, commands: Mapping[str, SetBlock], who: str) -> dict[str, list[Any]]:
        """Submit checked commands (:meth:`check`) to the loop and journal them; the changed
        fields (key -> [old, new])."""
        diffs: dict[str, list[Any]] = {}
        with self._lock:
            current = self.blocks()
            for block, command in commands.items():
                old = current[block]
                new = command.cfg
                if new == old:
                    continue
                self.loop.submit(command)
                for f in fields(new):
                    a, b = getattr(old, f.name), getattr(new, f.name)
                    if a != b:
                        diffs[f"{block}.{f.name}"] = [a, b]
        for key, (a, b) in diffs.items():
            self.journal.add(who, key, a, b)
        return diffs

    def save(self, who: str) -> None:
        """The present tuning becomes the one to revert to."""
        with self._lock:
            self._saved = self.blocks()
        self.journal.add(who, "tuning", "saved", "baseline")
