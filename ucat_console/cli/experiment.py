"""``ucat-console experiment {E1,E2,E3,E4,E5,all}``: the paper's experiments in simulation."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ucat_console.bench.extras import require_extra
from ucat_console.experiments import EXPERIMENTS, NAMED_ONLY


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "experiment", help="reproduce the paper's experiments (report.md, results.json, figures)",
        description="Run experiments of experiments.md headless on the simulated U-CAT and write "
                    "DIR/report.md, DIR/results.json and PNG figures.",
    )
    p.add_argument("names", nargs="+", metavar="NAME", help=f"{', '.join(EXPERIMENTS + NAMED_ONLY)} or all (all: not E7, E8)")
    p.add_argument("--quick", action="store_true", help="reduced runs (short, fewer seeds and targets)")
    p.add_argument("--out", type=Path, default=Path("experiments-out"), help="output directory DIR")
    p.add_argument("--seed", type=int, default=0, help="base seed of planners and sensor noise")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="dask scheduler address (default: a local cluster of worker processes)")
    p.add_argument("--velocities", type=float, nargs="+", default=None, metavar="V",
                   help="E4 reference velocities (m/s; default 0.1 0.2 0.3 0.4)")
    p.add_argument("--depth", type=float, default=None, help="depth setpoint of E4 / E5 (m)")
    p.add_argument("--seeds", type=int, default=None, metavar="N",
                   help="E7 and E8 only: their declared reduced design, the first N of their 10 seeds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    require_extra()
    from ucat_console.compiled import prepare_all
    from ucat_console.experiments.runner import run_experiments

    prepare_all()
    command = "ucat-console experiment " + " ".join(sys.argv[2:] if len(sys.argv) > 2 else args.names)
    doc = run_experiments(
        args.names, args.out, quick=args.quick, seed=args.seed, scheduler=args.scheduler,
        speeds=args.velocities, depth=args.depth, command=command, e7_seeds=args.seeds,
    )
    for name, res in doc["experiments"].items():
        print(f"{name}: {res['runtime_s']:.1f} s")
    print(f"wrote {args.out / 'report.md'} and {args.out / 'results.json'}")
    return 0
