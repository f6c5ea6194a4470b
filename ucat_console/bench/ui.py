"""``ucat-console bench ui``: the live page under load, measured in headless Chromium.

The console runs as it does at the pool (supervisor on the simulated robot in real time,
armed and swimming; web page on a free loopback port) with ``pages`` headless Chromium
pages open on it. After a warm-up, for ``duration`` seconds:

* pose updates per second reaching each page, counted at two points: *delivered*, when
  the batch carrying the update leaves viser's websocket worker for the page's main
  thread (what the server and the network achieve), and *displayed*, when the page
  applies it in a rendered frame (viser applies queued messages once per frame, so
  updates that arrive between two frames are shown together: this is bounded by how fast
  the browser renders). The app's probe element (``probe=True``) changes in the same
  message batch as every pose update and carries the update's sequence number; the page
  counts distinct numbers (a hook on the worker's messages; a MutationObserver);
* plot refreshes per second: the page counts uPlot redraws (its ``clearRect`` calls on
  canvases inside ``.uplot``) per chart;
* telemetry-message-to-page latency: the probe carries the wall-clock time at which the
  BodyState it shows was published on the stream; the page records ``Date.now()`` when
  the probe changes on screen (same machine, same clock); p50 / p95 / max;
* supervisor CPU: the console process's CPU time over the wall time (100 % = one core),
  which includes the loop, the planner threads, the UI thread, the web server and the
  recorder (recording starts on arming, as at the pool); measured again for another
  ``duration`` seconds with the probe off (its element updated with every pose and sent to
  every page is the benchmark's, not the console's), the pages still drawing;
* with ``--camera FPS`` the emulated camera runs at that rate (recorded with the rest): the
  bytes sent to each page (the guard's count of its socket's bytes) and the camera pictures
  sent to the pages (at most 5 a second each) say what the video adds, beside the recorder's
  frames and its drops;
* browser CPU (Linux): the same for the Chromium processes started for the pages, split
  into the GPU process (where software GL draws the 3-D view when there is no GPU), the
  page renderers and the rest; with the supervisor's share it tells whether the machine
  was saturated.

The figures depend on the machine and its load (reported with them); they are for the
docs/performance.md, never test assertions.
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import os
import re
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
]
#: pages of one headless browser count as hidden: keep their timers and rendering at full rate
UNTHROTTLED = ["--disable-background-timer-throttling", "--disable-renderer-backgrounding",
               "--disable-backgrounding-occluded-windows"]

#: page-side instrumentation, installed before the page's own scripts
PAGE_PROBE = r"""
(() => {
  const b = window.__ucatBench = {probe: [], delivered: [], redraws: 0, counting: false, lastSeq: -1};
  const NativeWorker = window.Worker;
  window.Worker = class extends NativeWorker {
    constructor(...args) {
      super(...args);
      this.addEventListener('message', (e) => {
        const d = e.data;
        if (!b.counting || !d || d.type !== 'message_batch') return;
        for (const m of d.messages) {
          if (m.type !== 'GuiUpdateMessage' || typeof m.updates.content !== 'string') continue;
          const seq = /id="ucat-probe" data-seq="(\d+)"/.exec(m.updates.content);
          if (seq) b.delivered.push(Number(seq[1]));
        }
      });
    }
  };
  const clear = CanvasRenderingContext2D.prototype.clearRect;
  CanvasRenderingContext2D.prototype.clearRect = function (...args) {
    if (b.counting && this.canvas && this.canvas.closest && this.canvas.closest('.uplot')) b.redraws++;
    return clear.apply(this, args);
  };
  let last = null;
  new MutationObserver(() => {
    const el = document.getElementById('ucat-probe');
    if (!el) return;
    const seq = el.dataset.seq;
    if (seq === last) return;
    last = seq;
    b.lastSeq = Number(seq);
    if (b.counting) b.probe.push([Date.now(), Number(seq), Number(el.dataset.wall)]);
  }).observe(document, {subtree: true, childList: true, attributes: true, characterData: true});
})();
"""


_START_COUNTING = ("() => { const b = window.__ucatBench; b.probe = []; b.delivered = []; b.redraws = 0; "
                   "b.counting = true; }")


def _percentile(xs: list[float], q: float) -> float:
    if not xs:
        return float("nan")
    s = sorted(xs)
    k = min(len(s) - 1, max(0, round(q * (len(s) - 1))))
    return s[k]


def _stat_fields(stat: Path) -> list[str]:
    """The fields of a /proc ``stat`` file after the command name (parent pid first)."""
    return stat.read_text().rsplit(")", 1)[1].split()


def _cpu_seconds(fields: list[str]) -> float:
    """User plus system CPU seconds from :func:`_stat_fields`."""
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _thread_cpu_seconds() -> dict[str, float]:
    """CPU seconds of this process's live threads by thread name (Linux /proc); numbered
    names (``Thread-3 (...)``, ``ThreadPoolExecutor-0_1``) are summed under their stem."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    out: dict[str, float] = collections.defaultdict(float)
    for entry in Path(f"/proc/{os.getpid()}/task").iterdir():
        try:
            fields = _stat_fields(entry / "stat")
        except OSError:
            continue
        name = names.get(int(entry.name), "(not a Python thread)")
        name = re.sub(r"[-_]\d.*$", "", re.sub(r"^Thread-\d+ ", "", name))
        out[name] += _cpu_seconds(fields)
    return dict(out)


def _descendant_cpu_seconds() -> dict[str, float]:
    """CPU seconds of this process's descendant Chromium processes by kind (Linux /proc)."""
    procs: dict[int, tuple[int, str, float]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = _stat_fields(entry / "stat")
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        procs[int(entry.name)] = (int(fields[1]), cmdline, _cpu_seconds(fields))
    mine, frontier = set(), {os.getpid()}
    while frontier:
        frontier = {pid for pid, (ppid, _, _) in procs.items() if ppid in frontier} - mine
        mine |= frontier
    out = {"gpu": 0.0, "renderer": 0.0, "other": 0.0}
    for pid in mine:
        _, cmdline, cpu = procs[pid]
        if "chrom" not in cmdline:
            continue
        kind = ("gpu" if "--type=gpu-process" in cmdline
                else "renderer" if "--type=renderer" in cmdline else "other")
        out[kind] += cpu
    return out


def _sent_bytes(app: Any) -> dict[int, int]:
    """Bytes written to each page's socket so far, by client id."""
    out = {}
    for cid in list(app.pages):
        state = app.guard.link_state(cid)
        if state is not None:
            out[cid] = int(state["sent"])
    return out


def _pictures_sent(app: Any) -> int:
    return sum(p.sent for p in list(app.cameras.panels.values()))


def measure_ui(duration: float = 20.0, pages: int = 2, warmup: float = 5.0, velocity: float = 0.2,
               chromium: str = CHROMIUM, viewport: tuple[int, int] = (1400, 900),
               camera: float | None = None) -> dict[str, Any]:
    """Run the console with ``pages`` headless pages and measure (module docstring); with
    ``camera`` (fps) the emulated camera on, at its default size and quality."""
    from playwright.sync_api import sync_playwright

    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import load_config
    from ucat_console.ui.app import ConsoleApp

    if duration <= 0 or pages < 1:
        raise ValueError(f"duration must be > 0 and pages >= 1, got {duration}, {pages}")
    from ucat_console.backend.camera.config import CameraConfig

    cam = CameraConfig(source="emulated", fps=camera) if camera else CameraConfig()
    # the configuration the console starts on (scripts/run.sh): under the paper's weights the
    # simulated robot does not swim, and the tracking failsafe rightly warns after 10 s
    base = load_config("sim-tuned")
    cfg = base.replace(console=base.console.replace(port=0), camera=cam)
    with tempfile.TemporaryDirectory() as tmp:
        sup = Supervisor(cfg, sessions_dir=tmp)
        app = ConsoleApp(sup, probe=True)
        app.start()
        sup.start()
        try:
            sup.set_setpoints(LOCAL, velocity=velocity)
            sup.arm(LOCAL)
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS + UNTHROTTLED)
                opened = []
                for _ in range(pages):
                    page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]})
                    page.add_init_script(PAGE_PROBE)
                    page.goto(app.url)
                    page.wait_for_function("() => !document.body.innerText.includes('Connecting...')",
                                           timeout=60_000)
                    opened.append(page)
                for page in opened:
                    page.wait_for_function("() => document.querySelectorAll('.uplot').length >= 5",
                                           timeout=60_000)
                time.sleep(warmup)
                for page in opened:
                    page.evaluate(_START_COUNTING)
                scene0, plots0 = app.scene.updates, app.plots.updates
                cpu0, wall0 = time.process_time(), time.perf_counter()
                bytes0, pictures0 = _sent_bytes(app), _pictures_sent(app)
                image0 = sup.recorder.stats().image_bytes
                browser0 = _descendant_cpu_seconds()
                threads0 = _thread_cpu_seconds()
                load0 = os.getloadavg()[0]
                time.sleep(duration)
                cpu1, wall1 = time.process_time(), time.perf_counter()
                bytes1, pictures1 = _sent_bytes(app), _pictures_sent(app)
                image1, dropped = sup.recorder.stats().image_bytes, sup.recorder.stats().dropped
                browser1 = _descendant_cpu_seconds()
                threads1 = _thread_cpu_seconds()
                scene1, plots1 = app.scene.updates, app.plots.updates
                results = [page.evaluate("() => { const b = window.__ucatBench; b.counting = false; return b; }")
                           for page in opened]
                n_plots = opened[0].evaluate("() => document.querySelectorAll('.uplot').length")
                # the supervisor again without the probe (one element more with every pose,
                # sent to every page: the benchmark's instrument, not the console)
                probe_cb, app.view.on_pose = app.view.on_pose, None
                passes, deadline = app.scene.updates, time.monotonic() + 30.0
                while app.scene.updates < passes + 2:  # a whole pose pass without the probe
                    if time.monotonic() > deadline:
                        raise RuntimeError("the live view stopped updating the robot's pose")
                    time.sleep(0.01)
                probe_last_seq = app.view.body_seq  # no probe sent after this carries a later one
                cpu2, wall2, threads2 = time.process_time(), time.perf_counter(), _thread_cpu_seconds()
                time.sleep(duration)
                cpu3, wall3, threads3 = time.process_time(), time.perf_counter(), _thread_cpu_seconds()
                seen = [page.evaluate("() => window.__ucatBench.lastSeq") for page in opened]
                app.view.on_pose = probe_cb
                browser.close()
            parts = page_parts(app)
            health = sup.health()
        finally:
            sup.stop()
            app.stop()
    elapsed = wall1 - wall0
    per_page = []
    for r in results:
        probe = r["probe"]
        lat = [now - wall for now, _, wall in probe]
        per_page.append({
            "pose_updates_delivered_per_s": len(set(r["delivered"])) / elapsed,
            "pose_updates_per_s": len(probe) / elapsed,
            "plot_refresh_per_s": r["redraws"] / max(n_plots, 1) / elapsed,
            "latency_ms_p50": _percentile(lat, 0.50),
            "latency_ms_p95": _percentile(lat, 0.95),
            "latency_ms_max": max(lat) if lat else float("nan"),
            "samples": len(lat),
        })
    return {
        "duration_s": elapsed,
        "pages": per_page,
        "plots": n_plots,
        "server_scene_updates_per_s": (scene1 - scene0) / elapsed,
        "server_plot_updates_per_s": (plots1 - plots0) / elapsed,
        "configured_scene_rate": cfg.console.scene_rate,
        "configured_plot_rate": cfg.console.plot_rate,
        "supervisor_cpu_percent": 100.0 * (cpu1 - cpu0) / elapsed,
        "camera_fps": camera,
        "page_kbytes_per_s": [(bytes1.get(c, 0) - b) / elapsed / 1e3 for c, b in bytes0.items()],
        "camera_pictures_to_pages_per_s": (pictures1 - pictures0) / elapsed,
        "recorded_image_kbytes_per_s": (image1 - image0) / elapsed / 1e3,
        "recorder_dropped": dropped,
        "supervisor_cpu_percent_without_probe": 100.0 * (cpu3 - cpu2) / (wall3 - wall2),
        "supervisor_threads_cpu_percent_without_probe": _thread_percent(threads2, threads3, wall3 - wall2),
        "probe_last_seq_when_off": probe_last_seq,
        "probe_last_seq_seen": seen,
        "browser_cpu_percent": {k: 100.0 * (browser1[k] - browser0[k]) / elapsed for k in browser0},
        "supervisor_threads_cpu_percent": _thread_percent(threads0, threads1, elapsed),
        "recording": health.recording,
        "loop_lag_max_ms": health.lag_max * 1e3,
        "late_plans": health.late_plans,
        "plan_overruns": health.plan_overruns,
        "load_average_1min": load0,
        "cpus": os.cpu_count(),
        "page_parts": parts,
    }


def page_parts(app: Any, refreshes: int = 200) -> dict[str, Any]:
    """The plots' series of one refresh (``plots.series_of``) of the live view's window as
    it is at the end of the run, timed in a tight loop (median of ``refreshes``)."""
    import math

    from ucat_console.ui.plots import series_of

    plots, view = app.plots, app.view
    n = int(math.ceil(float(view.history()) * plots.rate)) + 1
    times = []
    for _ in range(refreshes):
        t0 = time.perf_counter()
        got = series_of(plots.feeder.buffer, n, plots.max_points, plots.corridor())
        times.append(time.perf_counter() - t0)
    if got is None:
        raise RuntimeError("the live plots hold no window of rows: nothing to time")
    return {"plot_series_points": int(got[0].shape[0]), "plot_series_us": statistics.median(times) * 1e6}


def _thread_percent(before: dict[str, float], after: dict[str, float], elapsed: float) -> dict[str, float]:
    """Each thread's CPU between two readings, as % of one core, largest first."""
    return {k: 100.0 * (v - before.get(k, 0.0)) / elapsed
            for k, v in sorted(after.items(), key=lambda kv: before.get(kv[0], 0.0) - kv[1])}


def _threads(percent: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.1f} %" for k, v in percent.items() if v >= 0.5)


def format_result(r: dict[str, Any]) -> str:
    lines = [
        f"console page benchmark: {len(r['pages'])} headless pages, {r['duration_s']:.0f} s, "
        f"{r['cpus']} CPUs, load average {r['load_average_1min']:.1f}; "
        + (f"the emulated camera at {r['camera_fps']:g} fps" if r.get("camera_fps") else "no camera"),
        f"server pushes: scene {r['server_scene_updates_per_s']:.1f}/s (configured {r['configured_scene_rate']:g}), "
        f"plots {r['server_plot_updates_per_s']:.1f}/s (configured {r['configured_plot_rate']:g})",
        "pose updates per second: delivered to the page / displayed in a rendered frame",
        f"{'page':>4} {'pose/s':>13} {'plot/s':>7} {'lat p50':>8} {'lat p95':>8} {'lat max':>8}",
    ]
    for i, p in enumerate(r["pages"]):
        pose = f"{p['pose_updates_delivered_per_s']:.1f} / {p['pose_updates_per_s']:.1f}"
        lines.append(f"{i:>4} {pose:>13} {p['plot_refresh_per_s']:7.1f} "
                     f"{p['latency_ms_p50']:6.0f}ms {p['latency_ms_p95']:6.0f}ms {p['latency_ms_max']:6.0f}ms")
    b = r["browser_cpu_percent"]
    lines.append(f"browser CPU: GPU process (software GL) {b['gpu']:.0f} %, page renderers "
                 f"{b['renderer']:.0f} %, other {b['other']:.0f} % of one core")
    lines.append(f"supervisor CPU {r['supervisor_cpu_percent']:.0f} % of one core; loop lag max "
                 f"{r['loop_lag_max_ms']:.0f} ms; late plans {r['late_plans']}, hand-over overruns "
                 f"{r['plan_overruns']}")
    lines.append("supervisor CPU by thread: " + _threads(r["supervisor_threads_cpu_percent"]))
    lines.append(f"supervisor CPU without the benchmark's probe {r['supervisor_cpu_percent_without_probe']:.0f} %"
                 " of one core; by thread: " + _threads(r["supervisor_threads_cpu_percent_without_probe"]))
    if "page_kbytes_per_s" in r:
        lines.append("sent to each page: " + ", ".join(f"{k:.0f} kB/s" for k in r["page_kbytes_per_s"])
                     + f"; camera pictures to the pages {r['camera_pictures_to_pages_per_s']:.1f}/s; "
                     f"recorded {r['recorded_image_kbytes_per_s']:.0f} kB/s of camera frames, "
                     f"{r['recorder_dropped']} messages dropped by the recorder")
    p = r["page_parts"]
    lines.append(f"in a tight loop: the plots' series of a refresh {p['plot_series_us']:.0f} us "
                 f"({p['plot_series_points']} points)")
    return "\n".join(lines)


def register_bench(kinds: argparse._SubParsersAction) -> None:
    """Add ``ui`` to ``ucat-console bench``."""
    p = kinds.add_parser("ui", help="console page: pose and plot rates, latency, supervisor CPU (headless Chromium)")
    p.add_argument("--duration", type=float, default=20.0, help="measured seconds (after the warm-up)")
    p.add_argument("--pages", type=int, default=2, help="headless pages open on the console")
    p.add_argument("--warmup", type=float, default=5.0, help="seconds before measuring")
    p.add_argument("--chromium", default=CHROMIUM, help="Chromium executable")
    p.add_argument("--camera", type=float, nargs="?", const=30.0, default=None, metavar="FPS",
                   help="the emulated camera on at FPS (default 30; without the option: no camera)")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run_ui)


def run_ui(args: argparse.Namespace) -> int:
    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    if not Path(args.chromium).exists():
        raise ValueError(f"--chromium: {args.chromium} not found")
    from ucat_console.bench.machine import machine_info, speed_line
    from ucat_console.compiled import prepare_all

    if args.camera is not None and not 0.1 <= args.camera <= 30.0:
        raise ValueError(f"--camera: {args.camera} fps must be in [0.1, 30] (camera.fps' range)")
    prepare_all()
    r = measure_ui(duration=args.duration, pages=args.pages, warmup=args.warmup, chromium=args.chromium,
                   camera=args.camera)
    r["machine"] = machine_info(None)
    print(format_result(r))
    print(speed_line(r["machine"]))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    return 0


def summary(r: dict[str, Any]) -> dict[str, float]:
    """The figures docs/performance.md quotes (means over the pages)."""
    pages = r["pages"]
    return {
        "pose_updates_delivered_per_s": statistics.fmean(p["pose_updates_delivered_per_s"] for p in pages),
        "pose_updates_per_s": statistics.fmean(p["pose_updates_per_s"] for p in pages),
        "plot_refresh_per_s": statistics.fmean(p["plot_refresh_per_s"] for p in pages),
        "latency_ms_p95": max(p["latency_ms_p95"] for p in pages),
        "supervisor_cpu_percent": r["supervisor_cpu_percent"],
    }
