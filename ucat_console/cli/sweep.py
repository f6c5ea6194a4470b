"""``ucat-console sweep``: MPC weight grid over E4's closed-loop protocol on the executor."""

from __future__ import annotations

import argparse
from pathlib import Path

from ucat_console.backend.sim.variants import DEFAULT_PLANT, PLANT_VARIANTS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="MPC weight sweep over the E4 protocol (table + plot; savings and "
                                     "energy per metre where both runs track)")
    p.add_argument("--lam-st", type=float, nargs="+", default=[1.0, 2.5, 5.0, 10.0], metavar="X",
                   help="values of lam_st")
    p.add_argument("--lam-d", type=float, nargs="+", default=[0.3, 1.0, 3.0], metavar="X",
                   help="values of lam_d")
    p.add_argument("--velocities", type=float, nargs="+", default=[0.1, 0.2, 0.3], metavar="V",
                   help="reference velocities (m/s)")
    p.add_argument("--seeds", type=int, default=2, help="runs per point (seeds S..S+n-1)")
    p.add_argument("--seed", type=int, default=0, help="first seed")
    p.add_argument("--plant", choices=tuple(PLANT_VARIANTS), default=DEFAULT_PLANT)
    p.add_argument("--formulation", choices=("paper", "closed_stroke"), default="paper",
                   help="the MPC's cost formulation")
    p.add_argument("--quick", action="store_true", help="short runs")
    p.add_argument("--out", type=Path, default=Path("sweep-out"), help="output directory")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="dask scheduler address")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console.bench.extras import require_extra

    require_extra()
    from ucat_console.compiled import prepare_all
    from ucat_console.experiments.runner import run_sweep_command

    if args.seed < 0:
        raise ValueError(f"--seed: {args.seed} must be >= 0")
    prepare_all()
    doc = run_sweep_command(
        args.out, lam_st=args.lam_st, lam_d=args.lam_d, speeds=args.velocities, seeds=args.seeds,
        quick=args.quick, seed=args.seed, plant=args.plant, scheduler=args.scheduler,
        formulation=args.formulation,
    )
    print(f"sweep: {len(doc['experiments']['sweep']['rows'])} rows in "
          f"{doc['experiments']['sweep']['runtime_s']:.1f} s; wrote {args.out}/sweep.csv, sweep.md, report.md")
    return 0
