"""The run library's query language, translated to parameterised SQL: :func:`parse`.

A query is terms separated by spaces, all of which a session must match::

    mode=mpc speed>0.15 tag:pool-3 plant=plate_cd0.05 date>=2026-12-01 notes~"weak fin" -tag:draft

* ``FIELD OP VALUE`` with OP one of ``= != < <= > >= ~`` (``~``: contains); numbers compare
  as numbers, dates (``date``: ``YYYY-MM-DD``, UTC) as dates, text case-insensitively.
  A field of several values (``mode``, ``tag``, ``failsafe``, ``segment``) matches when one
  of its values does (``!=``: when none does). A session without a figure (a run never
  driven) matches no comparison of it;
* ``tag:X`` is ``tag=X``;
* a term starting with ``-`` is negated (``-tag:draft``, ``-mode=baseline``);
* any other word matches the notes, the session id, the manoeuvre or the configuration's name
  (contains, case-insensitive).

Quotes group words (``notes~"weak fin"``): the terms are split by :func:`shlex.split`
(POSIX shell quoting, stdlib). Each term is one match of a regular expression; the grammar
is flat (a conjunction, no nesting), which a parser library (pyparsing, lark: not
dependencies of the console) would not make shorter or clearer. Every value reaches SQL as
a parameter, never formatted into the text; field names come from :data:`FIELDS` only.
A bad term raises :class:`QueryError` naming it and the known fields.
"""

from __future__ import annotations

import datetime as dt
import math
import re
import shlex
from dataclasses import dataclass

#: kinds of field
NUMBER, TEXT, DATE, MANY = "number", "text", "date", "many"


@dataclass(frozen=True)
class Field:
    column: str  # the sessions table's column; for MANY the ``vals`` table's field name
    kind: str
    doc: str
    unit: str = ""


#: the fields a query (and ``--sort``) may name
FIELDS: dict[str, Field] = {
    "id": Field("id", TEXT, "session id"),
    "date": Field("date", DATE, "the day it started (UTC, YYYY-MM-DD)"),
    "start": Field("start", NUMBER, "when it started (UNIX s)", "s"),
    "duration": Field("duration", NUMBER, "length", "s"),
    "size": Field("size", NUMBER, "bytes of its parts", "B"),
    "parts": Field("parts", NUMBER, "part files"),
    "status": Field("status", TEXT, "ok, truncated, recording or unreadable"),
    "robot": Field("robot", TEXT, "sim, sim-devices or hardware"),
    "plant": Field("plant", TEXT, "the simulated plant's variant (plate_cd0.05, still_water, ...)"),
    "config": Field("config", TEXT, "the configuration's name (when known)"),
    "hash": Field("config_hash", TEXT, "sha256 of the recorded configuration (= matches a prefix)"),
    "formulation": Field("formulation", TEXT, "the MPC's cost formulation"),
    "mode": Field("mode", MANY, "a mode used (mpc, mpc_sync, baseline ...)"),
    "manoeuvre": Field("manoeuvre", TEXT, "the scripted manoeuvre's name"),
    "segment": Field("segment", MANY, "a measured segment's label"),
    "segments": Field("segments", NUMBER, "measured segments"),
    "operator": Field("operator", TEXT, "the operator's name"),
    "notes": Field("notes", TEXT, "the notes (the library's, else the recorded ones)"),
    "tag": Field("tag", MANY, "a tag"),
    "tags": Field("ntags", NUMBER, "how many tags"),
    "markers": Field("markers", NUMBER, "markers (recorded and review markers)"),
    "failsafes": Field("failsafes", NUMBER, "failsafes triggered"),
    "failsafe": Field("failsafe", MANY, "a failsafe triggered, by name"),
    "epm": Field("epm", NUMBER, "energy per metre over the driven part", "J/m"),
    "epm_lo": Field("epm_lo", NUMBER, "its interval's low end", "J/m"),
    "epm_hi": Field("epm_hi", NUMBER, "its interval's high end", "J/m"),
    "cot": Field("cot", NUMBER, "cost of transport", "J/(kg m)"),
    "power": Field("power", NUMBER, "mean power", "W"),
    "speed": Field("speed", NUMBER, "mean speed over the driven part", "m/s"),
    "speed_mae": Field("speed_mae", NUMBER, "speed mean |error|", "m/s"),
    "depth_mae": Field("depth_mae", NUMBER, "depth mean |error|", "m"),
    "heading_mae": Field("heading_mae", NUMBER, "heading mean |error|", "rad"),
    "st_mae": Field("st_mae", NUMBER, "St mean |St - St_opt|"),
    "st_in": Field("st_in", NUMBER, "strokes in the St corridor", "%"),
}
ALIASES = {"energy_per_metre": "epm", "cost_of_transport": "cot", "config_hash": "hash", "modes": "mode"}
OPS = ("!=", "<=", ">=", "=", "<", ">", "~")
_TERM = re.compile(r"^(?P<field>[A-Za-z_][A-Za-z0-9_]*)(?P<op>!=|<=|>=|=|<|>|~)(?P<value>.*)$", re.S)
_SQL_OP = {"=": "=", "!=": "!=", "<": "<", "<=": "<=", ">": ">", ">=": ">="}


class QueryError(ValueError):
    """A query refused: names the term and what is wrong."""


@dataclass(frozen=True)
class Query:
    """A parsed query: ``where`` (SQL over the ``sessions`` table ``s``) and its parameters."""

    text: str
    where: str
    params: tuple[object, ...]


def known() -> str:
    return ", ".join(FIELDS)


def field(name: str, what: str = "field") -> Field:
    """The field ``name`` (or an alias of it); QueryError naming the known ones."""
    f = FIELDS.get(ALIASES.get(name, name))
    if f is None:
        raise QueryError(f"{what} {name!r}: no such field; known fields: {known()}")
    return f


def _like(text: str) -> str:
    """``text`` as a LIKE pattern matching it anywhere (its %, _ and \\ escaped)."""
    return "%" + text.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"


def _number(term: str, name: str, f: Field, value: str) -> float:
    try:
        v = float(value)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise QueryError(f"term {term!r}: {name} is a number{f' ({f.unit})' if f.unit else ''}; "
                         f"{value!r} is not a finite number")
    return v


def _date(term: str, value: str) -> str:
    try:
        return dt.date.fromisoformat(value).isoformat()
    except ValueError:
        raise QueryError(f"term {term!r}: date is a day, YYYY-MM-DD (e.g. 2026-12-01); {value!r} is not one") from None


def _term(term: str) -> tuple[str, list[object]]:
    negate = term.startswith("-") and len(term) > 1
    body = term[1:] if negate else term
    if body.startswith("tag:"):
        body = "tag=" + body[4:]
    m = _TERM.match(body)
    if m is None:
        if any(op in body for op in OPS) or ":" in body:
            raise QueryError(f"term {term!r}: expected FIELD OP VALUE (OP one of {' '.join(OPS)}), tag:NAME "
                             f"or a word; known fields: {known()}")
        sql = ("(s.notes LIKE ? ESCAPE '\\' OR s.id LIKE ? ESCAPE '\\' OR s.manoeuvre LIKE ? ESCAPE '\\' "
               "OR s.config LIKE ? ESCAPE '\\')")
        pat = _like(body)
        return (f"NOT {sql}" if negate else sql), [pat] * 4
    name, op, value = m["field"].lower(), m["op"], m["value"]
    f = field(name, f"term {term!r}: field")
    if value == "":
        raise QueryError(f"term {term!r}: no value after {op!r}")
    params: list[object]
    if f.kind == MANY:
        if op not in ("=", "!=", "~"):
            raise QueryError(f"term {term!r}: {name} holds several values; compare it with =, != or ~")
        test = "v.value = ? COLLATE NOCASE" if op != "~" else "v.value LIKE ? ESCAPE '\\'"
        sql = f"EXISTS (SELECT 1 FROM vals v WHERE v.id = s.id AND v.field = '{f.column}' AND {test})"
        if op == "!=":
            sql = "NOT " + sql
        params = [value if op != "~" else _like(value)]
    elif f.kind == NUMBER:
        if op == "~":
            raise QueryError(f"term {term!r}: {name} is a number; ~ (contains) is for text")
        sql = f"s.{f.column} {_SQL_OP[op]} ?"
        params = [_number(term, name, f, value)]
    elif f.kind == DATE:
        if op == "~":
            raise QueryError(f"term {term!r}: date is a day; compare it with = != < <= > >=")
        sql = f"s.{f.column} {_SQL_OP[op]} ?"
        params = [_date(term, value)]
    else:
        if op == "~":
            sql, params = f"s.{f.column} LIKE ? ESCAPE '\\'", [_like(value)]
        elif op == "=" and f.column == "config_hash":
            sql, params = f"s.{f.column} LIKE ? ESCAPE '\\'", [_like(value.lower())[1:]]
        else:
            sql, params = f"s.{f.column} {_SQL_OP[op]} ? COLLATE NOCASE", [value]
        if op == "!=":
            sql = f"(s.{f.column} IS NULL OR {sql})"
    return (f"NOT ({sql})" if negate else sql), params


def parse(text: str) -> Query:
    """The query ``text`` (module docstring) as SQL; QueryError naming a bad term."""
    if not isinstance(text, str):
        raise QueryError(f"query: expected text, got {type(text).__name__}")
    try:
        terms = shlex.split(text)
    except ValueError as e:
        raise QueryError(f"query {text!r}: {e} (close the quote)") from None
    where, params = [], []
    for term in terms:
        sql, p = _term(term)
        where.append(sql)
        params += p
    return Query(text, " AND ".join(where) if where else "1", tuple(params))


def order_by(sort: str | None, desc: bool = False) -> str:
    """The ORDER BY clause of ``--sort`` (a scalar field; default: start), sessions without
    the value last; QueryError naming a field that is not one."""
    name = sort or "start"
    f = field(name, "--sort:")
    if f.kind == MANY:
        raise QueryError(f"--sort {name!r}: it holds several values; sort by a field of one value "
                         f"({', '.join(k for k, v in FIELDS.items() if v.kind != MANY)})")
    direction = "DESC" if desc else "ASC"
    return f"s.{f.column} IS NULL, s.{f.column} {direction}, s.id {direction}"
