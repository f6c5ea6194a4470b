"""``ucat-console bench run-report``: how long a run's HTML report takes (figures, never test
assertions).

A session of ``--seconds`` (default 600: a 10-minute run) is recorded at the recorder's live
mix with the channels the figures read (``bench library``'s
:func:`~ucat_console.bench.library.record_run`, about 470 messages/s), the drives'
electrical input at 10 Hz, a mode change and a tuning change, and a manoeuvre's
``--segments`` measured segments (each a Table V row with its bootstrap). Then:

* ``write_report`` in this process, the median of ``--repeats``: reading the session once,
  the figures and their intervals (the driven run and every segment), the four plots, the
  file written (the goal: under 10 s for 10 minutes);
* the report as the console writes it when a recording stops (:class:`ReportWriter`: a
  child process started with ``spawn``, at a lower priority): from the stop to the file,
  once, the child's start and imports included.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from ucat_console.backend.review.run_report import ReportWriter, report_path, write_report
from ucat_console.bench.library import record_run
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import ElectricalPower


def _extra(seconds: float, segments: int) -> list[tuple[float, str, Any]]:
    out: list[tuple[float, str, Any]] = [
        (k / 10.0, C.POWER_ELECTRICAL, ElectricalPower(k / 10.0, (1.0,) * 4, (24.0,) * 4, (0.6,) * 4, 2.4))
        for k in range(int(seconds * 10))]
    out.append((seconds / 3, C.EVENTS, Event(seconds / 3, "loop", "mode", "controller mpc -> baseline", "info",
                                             {"from": "mpc", "to": "baseline"})))
    out.append((seconds / 2, C.EVENTS, Event(seconds / 2, "loop", "tuning", "pilot: mpc.lam_st 2 -> 3", "info")))
    span = seconds / max(segments, 1)
    for k in range(segments):
        t0, t1 = k * span + 0.2 * span, (k + 1) * span
        out.append((t1, C.EVENTS, Event(t1, "manoeuvre", "segment", f"bench #{k + 1}", "info",
                                        {"manoeuvre": "bench", "index": k, "label": f"step {k + 1}",
                                         "t0": t0, "t1": t1})))
    return out


def measure(directory: Path, seconds: float, segments: int, repeats: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    part = record_run(directory, seconds, extra=_extra(seconds, segments))
    record_s = time.perf_counter() - t0
    sid = part.name.removesuffix("_001.mcap")
    times = []
    report = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        report = write_report(part, directory / "bench.report.html", directory)
        times.append(time.perf_counter() - t0)
    assert report is not None
    done = threading.Event()
    writer = ReportWriter(on_done=lambda r, e: done.set())
    t0 = time.perf_counter()
    writer.submit(sid, [part])
    done.wait()
    background_s = time.perf_counter() - t0
    written = report_path(sid, directory).is_file()
    return {"seconds": seconds, "segments": segments, "messages_bytes": part.stat().st_size, "record_s": record_s,
            "repeats": repeats, "report_s_median": statistics.median(times), "report_s_max": max(times),
            "report_bytes": report.path.stat().st_size, "missing": list(report.missing),
            "background_s": background_s, "background_written": written}


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("run-report", help="a run's HTML report: its time for a 10-minute session")
    p.add_argument("--seconds", type=float, default=600.0, help="the session's length (s)")
    p.add_argument("--segments", type=int, default=10, help="the manoeuvre's measured segments in it")
    p.add_argument("--repeats", type=int, default=3, help="reports timed in this process (the median is kept)")
    p.add_argument("--dir", type=Path, default=None, help="scratch directory (default: /tmp)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not 10.0 <= args.seconds <= 7200.0:
        raise ValueError(f"--seconds: {args.seconds} must be in 10..7200")
    if not 0 <= args.segments <= 100 or not 1 <= args.repeats <= 20:
        raise ValueError("--segments: 0..100; --repeats: 1..20")
    if args.json is not None and not args.json.parent.is_dir():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    from ucat_console.bench.machine import machine_info, speed_line

    tmp = Path(tempfile.mkdtemp(prefix="bench-run-report-", dir=args.dir))
    try:
        r = measure(tmp, args.seconds, args.segments, args.repeats)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"session of {r['seconds']:.0f} s ({r['messages_bytes'] / 1e6:.1f} MB, {r['segments']} segments): "
          f"report {r['report_s_median']:.2f} s (median of {r['repeats']}, max {r['report_s_max']:.2f} s), "
          f"{r['report_bytes'] / 1e3:.0f} kB; after a stop, in its own process: {r['background_s']:.2f} s"
          + ("" if r["background_written"] else " (NOT written)"))
    machine = r["machine"] = machine_info(None)
    print(speed_line(machine))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    return 0
