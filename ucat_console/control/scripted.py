"""Scripted manoeuvres: a sequence of segments, each a settle window then a measure window.

A :class:`Script` is what a manoeuvre file (docs/manoeuvres.md) describes once its kinds are
expanded: a tuple of :class:`Segment` s, each holding setpoints (and optionally a fin mode)
for ``settle_s`` then ``measure_s`` seconds. :func:`at` says where a script is ``t`` seconds
after its start; :func:`plan` lists it for people (what the arm confirmation shows).

:func:`script_of` builds a script from a manoeuvre file's table (already parsed): the kinds

* ``hold``: velocity, depth and yaw rate held;
* ``turn``: a hold with a non-zero ``yaw_rate``;
* ``ladder``: one segment per rung of ``speeds`` (m/s), the rest held;
* ``depth_step``: a hold at ``from_depth``, then one at ``to_depth``.

Top-level ``velocity``, ``depth``, ``yaw_rate``, ``settle``, ``measure`` and ``mode`` are
every segment's defaults. A bad table raises :class:`ScriptError` naming the segment (its
index, from 0, in the file's ``[[segment]]`` list) and the key. Nothing here reads a file,
a clock or the console's configuration: the envelope here is the widest one
(:class:`~ucat_console.control.allocation.BodySetpoints`); the console's own is checked
where a script is loaded for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.argcheck import finite, in_range

#: where a script is: settling into a segment, measuring it, or past its end
PHASES = ("settle", "measure", "done")
#: the kinds of segment a file may name
KINDS = ("hold", "turn", "ladder", "depth_step")
#: the longest a segment's window may be (s)
MAX_WINDOW = 3600.0
#: keys every segment takes, and those a kind adds
_COMMON = ("kind", "label", "velocity", "depth", "yaw_rate", "settle", "measure", "mode")
_KIND_KEYS = {"hold": (), "turn": (), "ladder": ("speeds",), "depth_step": ("from_depth", "to_depth")}
#: the keys a file's top level takes
TOP_KEYS = ("name", "description", "velocity", "depth", "yaw_rate", "settle", "measure", "mode", "segment")


class ScriptError(ValueError):
    """A manoeuvre table refused: ``segment`` (index in the file's list, None: the top
    level) and ``key`` say where."""

    def __init__(self, message: str, segment: int | None = None, key: str = "") -> None:
        super().__init__(message)
        self.segment = segment
        self.key = key


@dataclass(frozen=True)
class Segment:
    """Setpoints held for ``settle_s`` then ``measure_s`` seconds; ``mode`` the fin mode
    in force ("": the one in force when the script starts)."""

    label: str
    setpoints: BodySetpoints
    settle_s: float
    measure_s: float
    mode: str = ""
    #: the index of the file's ``[[segment]]`` entry it was made from
    source: int = 0

    def __post_init__(self) -> None:
        in_range("settle_s", self.settle_s, 0.0, MAX_WINDOW, unit="s")
        in_range("measure_s", self.measure_s, 0.0, MAX_WINDOW, lo_open=True, unit="s")

    @property
    def duration(self) -> float:
        return self.settle_s + self.measure_s


@dataclass(frozen=True)
class Script:
    """A named sequence of segments (module docstring)."""

    name: str
    segments: tuple[Segment, ...]
    description: str = ""

    def __post_init__(self) -> None:
        if not self.segments:
            raise ScriptError("segment: none; a manoeuvre needs at least one [[segment]]", None, "segment")

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segments)

    @property
    def starts(self) -> tuple[float, ...]:
        """Each segment's start, seconds from the script's."""
        out, t = [], 0.0
        for s in self.segments:
            out.append(t)
            t += s.duration
        return tuple(out)

    @property
    def modes(self) -> tuple[str, ...]:
        """The modes the segments name (each once, in order)."""
        return tuple(dict.fromkeys(s.mode for s in self.segments if s.mode))


@dataclass(frozen=True)
class Step:
    """Where a script is: segment ``index`` (``len(segments)`` once done), its phase, the
    setpoints and mode in force ("": the script's starting mode) and the phase's window
    ``[t0, t1]`` (seconds from the script's start)."""

    index: int
    phase: str
    setpoints: BodySetpoints
    mode: str
    t0: float
    t1: float


def at(script: Script, t: float) -> Step:
    """Where ``script`` is ``t`` s after its start (``t`` >= 0). A phase's window includes its
    start, not its end; from the total duration on: "done", with the last segment's
    setpoints and mode."""
    t = in_range("t", t, 0.0, unit="s")
    for k, (start, seg) in enumerate(zip(script.starts, script.segments)):
        measure = start + seg.settle_s
        if t < measure:
            return Step(k, "settle", seg.setpoints, seg.mode, start, measure)
        if t < measure + seg.measure_s:
            return Step(k, "measure", seg.setpoints, seg.mode, measure, measure + seg.measure_s)
    last = script.segments[-1]
    end = script.duration
    return Step(len(script.segments), "done", last.setpoints, last.mode, end, end)


def describe(seg: Segment) -> str:
    sp = seg.setpoints
    mode = f", mode {seg.mode}" if seg.mode else ""
    return (f"{seg.label}: velocity {sp.velocity:g} m/s, depth {sp.depth:g} m, yaw rate {sp.yaw_rate:g} rad/s"
            f"{mode}; settle {seg.settle_s:g} s, measure {seg.measure_s:g} s")


def plan(script: Script) -> str:
    """The script as lines of text: its name, length and each segment (the arm confirmation
    and ``ucat-console manoeuvres list`` show it)."""
    total = script.duration
    head = f"{script.name}: {len(script.segments)} segment{'s' if len(script.segments) != 1 else ''}, " \
           f"{total:g} s ({int(total // 60)} min {total % 60:g} s)"
    lines = [head]
    if script.description:
        lines.append(f"  {script.description}")
    lines += [f"  {k + 1}. {describe(s)}" for k, s in enumerate(script.segments)]
    return "\n".join(lines)


# ---- a manoeuvre file's table -------------------------------------------------------------------


def _number(table: Mapping[str, Any], key: str, segment: int | None, default: float | None) -> float:
    v = table.get(key, default)
    if v is None:
        where = f"segment {segment}" if segment is not None else "the file"
        raise ScriptError(f"{key}: missing in {where} (set it in the segment, or at the file's top level "
                          "for every segment)", segment, key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScriptError(f"{key}: expected a finite number, got {v!r}", segment, key)
    return float(v)


def _text(table: Mapping[str, Any], key: str, segment: int | None, default: str) -> str:
    v = table.get(key, default)
    if not isinstance(v, str):
        raise ScriptError(f"{key}: expected text, got {v!r}", segment, key)
    return v


#: a check the caller adds: the setpoints back, or ValueError naming the setpoint ("depth: ...")
Envelope = Callable[[BodySetpoints], BodySetpoints]
#: a check of a mode's name the caller adds: ValueError when the console has no such mode
ModeCheck = Callable[[str], None]


def _setpoints(k: int, velocity: float, depth: float, yaw_rate: float, keys: tuple[str, str, str],
               envelope: Envelope | None) -> BodySetpoints:
    try:
        sp = BodySetpoints(velocity, depth, yaw_rate)
        return sp if envelope is None else envelope(sp)
    except ValueError as e:
        key = str(e).split(":", 1)[0]
        given = dict(zip(("velocity", "depth", "yaw_rate"), keys)).get(key, key)
        raise ScriptError(str(e) if given == key else f"{given}: {e}", k, given) from None


def _segments(k: int, seg: Mapping[str, Any], top: Mapping[str, Any], envelope: Envelope | None,
              check_mode: ModeCheck | None) -> list[Segment]:
    if not isinstance(seg, Mapping):
        raise ScriptError(f"segment {k}: expected a table ([[segment]]), got {seg!r}", k, "")
    kind = _text(seg, "kind", k, "hold")
    if kind not in KINDS:
        raise ScriptError(f"kind: {kind!r} is not one of {', '.join(KINDS)}", k, "kind")
    allowed = (*_COMMON, *_KIND_KEYS[kind])
    for key in seg:
        if key not in allowed:
            raise ScriptError(f"{key}: not a key of a {kind} segment; allowed: {', '.join(allowed)}", k, key)

    def num(key: str, default: float | None) -> float:
        return _number(seg, key, k, top.get(key, default))

    label = _text(seg, "label", k, kind.replace("_", " "))
    mode = _text(seg, "mode", k, _text(top, "mode", None, ""))
    if mode and check_mode is not None:
        try:
            check_mode(mode)
        except ValueError as e:
            raise ScriptError(str(e), k, "mode") from None
    settle = num("settle", None)
    measure = num("measure", None)
    for key, v, lo_open in (("settle", settle, False), ("measure", measure, True)):
        try:
            in_range(key, v, 0.0, MAX_WINDOW, lo_open=lo_open, unit="s")
        except ValueError as e:
            raise ScriptError(str(e), k, key) from None
    yaw = num("yaw_rate", 0.0)

    def hold(lbl: str, velocity: float, depth: float, keys: tuple[str, str, str] = ("velocity", "depth", "yaw_rate")
             ) -> Segment:
        return Segment(lbl, _setpoints(k, velocity, depth, yaw, keys, envelope), settle, measure, mode, k)

    if kind == "ladder":
        speeds = seg.get("speeds")
        if not isinstance(speeds, list) or not speeds:
            raise ScriptError(f"speeds: expected a list of speeds (m/s), got {speeds!r}", k, "speeds")
        depth = num("depth", None)
        out = []
        for r, v in enumerate(speeds):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ScriptError(f"speeds: rung {r + 1} is {v!r}, not a number", k, "speeds")
            out.append(hold(f"{label} {float(v):g} m/s", float(v), depth, ("speeds", "depth", "yaw_rate")))
        return out
    velocity = num("velocity", 0.0)
    if kind == "depth_step":
        a, b = _number(seg, "from_depth", k, None), _number(seg, "to_depth", k, None)
        return [hold(f"{label} at {a:g} m", velocity, a, ("velocity", "from_depth", "yaw_rate")),
                hold(f"{label} to {b:g} m", velocity, b, ("velocity", "to_depth", "yaw_rate"))]
    if kind == "turn" and yaw == 0.0:
        raise ScriptError("yaw_rate: a turn needs a non-zero yaw rate (rad/s)", k, "yaw_rate")
    return [hold(label, velocity, num("depth", None))]


def script_of(name: str, table: Mapping[str, Any], envelope: Envelope | None = None,
              check_mode: ModeCheck | None = None) -> Script:
    """The script a manoeuvre file's table describes (module docstring); ScriptError naming
    the segment and the key of what is wrong. ``envelope`` and ``check_mode``: the caller's
    checks of each segment's setpoints and mode (the console's limits and modes)."""
    for key in table:
        if key not in TOP_KEYS:
            raise ScriptError(f"{key}: not a top-level key of a manoeuvre; allowed: {', '.join(TOP_KEYS)} "
                              "(a segment's keys go under [[segment]])", None, key)
    for key in ("velocity", "depth", "yaw_rate", "settle", "measure"):
        if key in table:
            finite(key, _number(table, key, None, None))
    title = _text(table, "name", None, name) or name
    description = _text(table, "description", None, "")
    segs = table.get("segment", [])
    if not isinstance(segs, list):
        raise ScriptError("segment: expected a list of tables ([[segment]] entries)", None, "segment")
    out: list[Segment] = []
    for k, seg in enumerate(segs):
        out.extend(_segments(k, seg, table, envelope, check_mode))
    return Script(title, tuple(out), description)
