"""A run's report: one self-contained HTML file per session (summary, timeline, plots, figures).

:func:`write_report` reads a session once (the run library's reader of facts,
:func:`~ucat_console.backend.sessions.library_read.read_facts`, which hands each record it
reads on to the report) and writes ``<session id>.report.html``: the run's summary (the
library's facts, the sidecar's notes and tags, the figures over the driven part with their
intervals), a timeline (table and strip plot) of mode, tuning and setpoint changes,
markers, manoeuvre segments, seek candidates and failsafes, the tracking, power and
Strouhal plots over time (:mod:`.run_report_plots`), each fin's figures, the Table V figures per manoeuvre segment
(the rows of ``sessions compare``, :func:`~ucat_console.backend.review.compare.table`) or
over the driven run, and the recorded configuration.

The file holds everything: inline CSS, the plots as PNG data URIs (matplotlib's Agg, as
``sessions compare``'s), no script. Every text from the session (notes, event messages, the
configuration) is escaped: a session file is untrusted input. What a session lacks (no
power messages, never driven, no configuration, no matplotlib) is said in the report's
*Missing* box; a session that cannot be read (truncated, not a session) is a ValueError
naming its file. The file is written to a temporary file beside it and renamed, so a
report is whole or absent.

:class:`ReportWriter` writes a report when a recording stops (the supervisor hands it the
recorder's stops): a background thread waits for a child process that writes it, so it
never runs in, nor holds the interpreter from, the loop's, the page's or DISARM's thread; a
failure is logged once and goes no further.
"""

from __future__ import annotations

import html
import logging
import math
import multiprocessing as mp
import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ucat_console.backend.review import compare
from ucat_console.backend.review.export import FIN_COLUMNS, ROBOT_COLUMNS, cell
from ucat_console.backend.review.metrics import FIGURES, MetricsConfig, RunData, TableRow, fin_energies
from ucat_console.backend.review.run_report_plots import (
    TimelineItem,
    power_png,
    strouhal_png,
    timeline_png,
    tracking_png,
)
from ucat_console.backend.review.trend import can_plot
from ucat_console.backend.sessions import files, sidecar
from ucat_console.backend.sessions.library_read import Facts, read_facts, recorded_metrics
from ucat_console.backend.sessions.markers import MarkerStore
from ucat_console.backend.sessions.reader import Record, SessionParts
from ucat_console.robot.fins import N_FINS
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.events import Event

log = logging.getLogger(__name__)

#: a report's file name after the session id
SUFFIX = ".report.html"
#: the most timeline rows listed (the strip plot shows them all)
MAX_TIMELINE_ROWS = 2000


def report_path(session_id: str, sessions_dir: str | Path | None = None) -> Path:
    """Where a session's report is written by default: beside its parts."""
    return files.sessions_dir(sessions_dir) / f"{session_id}{SUFFIX}"


@dataclass
class _Collected:
    """What the report needs beyond the facts, from the same records."""

    data: RunData = field(default_factory=RunData)
    events: list[Event] = field(default_factory=list)
    tracking: list[tuple[float, ...]] = field(default_factory=list)  # t, driving, refs, errors

    def feed(self, r: Record) -> None:
        m = r.message
        if r.channel == ch.EVENTS:
            self.events.append(m)
            return
        if r.channel == ch.BODY_TRACKING:
            self.tracking.append((m.t, float(m.driving), m.speed_ref, m.depth_ref, m.heading_ref,
                                  m.speed_error, m.depth_error, m.heading_error))
        self.data.feed(r.channel, m)


# ---- reading ---------------------------------------------------------------------------------------


def _kind(e: Event) -> str | None:
    if e.source == "failsafe":
        return "failsafe"
    if e.source == "manoeuvre":
        return "segment" if e.code == "segment" else "marker" if e.code == "manoeuvre" else None
    if e.source == "seek":
        return "seek"
    if e.code in ("armed", "disarmed"):
        return "armed"
    return e.code if e.code in ("mode", "tuning", "setpoints", "marker") else None


def timeline(events: Iterable[Event], origin: float, review_markers: Iterable[Any] = ()) -> list[TimelineItem]:
    """The events the timeline shows (module docstring) and the review markers, in time order."""
    out = []
    for e in events:
        kind = _kind(e)
        if kind is None:
            continue
        t1 = e.data.get("t1") if kind == "segment" and isinstance(e.data, dict) else None
        t0 = e.data.get("t0") if kind == "segment" and isinstance(e.data, dict) else None
        t = float(t0) if _finite(t0) else e.t
        out.append(TimelineItem(t - origin, kind, f"{e.source}/{e.code}", str(e.message),
                                float(t1) - origin if _finite(t1) else None))
    for m in review_markers:
        out.append(TimelineItem(m.t - origin, "marker", "review marker", m.note))
    return sorted(out, key=lambda i: i.t)


def _finite(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def segment_windows(run: compare.Run, events: Sequence[Event],
                    driven: tuple[float, float] | None) -> list[compare.Window]:
    """The manoeuvre's measured segments as compare's windows (their recorded ``t0``/``t1``,
    else from one segment event to the next or to the driven part's end); none: the driven
    run whole (no window when it was never driven)."""
    segs = [e for e in events if e.source == "manoeuvre" and e.code == "segment"]
    wins = []
    for k, e in enumerate(segs):
        d = e.data if isinstance(e.data, dict) else {}
        t0, t1 = d.get("t0"), d.get("t1")
        if not (_finite(t0) and _finite(t1)):
            t0 = e.t
            t1 = segs[k + 1].t if k + 1 < len(segs) else (driven[1] if driven else run.end)
        t0, t1 = max(float(t0), run.start), min(float(t1), run.end)
        if t1 > t0:
            label = f"#{k + 1} {d.get('label') or e.message}"
            wins.append(compare.Window(run, str(label), t0, t1, t0))
    if not wins and driven is not None:
        wins.append(compare.Window(run, "driven run", driven[0], driven[1], driven[0]))
    return wins


# ---- HTML ------------------------------------------------------------------------------------------

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:1.5em auto;max-width:1100px;color:#222;
padding:0 1em}h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.8em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}th,td{border:1px solid #ddd;padding:.25em .5em;
text-align:left;vertical-align:top}th{background:#f3f3f3}td.n{text-align:right;font-variant-numeric:tabular-nums}
.missing{background:#fff4e5;border:1px solid #f0b36b;padding:.5em 1em}img{max-width:100%}
pre{background:#f7f7f7;border:1px solid #ddd;padding:.8em;overflow:auto;font-size:.8em}
.bad{color:#b00}.small{font-size:.85em;color:#555}
"""


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _table(head: Sequence[str], rows: Iterable[Sequence[object]], numeric: Sequence[bool] = ()) -> str:
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(
            f"<td{' class=n' if k < len(numeric) and numeric[k] else ''}>{_e(v)}</td>" for k, v in enumerate(r))
            + "</tr>")
    return "".join(out) + "</table>"


def _when(t: float | None) -> str:
    if t is None or not math.isfinite(t):
        return "?"
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(t))


def _num(v: float, fmt: str = ".3g") -> str:
    return format(v, fmt) if math.isfinite(v) else "–"


@dataclass(frozen=True)
class _Summary:
    notes: str
    operator: str
    tags: tuple[str, ...]


def _summary_html(f: Facts, s: _Summary, origin: float, duration: float, driven_row: TableRow | None,
                  cfg: MetricsConfig) -> str:
    rows = [
        ("session", f.session_id), ("start", _when(f.start)), ("duration", f"{duration:.1f} s"),
        ("parts", f"{f.parts} ({f.size / 1e6:.1f} MB)"), ("robot", f.robot or "?"), ("plant", f.plant or "?"),
        ("configuration", f.config or "(unnamed)"), ("configuration hash (sha256)", f.config_hash or "(none)"),
        ("modes", ", ".join(f.modes) or "?"), ("MPC formulation", f.formulation or "?"),
        ("manoeuvre", f.manoeuvre or "–"), ("operator", s.operator or "–"), ("notes", s.notes or "–"),
        ("tags", ", ".join(s.tags) or "–"), ("markers (recorded)", f.markers),
        ("failsafes", ", ".join(f.failsafes) or "none"),
        ("driven part", f"{f.driven[0] - origin:.1f}–{f.driven[1] - origin:.1f} s" if f.driven else "never driven"),
    ]
    out = "<h2>Summary</h2>" + _table(("", ""), rows)
    if driven_row is None:
        return out + f"<p>No figures: {_e(f.figures_note.removeprefix('no figures: '))}.</p>"
    conf = f"{cfg.confidence * 100:g}%"
    out += (f"<h3>Figures over the driven run</h3><p class=small>With their {conf} bootstrap interval over "
            f"{driven_row.cycles} cycles ({cfg.resamples} resamples); power: {_e(driven_row.source_label)}; "
            f"cost of transport with mass {cfg.mass:g} kg.</p>")
    return out + _table(("figure", "value [interval]", "unit"),
                        ((FIGURES[k][0], cell(driven_row, k), FIGURES[k][1]) for k in ROBOT_COLUMNS))


def _timeline_html(items: Sequence[TimelineItem], png: str | None) -> str:
    out = "<h2>Timeline</h2>"
    if png:
        out += f'<img alt="timeline" src="{png}">'
    if not items:
        return out + "<p>No mode or tuning changes, markers, segments, seeks or failsafes.</p>"
    shown = items[:MAX_TIMELINE_ROWS]
    out += _table(("time (s)", "kind", "source/code", "what"),
                  ((f"{i.t:.2f}" + (f"–{i.t1:.2f}" if i.t1 is not None else ""), i.kind, i.what, i.message)
                   for i in shown), (True,))
    if len(items) > len(shown):
        out += f"<p>{len(items) - len(shown)} more events not listed (the strip plot shows them all).</p>"
    return out


def _fins_html(d: RunData, driven: tuple[float, float] | None, row: TableRow | None) -> str:
    out = "<h2>Per fin</h2>"
    if driven is None or row is None:
        return out + "<p>No figures: the fins were never driven or there are no power messages.</p>"
    energy = fin_energies(d, driven[0], driven[1], row.source)
    cycles = [int(np.count_nonzero((c.col("t") >= driven[0]) & (c.col("t") <= driven[1]))) if len(c) else 0
              for c in d.cycles]
    out += f"<p class=small>Over the driven run; energy and power: {_e(row.source_label)}.</p>"
    return out + _table(
        ("fin", "energy (J)", "mean power (W)", "St in corridor (%)", "St MAE", "cycles"),
        ((i, _num(energy[i], ".4g"), cell(row, f"power_{i}"), cell(row, f"st_in_{i}"), cell(row, f"st_mae_{i}"),
          cycles[i]) for i in range(N_FINS)), (True,) * 6)


def _segments_html(rows: Sequence[TableRow], origin: float, cfg: MetricsConfig, error: str) -> str:
    out = "<h2>Table V figures</h2>"
    if error:
        return out + f"<p>No figures: {_e(error)}</p>"
    if not rows:
        return out + "<p>No figures: the fins were never driven.</p>"
    conf = f"{cfg.confidence * 100:g}%"
    out += (f"<p class=small>Per manoeuvre segment, or over the driven run when there are none; each figure "
            f"with its {conf} bootstrap interval over cycles; power: {_e(rows[0].source_label)}. A row is "
            f"<i>not comparable</i> with the first when its tracking differs beyond the configured bounds.</p>")
    head = ["segment", "window (s)", "cycles", *(f"{FIGURES[k][0]} ({FIGURES[k][1]})" for k in ROBOT_COLUMNS),
            "comparable"]
    out += _table(head, ((r.label, f"{r.t0 - origin:.1f}–{r.t1 - origin:.1f}", r.cycles,
                          *(cell(r, k) for k in ROBOT_COLUMNS), r.not_comparable or "yes") for r in rows))
    head = ["segment", *(f"fin {i} {FIGURES[k][0]} ({FIGURES[k][1]})" for i in range(N_FINS) for k in FIN_COLUMNS)]
    return out + _table(head, ((r.label, *(cell(r, f"{k}_{i}") for i in range(N_FINS) for k in FIN_COLUMNS))
                               for r in rows))


# ---- the report --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Report:
    """A report made: its file, its session, what it says is missing, and how long it took."""

    path: Path
    session_id: str
    missing: tuple[str, ...]
    seconds: float


def _side(directory: Path, f: Facts, missing: list[str]) -> _Summary:
    try:
        side = sidecar.read(directory, f.session_id)
    except ValueError as e:
        missing.append(f"the tags and notes given after recording: {e}")
        side = sidecar.Sidecar()
    return _Summary(side.notes if side.notes is not None else f.notes,
                    side.operator if side.operator is not None else f.operator, side.tags)


def render(session: str | Path, directory: str | Path | None = None, *, confined: bool = False,
           known_configs: Mapping[str, str] | None = None) -> tuple[str, Path, str, tuple[str, ...]]:
    """(session id, the folder of its parts, the report's HTML, what it says is missing) of a
    session (an id or any part file); ValueError naming the file when it cannot be read."""
    root = files.sessions_dir(directory)
    with SessionParts(session, root, confined=confined) as s:  # truncated, foreign: an error naming the file
        sid, paths, origin, end = s.session_id, list(s.paths), s.start, s.end
    got = _Collected()
    facts = read_facts(sid, paths, paths[0].parent, known_configs=known_configs, on_record=got.feed)
    if facts.status != "ok":
        raise ValueError(f"{paths[0]}: {facts.error}")
    missing: list[str] = []
    folder = paths[0].parent
    summary = _side(folder, facts, missing)
    try:
        review = MarkerStore(folder, sid).markers
    except ValueError as e:
        missing.append(f"the review markers: {e}")
        review = []
    if facts.error:
        missing.append(f"the configuration's facts: {facts.error}")
    if not facts.config_toml:
        missing.append("the configuration: the recording holds none")
    cfg = recorded_metrics(facts.config_toml)
    data = got.data
    run = compare.Run(sid, data, got.events, origin, origin, end)
    driven = facts.driven
    rows: list[TableRow] = []
    driven_row: TableRow | None = None
    error = ""
    if len(data.power) == 0:
        error = "no power messages: the efficiency cannot be computed"
        missing.append(f"the figures: {error}")
    elif driven is None:
        missing.append("the figures: the fins were never driven")
    else:
        try:
            rows = compare.table(segment_windows(run, got.events, driven), cfg)
            whole = [compare.Window(run, "driven run", driven[0], driven[1], driven[0])]
            driven_row = rows[0] if rows[0].label == "driven run" else compare.table(whole, cfg)[0]
        except ValueError as e:
            error = str(e)
            missing.append(f"the figures: {error}")
    if not got.tracking:
        missing.append("the tracking plot: no body/tracking messages")
    if not any(len(s) for s in data.strokes):
        missing.append("the Strouhal plot: no strokes (fin/<i>/strouhal)")
    if len(data.electrical) == 0:
        missing.append("electrical power: no power/electrical messages (the figures are of the shaft estimate)")
    items = timeline(got.events, origin, review)
    pngs: dict[str, str] = {}
    if not can_plot():
        missing.append("the plots: matplotlib is not installed (pip install 'ucat-console[experiments]')")
    else:
        pngs["timeline"] = timeline_png(items, end - origin)
        if got.tracking:
            pngs["tracking"] = tracking_png(got.tracking, origin, driven)
        pngs["power"] = power_png(data, origin, driven)
        pngs["strouhal"] = strouhal_png(data, origin)
    parts = [
        "<!DOCTYPE html><html lang=en><head><meta charset=utf-8>",
        f"<title>Run {_e(sid)}</title><style>{_CSS}</style></head><body>",
        f"<h1>Run {_e(sid)}</h1><p class=small>{_e(', '.join(p.name for p in paths))}; report made "
        f"{_e(_when(time.time()))}; times are session time (s from the session's start).</p>",
    ]
    if missing:
        parts.append("<div class=missing><b>Missing</b><ul>" + "".join(f"<li>{_e(m)}</li>" for m in missing)
                     + "</ul></div>")
    parts.append(_summary_html(facts, summary, origin, end - origin, driven_row, cfg))
    parts.append(_timeline_html(items, pngs.get("timeline")))
    for key, title in (("tracking", "Tracking"), ("power", "Power"), ("strouhal", "Strouhal number per stroke")):
        if key in pngs:
            parts.append(f'<h2>{title}</h2><img alt="{key}" src="{pngs[key]}">')
    parts.append(_fins_html(data, driven, driven_row))
    parts.append(_segments_html(rows, origin, cfg, error))
    parts.append("<h2>Configuration</h2>" + (f"<pre>{_e(facts.config_toml)}</pre>" if facts.config_toml
                                             else "<p>The recording holds no configuration.</p>"))
    parts.append("</body></html>\n")
    return sid, folder, "".join(parts), tuple(missing)


def write_atomic(path: Path, text: str) -> None:
    """``text`` into ``path`` through a temporary file beside it, renamed over it (whole or absent)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_report(session: str | Path, out: str | Path | None = None, directory: str | Path | None = None, *,
                 confined: bool = False, known_configs: Mapping[str, str] | None = None) -> Report:
    """Write the report of ``session`` (an id or any part file) to ``out`` (None: beside its
    parts as ``<session id>.report.html``); ValueError naming the file when the session cannot
    be read or ``out``'s folder does not exist."""
    t0 = time.perf_counter()
    if out is not None and not Path(out).parent.is_dir():
        raise ValueError(f"{out}: no such directory {Path(out).parent}")
    sid, folder, text, missing = render(session, directory, confined=confined, known_configs=known_configs)
    path = Path(out) if out is not None else folder / f"{sid}{SUFFIX}"
    write_atomic(path, text)
    return Report(path, sid, missing, time.perf_counter() - t0)


#: how much lower than the console's the report's CPU priority is (os.nice steps)
NICE = 10
#: s, the longest a report may take before its process is ended
REPORT_TIMEOUT = 600.0


def _child(conn: Any, first: str, out: str, nice: int) -> None:
    try:
        os.nice(nice)
    except OSError:
        pass
    try:
        conn.send(("ok", write_report(first, out, Path(first).parent)))
    except Exception as e:  # the parent says it
        conn.send(("error", str(e) if isinstance(e, ValueError) else f"{type(e).__name__}: {e}"))
    finally:
        conn.close()


class ReportWriter:
    """Writes a session's report when its recording stops (:meth:`submit`, any thread; it
    returns at once): a background thread waits for a child process that writes it (started
    with ``spawn``, lowered by :data:`NICE` steps), so the report's reading, bootstrap and
    plotting never hold the console's interpreter (in a thread of the console's own process
    they stalled its other threads by up to half a second: docs/review.md). A failure is logged
    once, never raised; ``on_done(report_or_None, error)`` is told either way."""

    def __init__(self, on_done: Callable[[Report | None, str], None] = lambda r, e: None, *,
                 nice: int = NICE, timeout: float = REPORT_TIMEOUT) -> None:
        self._on_done = on_done
        self._nice = nice
        self._timeout = timeout
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []

    def submit(self, session_id: str, paths: Sequence[Path]) -> None:
        if not paths:
            return
        t = threading.Thread(target=self._write, args=(session_id, Path(paths[0])), daemon=True,
                             name=f"run-report-{session_id}")
        with self._lock:  # started before it is listed: a join never meets an unstarted thread
            t.start()
            self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _run_child(self, session_id: str, first: Path) -> tuple[Report | None, str]:
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(child, str(first), str(report_path(session_id, first.parent)),
                                                self._nice), name=f"run-report-{session_id}", daemon=True)
        proc.start()
        child.close()
        try:
            if not parent.poll(self._timeout):
                proc.kill()
                return None, f"not written within {self._timeout:g} s"
            kind, value = parent.recv()
        except EOFError:
            proc.join()
            return None, f"the report's process ended without a word (exit code {proc.exitcode})"
        finally:
            parent.close()
        proc.join()
        return (value, "") if kind == "ok" else (None, str(value))

    def _write(self, session_id: str, first: Path) -> None:
        try:
            report, error = self._run_child(session_id, first)
        except Exception as e:  # the process could not be started
            report, error = None, f"{type(e).__name__}: {e}"
        if report is None:
            log.warning("the report of session %s was not written: %s", session_id, error)
        else:
            log.info("report of session %s written to %s in %.1f s", session_id, report.path, report.seconds)
        self._on_done(report, error)

    def join(self, timeout: float | None = None) -> bool:
        """Wait for the reports being written (at most ``timeout`` s in all); whether all ended."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._lock:
            threads = list(self._threads)
        for t in threads:
            t.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
        return not any(t.is_alive() for t in threads)
