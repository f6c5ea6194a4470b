"""``ucat-console bench report``: the one performance table, made from the benchmarks' JSON.

Each benchmark writes its figures as JSON (``--json benchmarks/NAME.json``); this module
reads those files and renders one Markdown table (measure, figure, goal, the command that
measures it), headed by the machine the figures come from. ``--write FILE...`` replaces
the table between the markers :data:`START` and :data:`END` in each file (the README and
docs/performance.md), so the table in the docs is always the files' figures, never typed
by hand. A benchmark whose file is missing is left out of the table.
"""

from __future__ import annotations

import argparse
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

START = "<!-- performance-table: made by `ucat-console bench report --write`; do not edit -->"
END = "<!-- performance-table end -->"


@dataclass(frozen=True)
class Row:
    measure: str
    figure: str
    goal: str
    command: str


def _mpc(d: dict[str, Any]) -> list[Row]:
    def run(formulation: str, solver: str = "numba") -> dict[str, Any] | None:
        return next((r for r in d["runs"] if r["n"] == 500 and r["solver"] == solver
                     and r["stage"] == "two_stage" and r["formulation"] == formulation), None)

    cmd = "`bench mpc`"
    out = []
    for formulation, label in (("paper", "the paper's cost"), ("closed_stroke", "closed-stroke cost")):
        r = run(formulation)
        if r is not None:
            out.append(Row(f"MPC solve, two-stage, N = 500, {label}: p50 / p99",
                           f"{r['p50_us']:.1f} / {r['p99_us']:.1f} us", "<= 80 / <= 200 us", cmd))
    shipped = d.get("shipped")
    if shipped:
        out.append(Row(f"the same, as {shipped['config']} runs it (the cycle centred by its cost over a "
                       f"{shipped['centre_grid']} x {shipped['centre_grid']} grid): p50 / p99",
                       f"{shipped['p50_us']:.1f} / {shipped['p99_us']:.1f} us",
                       "one plan per fin cycle (>= 0.25 s)", cmd))
    ref = run("paper", "scipy")
    if ref is not None:
        out.append(Row("the same, the paper's scipy path: p50", f"{ref['p50_us'] / 1000:.1f} ms",
                       "(paper: about 38 ms on a Jetson Orin Nano)", cmd))
    gap = d.get("quality_gap", {}).get("numba_n500")
    if gap:
        out.append(Row("MPC cost above the best found (fixed cases): mean", f"{gap['mean_gap']:.4f}",
                       "<= 0.005", cmd))
    first = d.get("first_call")
    if first:
        out.append(Row("first plan in a fresh process: from numba's cache / cold",
                       f"{first['cached_first_plan_s']:.2f} / {first['cold_first_plan_s']:.1f} s", "", cmd))
    return out


def _sim(d: dict[str, Any]) -> list[Row]:
    rt = d["realtime_factor"]
    modes = list(rt["headless"])
    return [Row(f"closed loop, real-time factor, {kind} ({', '.join(modes)})",
                ", ".join(f"{rt[kind][m]:,.0f}x" for m in modes),
                ">= 300x (>= 1000x headless)" if kind == "headless" else ">= 300x", "`bench sim`")
            for kind in ("headless", "subscribed") if kind in rt]


def _compile(d: dict[str, Any]) -> list[Row]:
    runs = {r["workers"]: r for r in d["runs"]}
    r = runs.get(2) or runs[max(runs)]
    n = r["workers"]
    return [Row(f"cold compile, {n} process{'es' if n > 1 else ''}: ready for the console / everything",
                f"{r['ready_s']:.1f} / {r['complete_s']:.1f} s", "", "`bench compile`")]


def _sessions(d: dict[str, Any]) -> list[Row]:
    out = []
    t = d.get("throughput")
    if t:
        out.append(Row("recorder throughput (dropped)", f"{t['rate_msgs_per_s']:,.0f} messages/s ({t['dropped']})",
                       ">= 20,000/s, 0 dropped", "`bench sessions`"))
    s = d.get("seek")
    if s:
        out.append(Row(f"seek in a {s['hours']:g}-hour session: median / p95",
                       f"{s['median_ms']:.1f} / {s['p95_ms']:.1f} ms", "<= 50 ms median", "`bench sessions`"))
    return out


def _ui(d: dict[str, Any]) -> list[Row]:
    pages = d["pages"]
    worst = lambda key, f: f(p[key] for p in pages)  # noqa: E731
    cmd = "`bench ui`"
    return [
        Row("supervisor CPU, two pages, armed and recording", f"{d['supervisor_cpu_percent']:.1f} % of a core",
            "<= 10 %", cmd),
        Row("per page: poses delivered / plot refresh (the slower page)",
            f"{worst('pose_updates_delivered_per_s', min):.1f}/s / {worst('plot_refresh_per_s', min):.1f} Hz",
            ">= 30/s / >= 10 Hz", cmd),
        Row("telemetry to page, p95 (the slower page)", f"{worst('latency_ms_p95', max):.0f} ms", "<= 100 ms", cmd),
    ]


def _safety(d: dict[str, Any]) -> list[Row]:
    cmd = "`bench safety`"
    out = []
    f = d.get("frozen_pilot")
    if f:
        out.append(Row("a frozen pilot seen as gone: median / max",
                       f"{f['detection_median_s']:.2f} / {f['detection_max_s']:.2f} s",
                       f"the timeout, {f['pilot_gone_timeout_s']:g} s", cmd))
    t = d.get("takeover_under_spam")
    if t:
        out.append(Row("take-over by the pilot under wrong-token spam: median / max",
                       f"{t['takeover_median_s'] * 1000:.0f} / {t['takeover_max_s'] * 1000:.0f} ms", "", cmd))
    c = d.get("crowd")
    if c:
        out.append(Row(f"pages connecting at once ({c['pages']} a round, {c['rounds']} rounds): broken",
                       str(c["broken_total"]), "0", cmd))
    s = d.get("disarm_under_spam")
    if s:
        out.append(Row(f"DISARM applied while {s['spammers']} viewer(s) spam the session list: median / max",
                       f"{s['delay_median_s'] * 1000:.0f} / {s['delay_max_s'] * 1000:.0f} ms", "<= 500 ms", cmd))
    w = d.get("slow_link")
    if w:
        out.append(Row(f"a pilot reading {w['rate_bytes_s'] / 1000:g} kB/s for {w['seconds']:g} s: stays the pilot",
                       "yes" if w["stayed_pilot"] else f"no (gone after {w['pilot_for_s']:.0f} s)", "yes", cmd))
    k = d.get("slow_connect")
    if k:
        out.append(Row(f"a page through a {2 * k['delay_each_way_s']:g} s round trip: its socket open / its first "
                       "state, median / max",
                       f"{k['socket_median_s']:.1f} / {k['socket_max_s']:.1f} s, "
                       f"{k['connect_median_s']:.1f} / {k['connect_max_s']:.1f} s", "<= 10 s", cmd))
    x = d.get("slow_disarm")
    if x:
        out.append(Row(f"DISARM through a {2 * x['delay_each_way_s']:g} s round trip ({x['applied']} of "
                       f"{x['trials']} applied): median / max",
                       f"{x['disarm_median_s']:.2f} / {x['disarm_max_s']:.2f} s" if x["applied"] else "none",
                       f"<= {x['delay_each_way_s'] + 0.5:g} s (the link's delay + 0.5 s)", cmd))
    r = d.get("restart")
    if r:
        out.append(Row(f"the pilot's page the pilot again after a restart under {r['spinners']} spinning processes "
                       f"({r['back']} of {r['restarts']}): median / max from the console serving",
                       f"{r['from_up_median_s']:.1f} / {r['from_up_max_s']:.1f} s", "<= 10 s", cmd))
    x = d.get("failsafes")
    for name, f in (x or {}).get("triggers", {}).items():
        out.append(Row(f"failsafe {name} ({f['action']}) on the emulated rig: detection to action beyond its "
                       f"{f['timeout_s']:g} s timeout, p99 / max ({x['trials']} trials)",
                       f"{f['p99_s'] * 1000:.0f} / {f['max_s'] * 1000:.0f} ms", "<= 100 ms", cmd))
    return out


def _tracking(d: dict[str, Any]) -> list[Row]:
    figures = []
    for mode, m in d["modes"].items():
        goals = m["goals"]
        figures.append(f"{mode} {sum(g['met'] for g in goals.values())}/{len(goals)}")
    return [Row("tracking goals met (depth step, heading, turn, speed, E5, force direction)",
                ", ".join(figures), "all", "`bench tracking`")]


def _worst(d: dict[str, Any], case: str, key: str, digits: int = 1) -> str:
    """Each mode's worst case over the seeds of ``key`` in ``case``."""
    return ", ".join(f"{mode} {m['goals'][key]['worst']:.{digits}f}" for mode, m in d["cases"][case].items()
                     if key in m["goals"])


def _tracking_seeds(d: dict[str, Any]) -> list[Row]:
    n = len(d["seeds"])
    how = f"over {n} seeds{' (half-length manoeuvres)' if d['quick'] else ''}, the worst"
    return [Row(f"heading error through the depth step, from its start, {how} (deg)",
                _worst(d, "nominal", "depth_step/heading_all_deg"), "<= 5", "`bench tracking --seeds`"),
            Row(f"heading error going straight, from the start, {how} (deg)",
                _worst(d, "nominal", "straight/heading_all_deg"), "<= 3", "`bench tracking --seeds`")]


def _tracking_cases(d: dict[str, Any]) -> list[Row]:
    n = len(d["seeds"])
    rows = []
    if "weak_fin" in d["cases"]:
        rows.append(Row(f"one fin's drive at half speed: heading error through the depth step, worst of {n} seeds "
                        "(deg)", _worst(d, "weak_fin", "depth_step/heading_all_deg"), "<= 10",
                        "`bench tracking --cases weak_fin`"))
    for case, what in (("light_1pc", "1 % light"), ("heavy_1pc", "1 % heavy")):
        if case in d["cases"]:
            rows.append(Row(f"the robot {what}: depth error from 30 s, worst of {n} seeds (m)",
                            _worst(d, case, "straight/depth_dev", 2), "<= 0.1",
                            f"`bench tracking --cases {case}`"))
    return rows


def _load(d: dict[str, Any]) -> list[Row]:
    return [
        Row(f"emulated rig swimming for {d['load_s'] / 60:g} min under {d['hogs']} spinning processes "
            f"(1-minute load average {d['loadavg_min']:.1f}-{d['loadavg_max']:.1f}, mean {d['loadavg_mean']:.1f}"
            + (f", at least 8 for {d['load_at_goal_s'] / 60:.1f} min" if "load_at_goal_s" in d else "") + "): "
            "spurious drive / sensor faults",
            f"{d['drive_faults']} / {d['sensor_faults']}", "0 / 0", "`bench load`"),
        Row("the loop's lag back under 100 ms after the load ended", f"{d['lag_back_under_goal_after_s']:.1f} s",
            "<= 5 s", "`bench load`"),
    ]


def _pages(d: dict[str, Any]) -> list[Row]:
    kept = sum(abs(n - d["baseline"][name]) for name, n in d["after"].items())
    return [Row(f"{d['pages']:,} pages opened and closed at random moments: per-page state kept / Python "
                "allocations kept / resident size", f"{kept} / {d['traced_growth_mb']:+.1f} MB / "
                f"{d['rss_before_mb']:.0f} -> {d['rss_after_mb']:.0f} MB", "0 / < 10 MB", "`bench pages`")]


def _library(d: dict[str, Any]) -> list[Row]:
    w, cmd = d["warm"], "`bench library`"
    out = [Row(f"run library, {w['sessions']:,} sessions: refresh with nothing changed / list all / "
               f"filter of 5 terms / sorted", f"{w['refresh_unchanged_s'] * 1e3:.0f} / {w['list_s'] * 1e3:.0f} / "
               f"{w['filter_s'] * 1e3:.0f} / {w['sort_s'] * 1e3:.0f} ms", "< 1 s each", cmd)]
    c = d.get("cold")
    if c:
        out.append(Row(f"run library: a new {c['seconds_each']:.0f}-s session indexed (its figures computed)",
                       f"{c['per_session_s'] * 1e3:.0f} ms", "", cmd))
    return out


def _run_report(d: dict[str, Any]) -> list[Row]:
    return [Row(f"a run's HTML report of a {d['seconds'] / 60:g}-minute session ({d['segments']} segments): in "
                "the process / after a stop, in its own process", f"{d['report_s_median']:.1f} / "
                f"{d['background_s']:.1f} s", "< 10 s", "`bench run-report`")]


#: each benchmark's file (in ``benchmarks/``) and the rows made from it, in the table's order
SOURCES: dict[str, Callable[[dict[str, Any]], list[Row]]] = {
    "mpc": _mpc, "sim": _sim, "compile": _compile, "sessions": _sessions, "library": _library,
    "run_report": _run_report, "ui": _ui,
    "safety": _safety, "link": _safety, "pages": _pages, "load": _load, "tracking": _tracking,
    "tracking_seeds": _tracking_seeds, "tracking_cases": _tracking_cases,
}


def machine_line(machines: dict[str, dict[str, Any]]) -> str:
    """Where the figures come from: the CPU and Python of each file's run, grouped."""
    groups: dict[str, list[str]] = {}
    for name, m in machines.items():
        key = (f"{m.get('cpu_model', 'unknown CPU')}, {m.get('logical_cpus', '?')} logical CPUs, "
               f"Python {m.get('python', '?')}, numba {m.get('numba', '?')}")
        groups.setdefault(key, []).append(name)
    if len(groups) == 1:
        return f"Measured on {next(iter(groups))}."
    return "Measured on " + "; ".join(f"{k} ({', '.join(v)})" for k, v in groups.items()) + "."


def table(directory: Path) -> str:
    """The Markdown table (with its machine line) of the benchmark files in ``directory``."""
    rows: list[Row] = []
    machines: dict[str, dict[str, Any]] = {}
    for name, make in SOURCES.items():
        path = directory / f"{name}.json"
        if not path.is_file():
            continue
        try:
            data = json.loads(path.read_text())
            rows += make(data)
        except (ValueError, KeyError, TypeError) as e:
            raise ValueError(f"{path}: not a benchmark file of this version ({type(e).__name__}: {e})") from e
        if "machine" in data:
            machines[name] = data["machine"]
        for key in data:  # a run of some parts of the file keeps its own machine (machine_<parts>)
            if key.startswith("machine_") and isinstance(data[key], dict):
                machines[f"{name} {key.removeprefix('machine_').replace('_', ' ')}"] = data[key]
    if not rows:
        raise ValueError(f"{directory}: no benchmark files ({', '.join(f'{n}.json' for n in SOURCES)})")
    lines = [machine_line(machines), "", "| measure | figure | goal | measured by `ucat-console` |",
             "|---|---|---|---|"]
    lines += [f"| {r.measure} | {r.figure} | {r.goal} | {r.command} |" for r in rows]
    return "\n".join(lines)


def replace_block(text: str, block: str, where: str) -> str:
    """``text`` with what is between :data:`START` and :data:`END` replaced by ``block``."""
    pattern = re.compile(re.escape(START) + r"\n(?:.*?\n)?" + re.escape(END), re.S)
    if len(pattern.findall(text)) != 1:
        raise ValueError(f"{where}: needs exactly one pair of the performance table's markers")
    return pattern.sub(lambda _: f"{START}\n{block}\n{END}", text)


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("report", help="the performance table from the benchmarks' JSON files")
    p.add_argument("--dir", type=Path, default=Path("benchmarks"), help="the JSON files' folder")
    p.add_argument("--write", type=Path, nargs="*", default=[], metavar="FILE",
                   help="replace the table between its markers in these files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    block = table(args.dir)
    texts = {path: replace_block(path.read_text(), block, str(path)) for path in args.write}
    for path, text in texts.items():  # every file checked before any is written
        path.write_text(text)
        print(f"wrote the table into {path}")
    if not args.write:
        print(block)
    return 0
