"""``ucat-console bench mpc``: Table IV of the paper, for the compiled solver and the
scipy reference on the same protocol, plus fixed-case quality and first-call latency."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    bench = sub.add_parser("bench", help="benchmarks (figures for docs/performance.md: `bench report`)")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    p = kinds.add_parser("mpc", help="MPC solve time and cost, numba vs scipy (Table IV)")
    p.add_argument("--n", type=int, nargs="+", default=None, metavar="N",
                   help="sample counts (default: the paper's 250 500 1000 1500 2000 5000)")
    p.add_argument("--solvers", nargs="+", choices=("numba", "scipy"), default=["numba", "scipy"])
    p.add_argument("--formulations", nargs="+", choices=("paper", "closed_stroke"),
                   default=["paper", "closed_stroke"],
                   help="cost formulations (closed_stroke: compiled solver only)")
    p.add_argument("--stages", nargs="+", choices=("sampling", "two_stage"),
                   default=["sampling", "two_stage"])
    p.add_argument("--seeds", type=int, default=1,
                   help="protocol runs per row, with planner seeds 0..S-1 (costs and times pooled)")
    p.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: the last one)")
    p.add_argument("--gap-cases", type=int, default=40,
                   help="fixed cases for the quality gap (0: skip)")
    p.add_argument("--no-first-call", action="store_true", help="skip the first-call latency")
    p.add_argument("--shipped", default="sim-tuned", metavar="NAME|FILE",
                   help="also time the MPC of this configuration as the console runs it (sim-tuned: the "
                        "cycle centred by its cost over a grid); 'none': skip")
    p.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    p.set_defaults(func=run_mpc)
    q = kinds.add_parser("sim", help="headless real-time factor of the closed loop (1 kHz physics)")
    q.add_argument("--seconds", type=float, default=30.0, help="simulated seconds timed per mode")
    from ucat_console.backend.loop.modes import mode_names

    steered = mode_names(follows_targets=True)  # the modes whose fins follow the body loops
    q.add_argument("--modes", nargs="+", choices=steered, default=list(steered))
    q.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: the last one)")
    q.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    q.set_defaults(func=run_sim)

    from ucat_console.bench import library as bench_library
    from ucat_console.bench import load as bench_load
    from ucat_console.bench import pages as bench_pages
    from ucat_console.bench import plant as bench_plant
    from ucat_console.bench import report as bench_report
    from ucat_console.bench import run_report as bench_run_report
    from ucat_console.bench import safety as bench_safety
    from ucat_console.bench import sessions as bench_sessions
    from ucat_console.bench import tracking as bench_tracking
    from ucat_console.bench import tracking_live as bench_tracking_live
    from ucat_console.bench import ui as bench_ui

    bench_sessions.register(kinds)
    bench_library.register(kinds)
    bench_ui.register_bench(kinds)
    bench_safety.register_bench(kinds)
    bench_tracking.register_bench(kinds)
    bench_tracking_live.register_bench(kinds)
    bench_load.register_bench(kinds)
    bench_plant.register_bench(kinds)
    bench_pages.register_bench(kinds)
    bench_report.register_bench(kinds)
    bench_run_report.register_bench(kinds)
    c = kinds.add_parser("compile", help="cold compile of every preparation step, serial and in parallel")
    c.add_argument("--config", default=None, metavar="NAME|FILE", help="the configuration to compile for")
    c.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="process counts to measure")
    c.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    c.set_defaults(func=run_compile)


def run_compile(args: argparse.Namespace) -> int:
    from ucat_console.bench.machine import machine_info
    from ucat_console.cli.prepare import measure_cold
    from ucat_console.config import load_config

    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    cfg = load_config(args.config)
    runs = []
    for w in args.workers:
        if w < 1:
            raise ValueError(f"--workers: {w} must be >= 1")
        r = measure_cold(cfg, w)
        runs.append(r)
        print(f"{w} process{'es' if w > 1 else ''}: ready for the console {r['ready_s']:.1f} s, "
              f"everything {r['complete_s']:.1f} s", flush=True)
        for s in r["steps"]:
            print(f"    {s['text']}: {r['seconds'][s['key']]:.1f} s{'' if s['needed'] else ' (after the start)'}")
    if args.json:
        args.json.write_text(json.dumps({"runs": runs, "machine": machine_info(None)}, indent=2))
        print(f"wrote {args.json}")
    return 0


def run_mpc(args: argparse.Namespace) -> int:
    from ucat_console.bench.extras import require_extra

    require_extra("tqdm")
    from tqdm import tqdm

    from ucat_console.bench import mpc as B
    from ucat_console.compiled import prepare_all
    from ucat_console.bench.machine import machine_info, pin_to_one_core, speed_line
    from ucat_console.control import FinMpc, MpcConfig

    ns = args.n or list(B.PAPER_NS)
    for n in ns:
        if n < 1:
            raise ValueError(f"--n: {n} must be at least 1")
    if args.gap_cases < 0:
        raise ValueError(f"--gap-cases: {args.gap_cases} must be >= 0")
    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    prepare_all()  # before pinning: the child processes would inherit the one core
    cpu = pin_to_one_core(args.cpu)
    base = MpcConfig()
    # the scipy reference solves the paper's formulation only
    combos = [(s, f) for f in args.formulations for s in args.solvers
              if f == "paper" or s == "numba"]
    # compile / load every kernel before timing anything
    for solver, form in combos:
        FinMpc(base.replace(solver=solver, formulation=form)).plan((-0.5, 0.5), 0.3, 0.0, B.U_PREV0)
    first_call = {} if args.no_first_call else B.first_call_latency()

    runs = []
    if args.seeds < 1:
        raise ValueError(f"--seeds: {args.seeds} must be at least 1")
    total = len(ns) * len(combos) * len(args.stages) * 121 * B.CYCLES * args.seeds
    with tqdm(total=total, desc="bench mpc", unit="solve", file=sys.stderr) as bar:
        for n in ns:
            for solver, form in combos:
                for stage in args.stages:
                    cfg = base.replace(n_samples=n, solver=solver, formulation=form)
                    res = None
                    for seed in range(args.seeds):
                        r = B.run_protocol(cfg, refine=stage == "two_stage", seed=seed,
                                           on_solve=lambda: bar.update())
                        res = r if res is None else res.merge(r)
                    runs.append(res.row())
    shipped = None
    if args.shipped != "none":
        from ucat_console.config import load_config

        mpc_cfg = load_config(args.shipped).loop.mpc
        FinMpc(mpc_cfg).plan((-0.5, 0.5), 0.3, 0.0, B.U_PREV0)  # its kernels loaded before timing
        shipped = B.run_protocol(mpc_cfg, refine=True, seed=0).row()
        shipped.update(config=args.shipped, centre_rate=mpc_cfg.centre_rate, centre_grid=mpc_cfg.centre_grid)
    gap = {}
    if args.gap_cases:
        cases = B.fixed_cases(args.gap_cases)
        gap = B.quality_gap(
            {f"{s}_n{base.n_samples}": base.replace(solver=s) for s in args.solvers}, cases
        )

    print(B.format_table(runs))
    if shipped is not None:
        print(f"\nthe MPC of {shipped['config']} as the console runs it ({shipped['formulation']}, N = "
              f"{shipped['n']}, centre_rate {shipped['centre_rate']:g} rad/s, centre_grid {shipped['centre_grid']}): "
              f"p50 {shipped['p50_us']:.1f} us, p99 {shipped['p99_us']:.1f} us")
    machine = machine_info(cpu)
    print(speed_line(machine))
    if first_call:
        print(f"\nfirst plan in a fresh process: {first_call['cached_first_plan_s'] * 1e3:.0f} ms "
              f"with the compiled cache, {first_call['cold_first_plan_s']:.1f} s cold (compiling)")
    if gap:
        print(f"\nfixed cases ({args.gap_cases} cases x 3 seeds), cost above the exhaustive best:")
        for name, g in gap.items():
            print(f"  {name:>12}: mean {g['mean_gap']:.4f}  p90 {g['p90_gap']:.4f}  "
                  f"max {g['max_gap']:.4f}")
    if args.json:
        doc = {"runs": runs, "shipped": shipped, "machine": machine, "first_call": first_call,
               "quality_gap": gap, "protocol": {"v_body": B.V_BODY, "cycles": B.CYCLES,
                                                "targets": 121, "u_prev0": B.U_PREV0,
                                                "seeds": args.seeds}}
        args.json.write_text(json.dumps(doc, indent=2))
        print(f"\nwrote {args.json}")
    return 0


def run_sim(args: argparse.Namespace) -> int:
    from ucat_console.bench.sim import TELEMETRY, measure_realtime_factor
    from ucat_console.bench.machine import machine_info, pin_to_one_core, speed_line
    from ucat_console.compiled import prepare_all

    if not 0.0 < args.seconds <= 3600.0:
        raise ValueError(f"--seconds: {args.seconds} must be in (0, 3600]")
    if args.json is not None and not args.json.parent.exists():
        raise ValueError(f"--json: directory {args.json.parent} does not exist")
    prepare_all()  # before pinning: the child processes would inherit the one core
    cpu = pin_to_one_core(args.cpu)
    factors: dict[str, dict[str, float]] = {t: {} for t in TELEMETRY}
    chunks: dict[str, dict[str, list[float]]] = {t: {} for t in TELEMETRY}
    for mode in args.modes:
        for telemetry in TELEMETRY:
            median, per_chunk = measure_realtime_factor(mode, args.seconds, telemetry=telemetry)
            factors[telemetry][mode], chunks[telemetry][mode] = median, per_chunk
            print(f"closed loop, {mode:>8}, {telemetry:>10}: {median:,.0f}x real time (median of "
                  f"{len(per_chunk)} chunks, {min(per_chunk):,.0f}-{max(per_chunk):,.0f}x; one core, "
                  f"1 kHz physics)", flush=True)
    machine = machine_info(cpu)
    print(speed_line(machine))
    if args.json:
        args.json.write_text(json.dumps({"realtime_factor": factors, "chunks": chunks,
                                         "seconds": args.seconds, "machine": machine}, indent=2))
        print(f"wrote {args.json}")
    return 0