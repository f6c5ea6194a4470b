"""After each of E8's changes of the robot, every fixed frequency of a fine grid, measured as E8
measures the baseline tuned before the change: how far below that gait could any fixed gait be?

Not part of E8's declaration (run after it, to read its rule 3): on ``plate_cd0.05`` at 0.2 m/s,
for each change (E8's three, and ``weak_fin``, which E8 does not have: paper fin 2's drive at
half speed, as ``bench tracking``'s case), frequency and seed, the baseline from rest, 30 s held, 60 s measured, the change,
and the 30-s window ending 120 s after it (``experiments.e8.run_job``, the job E8 runs for
``baseline_tuned``). Prints, per change and frequency, the mean energy per metre after the change,
how many seeds tracked, and the saving against the gait tuned before the change (per seed, the
least and the most), and writes every window as JSON.

    python scripts/e8_change_sweep.py [--changes ...] [--tuned 1.0] [--seeds 3] [--jobs 1] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from ucat_console.experiments.e8 import CHANGE_PLANT, CHANGE_SPEED, CHANGES, Job, run_job, tracks

FREQUENCIES = (0.5, 0.625, 0.75, 0.875, 1.0, 1.125, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0)


def one(job: tuple[str, float, int]) -> dict:
    change, f, seed = job
    r = run_job(Job(CHANGE_PLANT, CHANGE_SPEED, seed, "baseline_tuned", values=(("baseline.frequency", f),),
                    change=change))
    return {"change": change, "frequency": f, "seed": seed, "before": r["window"], "after": r["after_change"],
            "fault": r["fault"]}


def table(runs: list[dict], tuned: float, changes: tuple[str, ...] = CHANGES) -> str:
    lines = ["| change | frequency (Hz) | energy per metre after (J/m, mean) | tracking | saving against "
             f"{tuned:g} Hz (%, least..most of the seeds) |", "|---|---|---|---|---|"]
    for change in changes:
        mine = [r for r in runs if r["change"] == change]
        ref = {r["seed"]: r["after"]["energy_per_metre"] for r in mine if r["frequency"] == tuned}
        for f in sorted({r["frequency"] for r in mine}):
            at = [r for r in mine if r["frequency"] == f]
            saving = [100.0 * (1.0 - r["after"]["energy_per_metre"] / ref[r["seed"]]) for r in at]
            lines.append(f"| {change} | {f:g} | {statistics.mean(r['after']['energy_per_metre'] for r in at):.2f} | "
                         f"{sum(tracks(r['after']) for r in at)} of {len(at)} | "
                         f"{min(saving):+.1f}..{max(saving):+.1f} |")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--changes", nargs="+", choices=(*CHANGES, "weak_fin"), default=list(CHANGES))
    p.add_argument("--frequencies", nargs="+", type=float, default=list(FREQUENCIES), help="Hz")
    p.add_argument("--tuned", type=float, default=1.0, help="the frequency tuned before the change (E8's report)")
    p.add_argument("--seeds", type=int, default=3, help="test seeds 0..N-1")
    p.add_argument("--jobs", type=int, default=1, help="processes")
    p.add_argument("--json", type=Path, default=None, help="write every run's windows here")
    a = p.parse_args()
    if a.tuned not in a.frequencies:
        p.error(f"--tuned: {a.tuned:g} Hz is not among --frequencies {', '.join(f'{f:g}' for f in a.frequencies)}")
    from ucat_console.compiled import prepare_all

    prepare_all("sim-tuned")
    jobs = [(c, f, s) for c in a.changes for f in a.frequencies for s in range(a.seeds)]
    with ProcessPoolExecutor(a.jobs) as ex:
        runs = list(ex.map(one, jobs))
    print(table(runs, a.tuned, tuple(a.changes)))
    if a.json is not None:
        a.json.write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
