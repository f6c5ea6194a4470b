"""``ucat-console sessions list|info|export|repair|compare|report|find|tag|note|trend``: the
recorded sessions, a run's HTML report (docs/review.md), and the run library over them
(docs/library.md: ``find`` a query, ``tag`` and ``note`` a session, the ``trend`` of a figure).

SESSION is a session id or any one of its part files (a path, or a file name inside the
sessions directory): ``info`` and ``export`` cover every part of the session, in order, as
one recording; ``repair`` takes one file (not one being recorded; the original is kept,
listed, as ``<name>.orig.mcap``); ``compare`` writes two to four sessions' (or their
segments') efficiency figures side by side (docs/review.md). ``--dir`` names the sessions directory (default:
``$UCAT_CONSOLE_SESSIONS``, else the user's data folder: ``ucat-console paths``), where a
session id or a bare file name is looked for; a path is read wherever it is (the page, unlike
the shell, is confined to the sessions directory).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any


def _add_dir(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dir", type=Path, default=None,
                   help="sessions directory (default: $UCAT_CONSOLE_SESSIONS, else the user's "
                        "data folder: ucat-console paths)")


def register(sub: argparse._SubParsersAction) -> None:
    sessions = sub.add_parser("sessions", help="recorded sessions: list, info, export, repair, compare, "
                              "report, find, tag, note, trend")
    kinds = sessions.add_subparsers(dest="sessions", required=True, metavar="ACTION")

    p = kinds.add_parser("list", help="every session: start, duration, size, events, notes")
    _add_dir(p)
    p.set_defaults(func=run_list)

    p = kinds.add_parser("info", help="one session's parts, channels, counts and metadata")
    p.add_argument("file", metavar="SESSION", help="session id or any part file of it")
    _add_dir(p)
    p.set_defaults(func=run_info)

    p = kinds.add_parser("export", help="CSV files of a set of channels, or a rosbag2 bag (every part)")
    p.add_argument("file", metavar="SESSION", help="session id or any part file of it")
    p.add_argument("--topics", nargs="+", default=None, metavar="CHANNEL",
                   help="CSV: channels to export (e.g. body/state fin/0/state; 'all' for every one)")
    p.add_argument("--format", choices=("csv",), default="csv", help="output format of --out")
    p.add_argument("--out", type=Path, default=None, metavar="DIR", help="CSV: output directory")
    p.add_argument("--rosbag2", type=Path, default=None, metavar="DIR",
                   help="write a ROS 2 bag (MCAP storage, standard and ucat_msgs types) into DIR, "
                        "a new or empty directory (docs/sessions.md, 'rosbag2')")
    p.add_argument("--start", type=float, default=None, help="from this time (stream s)")
    p.add_argument("--end", type=float, default=None, help="before this time (stream s)")
    _add_dir(p)
    p.set_defaults(func=run_export)

    p = kinds.add_parser("repair", help="re-index a truncated file (a killed recorder)")
    p.add_argument("file", metavar="FILE", help="session file")
    p.add_argument("--no-keep", action="store_true", help="do not keep the original as NAME.orig.mcap")
    p.add_argument("--force", action="store_true", help="rewrite even a file that opens")
    _add_dir(p)
    p.set_defaults(func=run_repair)

    from ucat_console.backend.review.compare import SEGMENT_CODES

    p = kinds.add_parser("compare", help="runs side by side: Table V figures (Markdown, CSV) and a PNG")
    p.add_argument("files", nargs="+", metavar="SESSION", help="one to four sessions (ids or part files)")
    p.add_argument("--segments", nargs="+", default=[], choices=SEGMENT_CODES, metavar="CODE",
                   help="cut each run at these events into segments (" + ", ".join(SEGMENT_CODES) + ")")
    p.add_argument("--align", choices=SEGMENT_CODES, default=None, metavar="CODE",
                   help="overlay each run or segment from its first event of this code (default: its start)")
    p.add_argument("--window", type=float, nargs=2, default=None, metavar=("FROM", "TO"),
                   help="only this stretch of each run (session s)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    _add_dir(p)
    p.set_defaults(func=run_compare)

    p = kinds.add_parser("report", help="one self-contained HTML report of a run (docs/review.md)")
    p.add_argument("file", metavar="SESSION", help="session id or any part file of it")
    p.add_argument("--out", type=Path, default=None, metavar="FILE",
                   help="the report (default: beside the session's parts, <session id>.report.html)")
    _add_dir(p)
    p.set_defaults(func=run_report)

    p = kinds.add_parser("find", help="the run library: sessions matching a query (docs/library.md)",
                         description="QUERY: terms all of which match, e.g. 'mode=mpc speed>0.15 tag:pool-3 "
                                     "date>=2026-12-01 notes~\"weak fin\"'. Fields: " + _fields())
    p.add_argument("query", nargs="?", default="", metavar="QUERY", help="the query (default: every session)")
    p.add_argument("--json", action="store_true", help="the rows as JSON")
    p.add_argument("--sort", default=None, metavar="FIELD", help="sort by this field (default: start)")
    p.add_argument("--desc", action="store_true", help="largest (latest) first")
    _add_dir(p)
    p.set_defaults(func=run_find)

    p = kinds.add_parser("tag", help="add (+TAG) or remove (-TAG) tags of a session")
    p.add_argument("session", metavar="SESSION", help="session id")
    # REMAINDER: a removal (-draft) is a change, not an option
    p.add_argument("changes", nargs=argparse.REMAINDER, metavar="+TAG|-TAG",
                   help="tags to add (+pool-3) or remove (-draft)")
    _add_dir(p)
    p.set_defaults(func=run_tag)

    p = kinds.add_parser("note", help="replace a session's notes (kept beside it in SESSION.meta.json)")
    p.add_argument("session", metavar="SESSION", help="session id")
    p.add_argument("text", nargs="?", default=None, metavar="TEXT", help="the notes")
    p.add_argument("--operator", default=None, metavar="NAME", help="also (or only) set the operator's name")
    _add_dir(p)
    p.set_defaults(func=run_note)

    p = kinds.add_parser("trend", help="a figure of the library's sessions by day or by a configuration key")
    p.add_argument("field", metavar="FIELD", help="a number field (epm, cot, speed, speed_mae, st_in ...)")
    p.add_argument("query", nargs="?", default="", metavar="QUERY", help="only the sessions matching it")
    p.add_argument("--by", default="date", metavar="date|KEY",
                   help="group by day (date) or by a key of the recorded configuration (loop.mpc.lam_st)")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.png|FILE.csv",
                   help="the figure (PNG, with the CSV beside it; CSV alone without matplotlib or for .csv)")
    _add_dir(p)
    p.set_defaults(func=run_trend)


def resolve(arg: str, directory: Path | None) -> list[Path]:
    """Session files named by ``arg`` (a path, a file name in the directory, or an id)."""
    from ucat_console.backend.sessions import files, index

    root = files.sessions_dir(directory)
    p = Path(arg)
    if p.is_file():
        return [p]
    if (root / arg).is_file():
        return [root / arg]
    return index.session_parts(arg, root)


def _fmt_duration(s: float | None) -> str:
    if s is None:
        return "?"
    m, sec = divmod(int(round(s)), 60)
    h, m = divmod(m, 60)
    return f"{h:d}:{m:02d}:{sec:02d}"


def _fmt_time(t: float | None) -> str:
    try:
        return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(t)) if t else "?"
    except (OverflowError, ValueError, OSError):  # a time no calendar holds
        return "?"


def _fmt_size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n} B"


def run_list(args: argparse.Namespace) -> int:
    from ucat_console.backend.sessions import files, index

    listing = index.scan(args.dir)
    sessions = listing.sessions
    for skipped in listing.skipped:
        print(f"skipped {skipped.name}: {skipped.why}")
    if not sessions:
        print(f"no sessions in {files.sessions_dir(args.dir)}")
        return 0
    print(f"{'session':<28} {'started (UTC)':<19} {'parts':>5} {'duration':>9} "
          f"{'size':>9} {'events':>6}  notes")
    for s in sessions:
        start = _fmt_time(s.start)
        events = "?" if s.events is None else str(s.events)
        if s.recording:
            flag = "  [recording]"
        elif any(p.repairable for p in s.parts):
            flag = "  [truncated: run `sessions repair`]"
        else:
            flag = "  [truncated]" if s.truncated else ""
        original = next((p.original_of for p in s.parts if p.original_of), "")
        if original:
            flag += f"  [the original of {files.printable(original)}, kept by its repair]"
        errors = [p.error for p in s.parts if p.error]
        note = files.printable(s.notes.replace("\n", " "))
        if len(note) > 40:
            note = note[:39] + "…"
        print(f"{files.printable(s.session_id):<28} {start:<19} {len(s.parts):>5} {_fmt_duration(s.duration):>9} "
              f"{_fmt_size(s.size):>9} {events:>6}  {note}{flag}")
        for e in errors:
            print(f"    unreadable: {files.printable(e)}")
    return 0


def run_info(args: argparse.Namespace) -> int:
    from ucat_console.backend.sessions import files, sidecar
    from ucat_console.backend.sessions.reader import SessionParts

    with SessionParts(args.file, args.dir, confined=False) as s:
        print(f"session {s.session_id}: {len(s.parts)} part{'s' if len(s.parts) > 1 else ''} "
              f"in {s.directory}, software {files.printable(s.version[:40]) or '?'}")
        print(f"  {s.message_count} messages, {s.duration:.1f} s "
              f"(t {s.start:.3f} .. {s.end:.3f}), epoch offset {s.epoch_offset!r}")
        if s.weights:
            print("  weights: " + ", ".join(f"{k}={v:g}" for k, v in s.weights.items()))
        side = sidecar.read(s.directory, s.session_id)
        if side.notes is not None:
            print(f"  notes: {files.printable(side.notes)} (from {sidecar.path_of(s.directory, s.session_id).name}"
                  + (f"; recorded: {files.printable(s.notes)})" if s.notes else ")"))
        elif s.notes:
            print(f"  notes: {files.printable(s.notes)}")
        if side.tags:
            print(f"  tags: {', '.join(side.tags)}")
        if side.operator:
            print(f"  operator: {files.printable(side.operator)}")
        for n, r in enumerate(s.parts, 1):
            print(f"  part {n}: {r.path.name}, {r.message_count} messages, "
                  f"{r.duration:.1f} s (t {r.start:.3f} .. {r.end:.3f})")
        for channel, n in s.message_counts().items():
            print(f"    {channel:<20} {n:>9}")
    return 0


def run_export(args: argparse.Namespace) -> int:
    if args.rosbag2 is not None:
        if args.topics is not None or args.out is not None:
            raise ValueError("export: --rosbag2 writes every topic it knows into its own directory; "
                             "give it without --topics and --out")
        return _export_rosbag2(args)
    if args.topics is None or args.out is None:
        raise ValueError("export: give --topics and --out (CSV), or --rosbag2 DIR")
    from ucat_console.backend.sessions.export import export_csv
    from ucat_console.backend.sessions.reader import SessionParts
    from ucat_console.telemetry.channels import CHANNELS

    topics = [t for arg in args.topics for t in arg.split(",") if t]
    if "all" in topics:
        topics = list(CHANNELS)
    with SessionParts(args.file, args.dir, confined=False) as s:
        result = export_csv(s, topics, args.out, args.start, args.end)
    for channel, (path, rows) in result.items():
        print(f"{channel:<20} {rows:>9} rows -> {path}")
    return 0


def _export_rosbag2(args: argparse.Namespace) -> int:
    from ucat_console.backend.identification import recorded_app_config
    from ucat_console.backend.sessions.reader import SessionParts
    from ucat_console.backend.sessions.rosbag2_export import check_destination, export_rosbag2

    check_destination(args.rosbag2)  # before reading anything
    with SessionParts(args.file, args.dir, confined=False) as s:
        cfg = recorded_app_config(s, str(s.path))  # the recorded robot's geometry
        counts = export_rosbag2(s, args.rosbag2, args.start, args.end,
                                plant=cfg.plant if cfg is not None else None)
    for topic, n in counts.items():
        print(f"{topic:<20} {n:>9} messages")
    print(f"rosbag2 bag -> {args.rosbag2} (ros2 bag info {args.rosbag2})")
    return 0


def run_repair(args: argparse.Namespace) -> int:
    from ucat_console.backend.sessions.repair import repair

    paths = resolve(args.file, args.dir)
    if len(paths) != 1:
        raise ValueError(f"{args.file}: names {len(paths)} files; repair one file at a time")
    report = repair(paths[0], args.dir, keep_original=not args.no_keep, force=args.force, confined=False)
    if not report.repaired:
        print(f"{report.path}: complete, nothing to repair ({report.messages} messages)")
        return 0
    print(f"{report.path}: repaired, {report.messages} messages and {report.metadata} "
          f"metadata records recovered")
    if report.stop_reason:
        print(f"  reading stopped at: {report.stop_reason}")
    if report.original:
        print(f"  original kept as {report.original}")
    return 0


def run_compare(args: argparse.Namespace) -> int:
    from ucat_console.backend.review import compare, export
    from ucat_console.backend.review.metrics import MetricsConfig

    if not 1 <= len(args.files) <= 4:
        raise ValueError(f"compare: one to four sessions, got {len(args.files)}")
    if len(args.files) == 1 and not args.segments:
        raise ValueError("compare: one session needs --segments to compare its segments")
    cfg = MetricsConfig()
    wins = []
    for f in args.files:
        run = compare.load_run(f, args.dir, confined=False)
        if args.window is not None:
            run.cut(*args.window)
        wins += compare.windows(run, args.segments, args.align)
    rows = compare.table(wins, cfg)
    paths = export.write_all(rows, wins, cfg, args.out)
    print(f"power: {rows[0].source_label}")
    for r in rows:
        flag = f"  NOT COMPARABLE: {r.not_comparable}" if r.not_comparable else ""
        print(f"{r.label:<40} power {export.cell(r, 'power'):<26} J/m {export.cell(r, 'energy_per_metre'):<26}"
              f" CoT {export.cell(r, 'cost_of_transport')}{flag}")
    for kind, path in paths.items():
        print(f"{kind:<9} -> {path}")
    return 0


def run_report(args: argparse.Namespace) -> int:
    from ucat_console.backend.review.run_report import write_report

    report = write_report(args.file, args.out, args.dir, known_configs=known_configs())
    for m in report.missing:
        print(f"missing: {m}")
    print(f"report of {report.session_id} -> {report.path} ({report.seconds:.1f} s)")
    return 0


def _fields() -> str:
    from ucat_console.backend.sessions.library_query import FIELDS

    return ", ".join(FIELDS)


def known_configs() -> dict[str, str]:
    from ucat_console.config import known_configs as names

    return names()


def open_library(directory: Path | None) -> Any:
    from ucat_console.backend.sessions import files
    from ucat_console.backend.sessions.library import Library

    root = files.sessions_dir(directory)
    if not root.is_dir():
        raise ValueError(f"{root}: no such sessions folder")
    lib = Library(root, known_configs=known_configs())
    report = lib.refresh()
    if report.rebuilt and report.added:
        print(f"run library: indexed {report.added} sessions ({report.rebuilt}) in {report.seconds:.1f} s",
              file=sys.stderr)
    return lib


def _fmt_figure(v: float | None, lo: float | None = None, hi: float | None = None) -> str:
    if v is None:
        return "-"
    if lo is None or hi is None:
        return f"{v:.3g}"
    return f"{v:.3g} [{lo:.3g}, {hi:.3g}]"


def _cut(text: str, n: int) -> str:
    from ucat_console.backend.sessions import files

    text = files.printable(text.replace("\n", " "))
    return text if len(text) <= n else text[: n - 1] + "…"


def run_find(args: argparse.Namespace) -> int:
    with open_library(args.dir) as lib:
        rows = lib.find(args.query, args.sort, args.desc)
    if args.json:
        print(json.dumps([r.to_json() for r in rows], indent=1, allow_nan=False))
        return 0
    if not rows:
        print(f"no sessions match {args.query!r}" if args.query else "no sessions")
        return 0
    print(f"{'session':<28} {'started (UTC)':<19} {'duration':>8}  {'mode':<16} {'config':<12} "
          f"{'manoeuvre':<12} {'J/m [lo, hi]':<24} {'tags':<16} notes")
    for r in rows:
        f = r.figures
        epm = _fmt_figure(f["epm"], f["epm_lo"], f["epm_hi"]) if r.status == "ok" else f"({r.status})"
        print(f"{_cut(r.id, 28):<28} {_fmt_time(r.start):<19} {_fmt_duration(r.duration):>8}  "
              f"{_cut(','.join(r.modes) or '-', 16):<16} {_cut(r.config or (r.config_hash[:8] or '-'), 12):<12} "
              f"{_cut(r.manoeuvre or '-', 12):<12} {epm:<24} {_cut(','.join(r.tags) or '-', 16):<16} "
              f"{_cut(r.notes, 40)}")
    print(f"{len(rows)} session{'s' if len(rows) != 1 else ''}")
    return 0


def run_tag(args: argparse.Namespace) -> int:
    changes = list(args.changes)
    for k, c in enumerate(changes):  # --dir after the changes (REMAINDER took it)
        if c == "--dir" and k + 1 < len(changes):
            args.dir = Path(changes[k + 1])
            del changes[k:k + 2]
            break
        if c.startswith("--dir="):
            args.dir = Path(c.removeprefix("--dir="))
            del changes[k]
            break
    if not changes:
        raise ValueError("tag: give the tags to add (+TAG) or remove (-TAG)")
    args.changes = changes
    with open_library(args.dir) as lib:
        tags = lib.set_tags(args.session, args.changes)
    print(f"{args.session}: tags {', '.join(tags) or '(none)'}")
    return 0


def run_note(args: argparse.Namespace) -> int:
    if args.text is None and args.operator is None:
        raise ValueError("note: give the notes TEXT, --operator NAME, or both")
    with open_library(args.dir) as lib:
        row = lib.set_notes(args.session, args.text, args.operator)
    print(f"{row.id}: notes {row.notes!r}" + (f", operator {row.operator!r}" if row.operator else ""))
    return 0


def run_trend(args: argparse.Namespace) -> int:
    from ucat_console.backend.review import trend
    from ucat_console.backend.sessions.library_query import field

    unit = field(args.field, "trend: field").unit
    if not args.out.parent.is_dir():
        raise ValueError(f"--out: directory {args.out.parent} does not exist")
    with open_library(args.dir) as lib:
        points = lib.trend(args.field, args.by, args.query)
    if not points:
        raise ValueError(f"trend: no session{' matching ' + repr(args.query) if args.query else ''} has {args.field}")
    csv_path = args.out if args.out.suffix == ".csv" else args.out.with_suffix(".csv")
    csv_path.write_text(trend.csv_text(points, args.field, args.by))
    for g in trend.groups(points):
        print(f"{g.group:<24} n={g.n:<4} mean {g.mean:.4g}  range {g.low:.4g} .. {g.high:.4g}")
    print(f"csv -> {csv_path}")
    if args.out.suffix != ".csv":
        if trend.can_plot():
            trend.write_png(points, args.field, unit, args.by, args.out)
            print(f"png -> {args.out}")
        else:
            print("png: needs matplotlib (pip install 'ucat-console[experiments]'); wrote the CSV only")
    return 0
