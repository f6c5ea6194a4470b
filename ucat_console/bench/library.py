"""``ucat-console bench library``: the run library over 1,000 sessions (figures, never test
assertions).

* Reading a session: a few real sessions of the recorder's live mix (``bench sessions``'
  :data:`~ucat_console.bench.sessions.MIX`, about 400 messages/s) with the channels the
  figures read added (tracking at 50 Hz, each fin's strokes at 4 Hz and cycles at 2 Hz),
  ``--seconds`` each, indexed from nothing: the cost of a new session's first refresh (its
  summary, its messages, its figures with their bootstrap).
* A warm index of ``--sessions`` (1,000) rows: one real session file hard-linked under as many
  session names (the folder a refresh scans), each row's facts stored straight into the
  index with varied modes, speeds, days, notes and tags (a quarter of the sessions with a sidecar);
  then, each the median of ``--repeats``: a refresh with nothing changed (a directory scan,
  the rows' keys compared, no file opened), the whole listing, a filter of five terms and a
  sorted listing. The goal: each under 1 s for 1,000 sessions.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import random
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable

from ucat_console.backend.sessions import files, sidecar
from ucat_console.backend.sessions.library import Library
from ucat_console.backend.sessions.library_read import PartStat, read_facts
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.bench.sessions import synthetic_messages_between
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import BodyTracking, FinCycle, FinStrouhal
from ucat_console.telemetry.stream import TelemetryStream

#: the filter timed (five terms of every kind: a value of several, a number, a tag, a day, text)
FILTER = 'mode=mpc speed>0.15 tag:pool-3 date>=2026-12-01 notes~"weak fin"'


def _median(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def _tracking(t: float) -> BodyTracking:
    return BodyTracking(t, True, 0.3, 1.0, 0.0, 0.0, 0.01 * math.sin(t), 0.02, -0.01)


def _stroke(fin: int) -> Callable[[float], FinStrouhal]:
    return lambda t: FinStrouhal(t, fin, 0.3 + 0.05 * math.sin(3.0 * t), 0.25, 0.35, 0.3, 0.3, 0.5, 3.0)


def _cycle(fin: int) -> Callable[[float], FinCycle]:
    return lambda t: FinCycle(t, fin, "mpc", (-0.1, 0.0), (-0.1, 0.0), 0.0, 0.0, 0.5, 0.5)


#: what the figures read beyond the live mix: channel -> (rate Hz, message factory of t)
FIGURE_MIX: dict[str, tuple[float, Callable[[float], Any]]] = {
    C.BODY_TRACKING: (50.0, _tracking),
    **{C.fin_strouhal(i): (4.0, _stroke(i)) for i in range(C.N_FINS)},
    **{C.fin_cycle(i): (2.0, _cycle(i)) for i in range(C.N_FINS)},
}


def record_run(directory: Path, seconds: float, epoch_offset: float = 1.7e9,
               extra: Iterable[tuple[float, str, Any]] = ()) -> Path:
    """A session of the live mix and :data:`FIGURE_MIX` over ``seconds``, and ``extra``
    (t, channel, message) items; its file."""
    items = [(t, c, m) for t, c, m in synthetic_messages_between(0.0, seconds)] + list(extra)
    for channel, (rate, make) in FIGURE_MIX.items():
        items += [(k / rate, channel, make(k / rate)) for k in range(math.ceil(seconds * rate))]
    items.sort(key=lambda x: x[0])
    stream = TelemetryStream(validate=False)
    rec = Recorder(stream, RecorderConfig(queue_size=max(1, len(items)), split_duration=seconds + 1.0),
                   directory=directory, epoch_offset=epoch_offset)
    rec.start(label="library", notes="weak fin on the left")
    for _, channel, msg in items:
        stream.publish(channel, msg)
    paths = rec.stop()
    if rec.stats().dropped or len(paths) != 1:
        raise RuntimeError(f"bench session: {rec.stats().dropped} dropped, {len(paths)} parts")
    return paths[0]


def cold_read(directory: Path, sessions: int, seconds: float) -> dict[str, Any]:
    """Record ``sessions`` real sessions and index them from nothing."""
    for _ in range(sessions):
        record_run(directory, seconds)
    size = sum(p.stat().st_size for p in directory.glob("*" + files.SUFFIX))
    with Library(directory) as lib:
        t0 = time.perf_counter()
        report = lib.refresh()
        dt = time.perf_counter() - t0
    return {"sessions": sessions, "seconds_each": seconds, "bytes": size, "added": report.added,
            "refresh_s": dt, "per_session_s": dt / max(sessions, 1)}


def warm_index(directory: Path, n: int, repeats: int, seed: int = 0) -> dict[str, Any]:
    """A warm index of ``n`` rows (module docstring) and the times of its operations."""
    template = record_run(directory / ".template", 10.0)
    facts = read_facts(template.name.removesuffix("_001.mcap"), [template], template.parent)
    rng = random.Random(seed)
    day0 = time.mktime((2026, 11, 1, 12, 0, 0, 0, 0, 0))
    lib = Library(directory)
    t0 = time.perf_counter()
    for k in range(n):
        sid = f"20261101-120000-b{k:04d}"
        name = files.part_name(sid, 1)
        os.link(template, directory / name)
        st = (directory / name).stat()
        speed = rng.uniform(0.05, 0.3)
        modes = rng.choice([("mpc",), ("baseline",), ("mpc_sync",), ("mpc", "baseline")])
        epm = rng.uniform(10.0, 60.0)
        row = dataclasses.replace(
            facts, session_id=sid, start=day0 + 86400.0 * rng.randrange(60) + rng.uniform(0, 3600), modes=modes,
            notes=rng.choice(["", "weak fin on the left", "calm water", "pool 3 lane 2"]),
            plant=rng.choice(["plate_cd0.05", "plate_cd0.02", "still_water"]), status="ok",
            figures={**facts.figures, "speed": speed, "epm": epm, "epm_lo": 0.9 * epm, "epm_hi": 1.1 * epm},
        )
        lib.store(row, [PartStat(name, st.st_size, st.st_mtime_ns)])
        if k % 4 == 0:
            sidecar.write(directory, sid, sidecar.Sidecar(("pool-3",) if k % 8 == 0 else ("draft",)))
    shutil.rmtree(directory / ".template")
    fill_s = time.perf_counter() - t0
    first = lib.refresh()  # the sidecars read once (a refresh after the rows were stored)
    lib.close()
    out: dict[str, Any] = {"sessions": n, "fill_s": fill_s, "first_refresh_s": first.seconds,
                           "first_refresh_sidecars": first.sidecars, "repeats": repeats, "filter": FILTER}
    with Library(directory) as lib:
        def first_call() -> None:  # what a new process's first call does: open, check, refresh
            with Library(directory) as fresh:
                fresh.refresh()

        t_open, _ = _median(first_call, 1)
        refresh_s, report = _median(lib.refresh, repeats)
        list_s, rows = _median(lambda: lib.find(""), repeats)
        filter_s, hits = _median(lambda: lib.find(FILTER), repeats)
        sort_s, _ = _median(lambda: lib.find("", sort="epm", desc=True), repeats)
    out.update(open_and_refresh_s=t_open, refresh_unchanged_s=refresh_s, unchanged=report.unchanged,
               list_s=list_s, listed=len(rows), filter_s=filter_s, matched=len(hits), sort_s=sort_s)
    return out


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``bench library`` to the ``bench`` command's sub-commands."""
    p = kinds.add_parser("library", help="the run library: refresh, listing and filtering over 1,000 sessions")
    p.add_argument("--sessions", type=int, default=1000, help="rows of the warm index")
    p.add_argument("--cold", type=int, default=3, help="real sessions indexed from nothing")
    p.add_argument("--seconds", type=float, default=60.0, help="length of each of those sessions (s)")
    p.add_argument("--repeats", type=int, default=5, help="timings per operation (the median is kept)")
    p.add_argument("--dir", type=Path, default=None, help="scratch directory (default: /tmp)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.sessions <= 100_000:
        raise ValueError(f"--sessions: {args.sessions} must be in 1..100000")
    if not 0 <= args.cold <= 100 or not 1 <= args.repeats <= 100:
        raise ValueError("--cold: 0..100 sessions; --repeats: 1..100")
    if not 1.0 <= args.seconds <= 3600.0:
        raise ValueError(f"--seconds: {args.seconds} must be in 1..3600")
    if args.json is not None and not args.json.parent.is_dir():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    from ucat_console.bench.machine import machine_info, speed_line

    result: dict[str, Any] = {}
    tmp = Path(tempfile.mkdtemp(prefix="bench-library-", dir=args.dir))
    try:
        if args.cold:
            (tmp / "cold").mkdir()
            c = result["cold"] = cold_read(tmp / "cold", args.cold, args.seconds)
            print(f"new sessions: {c['sessions']} of {c['seconds_each']:.0f} s ({c['bytes'] / 1e6:.1f} MB) indexed "
                  f"from nothing in {c['refresh_s']:.2f} s: {c['per_session_s'] * 1e3:.0f} ms a session")
        (tmp / "warm").mkdir()
        w = result["warm"] = warm_index(tmp / "warm", args.sessions, args.repeats)
        print(f"warm index of {w['sessions']:,} sessions (median of {w['repeats']}): refresh with nothing changed "
              f"{w['refresh_unchanged_s'] * 1e3:.1f} ms; list all {w['list_s'] * 1e3:.1f} ms; "
              f"filter {w['filter_s'] * 1e3:.1f} ms ({w['matched']} matched); sorted by epm "
              f"{w['sort_s'] * 1e3:.1f} ms; a new Library's first refresh {w['open_and_refresh_s'] * 1e3:.1f} ms")
        print(f"  filter: {FILTER}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    machine = result["machine"] = machine_info(None)
    print(speed_line(machine))
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json}")
    return 0
