"""Scripted manoeuvres from their files: a shipped one by name (``e4_ladder``) or a TOML file.

:func:`load_script` reads the file, builds the :class:`~ucat_console.control.scripted.Script`
and checks each segment against the console's limits and modes with the loop's own checks
(the envelope ``SetSetpoints`` is checked against, the modes ``SetMode`` takes; a mode whose
fins do not follow the body loops, the identification manoeuvre, has no tracking to measure
and is refused). Every error names the file and the line: tomllib's for a syntax error; for a
bad value the segment's index (from 0), the line of its ``[[segment]]`` header in the text
and the key (and the key's own line when the segment sets it).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from ucat_console import shipped
from ucat_console.backend.loop.commands import SetMode, check_setpoints
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import mode
from ucat_console.control.scripted import Script, ScriptError, plan, script_of

_HEADER = re.compile(r"^\s*\[\[\s*segment\s*\]\]")
_TABLE = re.compile(r"^\s*\[")


def _key_line(lines: list[str], key: str, first: int, last: int) -> int | None:
    """The 1-based line of ``key = ...`` among ``lines[first:last]`` (None: not there)."""
    pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
    for n in range(first, min(last, len(lines))):
        if pattern.match(lines[n]):
            return n + 1
    return None


def where(text: str, e: ScriptError) -> str:
    """Where in ``text`` the error ``e`` is: ``segment 2 (line 14: [[segment]]), velocity
    (line 16)``, or the top-level key's line."""
    lines = text.splitlines()
    headers = [n for n, line in enumerate(lines) if _HEADER.match(line)]
    if e.segment is None:
        end = next((n for n, line in enumerate(lines) if _TABLE.match(line)), len(lines))
        line = _key_line(lines, e.key, 0, end) if e.key else None
        return f"line {line}" if line is not None else "top level"
    out = f"segment {e.segment}"
    if e.segment < len(headers):
        first = headers[e.segment]
        out += f" (line {first + 1}: [[segment]])"
        last = next((n for n in range(first + 1, len(lines)) if _TABLE.match(lines[n])), len(lines))
        line = _key_line(lines, e.key, first + 1, last) if e.key else None
        if line is not None:
            out += f", line {line}"
        elif e.key:  # a default from the top level
            top = _key_line(lines, e.key, 0, headers[0]) if headers else None
            if top is not None:
                out += f", its default at line {top}"
    return out


def _check_mode(name: str) -> None:
    SetMode(name)  # the loop's check: CommandRefused naming the modes there are
    if not mode(name).follows_targets:
        raise ValueError(f"mode: {name!r} does not follow the body loops: a manoeuvre has no tracking to measure")


def parse_script(text: str, name: str, loop: LoopConfig, source: str = "") -> Script:
    """The script in ``text`` (a manoeuvre file's contents) for a console with the loop
    configuration ``loop``; ValueError naming ``source`` (default ``name``) and the line."""
    source = source or name
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:  # its message carries the line and column
        raise ValueError(f"{source}: {e}") from None
    try:
        return script_of(name, table, envelope=lambda sp: check_setpoints(loop, sp), check_mode=_check_mode)
    except ScriptError as e:
        raise ValueError(f"{source}: {where(text, e)}: {e}") from None


def load_script(value: str | Path, loop: LoopConfig) -> Script:
    """The manoeuvre named ``value`` (a shipped one) or in the file ``value``, checked for a
    console with the loop configuration ``loop``."""
    path = shipped.manoeuvre_path(value)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"manoeuvre: {path}: no such file") from None
    except UnicodeDecodeError as e:
        raise ValueError(f"manoeuvre: {path}: not UTF-8 text ({e.reason})") from None
    return parse_script(text, path.stem, loop, str(path))


def shipped_plans(loop: LoopConfig) -> list[tuple[str, str]]:
    """Each shipped manoeuvre's name and plan (:func:`~ucat_console.control.scripted.plan`)."""
    return [(n, plan(load_script(n, loop))) for n in shipped.manoeuvre_names()]
