"""What the page's markdown elements say: text built from the supervisor's and the sessions'
state, everything from outside escaped (:func:`esc`)."""

from __future__ import annotations

import contextlib
import html
from typing import Any

from ucat_console.backend.safety import FailsafeState
from ucat_console.backend.sessions import index
from ucat_console.backend.sessions.markers import Marker
from ucat_console.backend.sessions.replay import ReplayResult
from ucat_console.backend.supervisor import JournalEntry
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import FinPlan


def esc(text: object) -> str:
    """Text made safe for a markdown element (no HTML, no markdown markup)."""
    s = html.escape(str(text), quote=False)  # the page decodes &lt; &gt; &amp; but shows &#x27; as is
    for c in "\\`*_{}[]()#+!|~>":
        s = s.replace(c, "\\" + c)
    return s


def _set(handle: Any, content: str) -> None:
    if handle.content != content:
        handle.content = content


def within(container: Any) -> Any:
    """``with within(container):`` enters the container when one is given."""
    return contextlib.nullcontext() if container is None else container




def introspection_markdown(plans: list[FinPlan | None], late_plans: int, overruns: int, mode: str) -> str:
    """Each fin's last plan: strokes and rates, cost split, solve time, late flag."""
    lines = [
        f"Mode **{esc(mode)}** · late plans **{late_plans}** · hand-over overruns **{overruns}**",
        "",
        "| fin | St | d1, d2 (rad) | w1, w2 (rad/s) | cost F / St / A / D = total | solve ms | late |",
        "|---|---|---|---|---|---|---|",
    ]
    baseline = []
    for i, p in enumerate(plans):
        if p is None:
            lines.append(f"| {i} | - | - | - | - | - | - |")
            continue
        d1, d2, w1, w2 = p.u
        lines.append(
            f"| {i} | {p.st:.3f} | {d1:+.2f}, {d2:+.2f} | {w1:.2f}, {w2:.2f} | "
            f"{p.cost_force:.3g} / {p.cost_strouhal:.3g} / {p.cost_amplitude:.3g} / {p.cost_smoothness:.3g}"
            f" = {p.cost_total:.3g} | {p.solve_time * 1e3:.1f} | {'yes' if p.late else 'no'} |"
        )
        if p.mode == "baseline":
            baseline.append(f"fin {i}: amplitude {p.amplitude:.2f} rad, centre {p.centre:+.2f} rad")
    if baseline:
        lines += ["", "Baseline: " + "; ".join(baseline)]
    return "\n".join(lines)


def failsafe_markdown(states: list[FailsafeState], now: float) -> str:
    lines = ["| failsafe | action | after | state | cause |", "|---|---|---|---|---|"]
    for s in states:
        state = f"**ACTIVE** {now - s.since:.0f} s" if s.active and s.since is not None else "ok"
        lines.append(f"| {s.name} | {s.action} | {s.timeout:g} s | {state} | {esc(s.cause) if s.active else ''} |")
    return "\n".join(lines)


def journal_markdown(entries: list[JournalEntry]) -> str:
    if not entries:
        return "Journal: no changes yet."
    return "Journal (newest first):\n\n" + "\n".join(f"- {esc(e.text())}" for e in reversed(entries))


def events_markdown(events: list[Event]) -> str:
    """The events, newest first, one list item each (the time unpadded: a list item whose
    text starts with four spaces would be a code block, its escapes shown as they are)."""
    if not events:
        return "No events yet."
    out = []
    for e in reversed(events):
        mark = "**" if e.level in ("error", "fatal") else ""
        out.append(f"- {e.t:.1f} s {mark}{esc(e.source)} {esc(e.code)}{mark}: {esc(e.message)}")
    return "\n".join(out)


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    return f"{n} B"


def _opt(v: float | int | None, fmt: str) -> str:
    return "?" if v is None else format(v, fmt)


def sessions_markdown(sessions: list[index.SessionInfo], skipped: list[index.Skipped] = ()) -> str:
    """The session browser's table, and the folder's entries that were not read and why."""
    notes = [f"- not read: {esc(k.name)}: {esc(k.why)}" for k in skipped]
    if not sessions:
        return "\n".join(["No recorded sessions.", "", *notes]) if notes else "No recorded sessions."
    lines = ["| session | part | duration | size | events | notes |", "|---|---|---|---|---|---|"]
    for s in sessions:
        for p in s.parts:
            dur = ("recording" if p.recording else "truncated (repair)" if p.repairable else "truncated") \
                if p.truncated else (f"{p.duration:.1f} s" if p.duration is not None else "?")
            if p.original_of:
                dur += f"; the original of {p.original_of}, kept by its repair"
            if p.error:
                dur = "unreadable: " + p.error
            lines.append(f"| {esc(s.session_id)} | {p.part} | {esc(dur)} | {_size(p.size)} | "
                         f"{_opt(p.events, 'd')} | {esc(p.notes)} |")
    return "\n".join(lines + ([""] + notes if notes else []))


def replay_markdown(result: ReplayResult, weights: dict[str, float]) -> str:
    """Recorded and counterfactual St, force error and predicted power, per fin and overall."""
    changed = ", ".join(f"{k} = {v:g}" for k, v in weights.items()) or "the recorded weights"
    head = f"Counterfactual with {esc(changed)}: {len(result.rows)} plans"
    if result.skipped:
        head += f", {result.skipped} not replayed (see the log)"
    if not result.rows:
        return head + "; no fin plans in this session."
    lines = [head, "",
             "| fin | plans | St rec | St new | force err rec (N) | force err new (N) | P rec (W) | P new (W) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in result.summary():
        lines.append(
            f"| {r['fin']} | {r['plans']} | {r['recorded_st']:.3f} | {r['st']:.3f} | "
            f"{r['recorded_force_error']:.4f} | {r['force_error']:.4f} | "
            f"{r['recorded_power']:.3f} | {r['power']:.3f} |"
        )
    return "\n".join(lines)


def _describe(what: Event | Marker, origin: float = 0.0) -> str:
    """An event or a review marker, at its time from ``origin`` (a session's start)."""
    if isinstance(what, Marker):
        return f"marker at {what.t - origin:.2f} s: {what.note or '(no note)'}"
    return f"event at {what.t - origin:.2f} s: {what.source}/{what.code} {what.message}"
