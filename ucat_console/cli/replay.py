"""``ucat-console replay SESSION --weights lam_st=2.0,...``: counterfactual replay.

SESSION is a session id or any one of its part files; every part is replayed, in order.
Re-plans every recorded fin plan with the given weights and prints recorded and
counterfactual Strouhal number, force error and predicted power side by side (means per
fin); ``--out`` writes every plan's row as CSV.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="counterfactual replay of a session with other MPC weights")
    p.add_argument("file", metavar="SESSION", help="session id or any part file of it")
    p.add_argument("--weights", required=True, metavar="W",
                   help="changed weights, e.g. lam_st=2.0,lam_f=1.5 (lam_f, lam_st, lam_a, lam_d)")
    p.add_argument("--seed", type=int, default=None,
                   help="one planner seed for every plan (default: each plan's recorded seed)")
    p.add_argument("--fins", type=int, nargs="+", default=None, metavar="FIN",
                   help="fins to replay (default: all)")
    p.add_argument("--out", type=Path, default=None, metavar="CSV", help="write every row as CSV")
    p.add_argument("--dir", type=Path, default=None,
                   help="sessions directory (default: $UCAT_CONSOLE_SESSIONS, else the user's "
                        "data folder: ucat-console paths)")
    p.set_defaults(func=run)


COLUMNS = (
    "t", "fin", "mode", "recorded_st", "st", "recorded_force_error", "force_error",
    "recorded_power", "power", "recorded_cost", "cost",
    "recorded_u.0", "recorded_u.1", "recorded_u.2", "recorded_u.3", "u.0", "u.1", "u.2", "u.3",
)


def format_summary(summary: list[dict]) -> str:
    head = (f"{'fin':>4} {'plans':>6} | {'St rec':>7} {'St new':>7} | {'|F err| rec':>11} "
            f"{'|F err| new':>11} | {'P rec (W)':>10} {'P new (W)':>10}")
    lines = [head, "-" * len(head)]
    for s in summary:
        lines.append(
            f"{s['fin']:>4} {s['plans']:>6} | {s['recorded_st']:>7.3f} {s['st']:>7.3f} | "
            f"{s['recorded_force_error']:>11.4f} {s['force_error']:>11.4f} | "
            f"{s['recorded_power']:>10.4f} {s['power']:>10.4f}"
        )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from ucat_console.backend.sessions.reader import SessionParts
    from ucat_console.backend.sessions.replay import counterfactual, parse_weights, recorded_seed
    from ucat_console.compiled import prepare_all

    weights = parse_weights(args.weights)
    if args.out is not None and not args.out.parent.exists():
        raise ValueError(f"--out: directory {args.out.parent} does not exist")
    prepare_all()
    with SessionParts(args.file, args.dir, confined=False) as s:
        result = counterfactual(s, weights, seed=recorded_seed if args.seed is None else args.seed,
                                fins=args.fins)
    rows, skipped, config = result.rows, result.skipped, result.config
    if not rows:
        print("no fin plans to replay")
        return 0
    print(f"weights: lam_f={config.lam_f:g} lam_st={config.lam_st:g} lam_a={config.lam_a:g} "
          f"lam_d={config.lam_d:g}; {len(rows)} plans replayed, {skipped} refused")
    print(format_summary(result.summary()))
    if args.out is not None:
        with open(args.out, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(COLUMNS)
            for r in rows:
                w.writerow([
                    repr(r.t), r.fin, r.mode, repr(r.recorded_st), repr(r.st),
                    repr(r.recorded_force_error), repr(r.force_error), repr(r.recorded_power),
                    repr(r.power), repr(r.recorded_cost), repr(r.cost),
                    *map(repr, r.recorded_u), *map(repr, r.u),
                ])
        print(f"wrote {args.out}")
    return 0
