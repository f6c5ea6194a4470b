"""E8: the efficiency seeker against the tuned and the paper's gaits, and after the robot changes.

Declared before it was run (docs/experiments/e8-declaration.md, which prints the plants'
hash, :func:`~ucat_console.experiments.efficiency_curves.plant_hash`). Every run is the
console itself (``backend.supervisor.Supervisor`` on the simulated robot in simulated time,
its loop stepped in the run's own thread, so that every command comes at the simulated time
the timing says and a job gives the same figures every time) on one of E7's energy-consistent plates
(:data:`E8_PLANTS`), measured by the seeker's own figures (``review.metrics.table_row``:
the battery's energy per metre with its bootstrap interval over the fin cycles, the speed,
depth and heading tracking errors). A run is a function of its :class:`Job` (a plant, a
speed, a seed, a controller, the timing) returning plain numbers, so it runs in a dask
worker (:func:`run_job`).

Controllers (:data:`FIXED`, :data:`SEEKERS`): the paper's 2 Hz fixed-frequency baseline, that
baseline at the frequency tuned per plant and speed on the held-out seed (the least energy
per metre among :data:`TUNING_FREQUENCIES` that tracks), the MPC with the shipped
``sim-tuned`` weights, and the seeker over the baseline's frequency and over the MPC's
Strouhal terms (:data:`SEEK_PARAMS`). A seeker's figure is its best, left in force when its
search ends, measured over the fixed controllers' window after the seek's settle time.

Robot changes (:data:`CHANGES`): the seeker finds its best on the nominal robot, the robot
changes, it seeks again; against the baseline at the frequency tuned before the change.
The analysis (:func:`compare`, :func:`decisions`) and the words (:func:`findings`) are the
declaration's, evaluated mechanically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ucat_console.backend.seek.config import SeekConfig, SeekParam
from ucat_console.backend.sim.params import VehicleConfig
from ucat_console.backend.sim.variants import cd0_name, plant_assumptions, plant_config
from ucat_console.bench.tracking import CASES, WEAK_FIN
from ucat_console.experiments.distributed import run_all
from ucat_console.experiments.e7 import TUNING_FREQUENCIES, paired_saving
from ucat_console.experiments.efficiency_curves import plant_hash
from ucat_console.robot.fins import PAPER_TO_ROBOT

#: E7's energy-consistent plates (the plate over the profile drag C_D0), not its null plant
E8_PLANTS = tuple(cd0_name(c) for c in (0.02, 0.05, 0.3))
E8_SPEEDS = (0.1, 0.2, 0.3, 0.4)
E8_SEEDS = 10
#: the seed the fixed frequency is tuned on (+ the base seed); never a test seed
HELD_OUT_SEED = 1000
FIXED = ("baseline_2hz", "baseline_tuned", "mpc_shipped")
SEEKERS = ("seek_baseline", "seek_mpc")
#: what each seeker searches: its loop mode and its parameters' bounds
SEEK_PARAMS: dict[str, tuple[str, tuple[SeekParam, ...]]] = {
    "seek_baseline": ("baseline", (SeekParam(name="baseline.frequency", lo=0.5, hi=3.0),)),
    "seek_mpc": ("mpc", (SeekParam(name="mpc.st_opt", lo=0.2, hi=0.6), SeekParam(name="mpc.lam_st", lo=0.5, hi=20.0))),
}
#: the robot changes: name -> what changes in the hull (``VehicleConfig``)
CHANGES = ("drag_x1.3", "mass_x1.25", "current")
DRAG_FACTOR = 1.3  # on the surge damping X_u and X_uu
CHANGE_PLANT = cd0_name(0.05)
CHANGE_SPEED = 0.2
#: decision rules
NO_WORSE_PCT = 3.0  # the seeker is no worse when its saving's interval lies above -3 %
PAPER_PCT = 10.0
CHANGE_PCT = 10.0
CONVERGED_PCT = 5.0  # a search has converged at the first accepted candidate within 5 % of its best
#: the seek's tracking bands (the seeker's defaults): a window tracks when every error is inside
BANDS = {"speed_mae": SeekConfig().speed_band, "depth_mae": SeekConfig().depth_band,
         "heading_mae": SeekConfig().heading_band}


@dataclass(frozen=True)
class Timing:
    """Simulated seconds of a run's phases."""

    hold_s: float = 30.0  # from rest to the first measure (fixed) or the seek's start
    window_s: float = 60.0  # a fixed run's measured window
    seek_settle_s: float = 10.0
    seek_window_s: float = 30.0
    candidates: int = 20
    confirm: int = 3  # the nominal search's best measured again (none after a change: its time is short)
    after_change_s: float = 120.0  # the seeker's time after a change

    @property
    def reseek_candidates(self) -> int:
        """The candidates that fit in the time after a change (the start's included)."""
        return max(1, int(self.after_change_s // (self.seek_settle_s + self.seek_window_s)))


DECLARED = Timing()


@dataclass(frozen=True)
class Job:
    """One run: a controller on a plant at a speed with a seed (``values``: tunable
    parameters set before arming; ``change``: a robot change after ``hold_s + window_s``
    (fixed) or after the nominal search (seekers))."""

    plant: str
    v_ref: float
    seed: int
    controller: str
    timing: Timing = DECLARED
    values: tuple[tuple[str, float], ...] = ()
    change: str = ""
    tag: str = field(default="", compare=False)


def changed_vehicle(v: VehicleConfig, change: str) -> VehicleConfig:
    """The hull after ``change`` (mass and current as ``bench tracking``'s cases)."""
    if change == "drag_x1.3":
        return v.replace(x_u=v.x_u * DRAG_FACTOR, x_uu=v.x_uu * DRAG_FACTOR)
    if change == "mass_x1.25":
        return v.replace(mass=v.mass * CASES["mass_x1.25"].mass)
    if change == "current":
        return v.replace(current_ned=CASES["current"].current)
    raise ValueError(f"change: {change!r} is not one of {', '.join(CHANGES)}")


def design(seed: int, n_seeds: int | None = None, plants: tuple[str, ...] = E8_PLANTS,
           speeds: tuple[float, ...] = E8_SPEEDS, timing: Timing = DECLARED) -> dict[str, Any]:
    """The plants, speeds, test seeds, the held-out seed and the timing of a run."""
    if n_seeds is not None and not 1 <= n_seeds <= E8_SEEDS:
        raise ValueError(f"--seeds: {n_seeds} is not in 1..{E8_SEEDS}")
    n = E8_SEEDS if n_seeds is None else n_seeds
    seeds = [seed + k for k in range(n)]
    held = HELD_OUT_SEED + seed
    if held in seeds:
        raise ValueError(f"seed: the held-out seed {held} would be a test seed")
    return {"plants": list(plants), "speeds": list(speeds), "seeds": seeds, "held_out": held,
            "frequencies": list(TUNING_FREQUENCIES), "changes": list(CHANGES), "change_plant": CHANGE_PLANT,
            "change_speed": CHANGE_SPEED, "timing": timing}


def tuning_jobs(d: dict[str, Any]) -> list[Job]:
    return [Job(p, v, d["held_out"], "baseline_tuned", d["timing"], (("baseline.frequency", f),), tag="tune")
            for p in d["plants"] for v in d["speeds"] for f in d["frequencies"]]


def test_jobs(d: dict[str, Any], freq: dict[tuple[str, float], float]) -> list[Job]:
    """Every plant, speed, test seed: the fixed controllers and the seekers."""
    out = []
    for p in d["plants"]:
        for v in d["speeds"]:
            for s in d["seeds"]:
                out.append(Job(p, v, s, "baseline_2hz", d["timing"], (("baseline.frequency", 2.0),)))
                out.append(Job(p, v, s, "baseline_tuned", d["timing"], (("baseline.frequency", freq[(p, v)]),)))
                out.append(Job(p, v, s, "mpc_shipped", d["timing"]))
                out += [Job(p, v, s, k, d["timing"]) for k in SEEKERS]
    return out


def change_jobs(d: dict[str, Any], freq: dict[tuple[str, float], float]) -> list[Job]:
    """Each change and test seed: the seekers and the baseline tuned before the change."""
    p, v = d["change_plant"], d["change_speed"]
    f = freq[(p, v)]
    return [Job(p, v, s, c, d["timing"], (("baseline.frequency", f),) if c == "baseline_tuned" else (), change=ch)
            for ch in d["changes"] for s in d["seeds"] for c in ("baseline_tuned",) + SEEKERS]


# ---------------------------------------------------------------------------------- one run
def tracks(figs: dict[str, Any]) -> bool:
    """A window tracks: every tracking error measured and inside its band (:data:`BANDS`)."""
    return all(figs.get(k) is not None and math.isfinite(figs[k]) and figs[k] <= b for k, b in BANDS.items())


def _window(data: Any, t0: float, t1: float, metrics: Any, label: str) -> dict[str, Any]:
    """The figures of ``[t0, t1]``; a window without readings (the loop stopped: its fault is
    the run's ``fault``) has NaN figures, which do not track."""
    from ucat_console.backend.review.metrics import table_row

    try:
        return _figures(table_row(data, t0, t1, metrics, label))
    except ValueError as e:
        return {k: math.nan for k in ("energy_per_metre", "lo", "hi", "power", "speed", "speed_mae", "depth_mae",
                                      "heading_mae")} | {"source": f"no figures ({e})"}


def _figures(row: Any) -> dict[str, Any]:
    f = row.figures
    e = f["energy_per_metre"]
    return {"energy_per_metre": e.value, "lo": e.lo, "hi": e.hi, "power": f["power"].value,
            "speed": f["speed"].value, "speed_mae": f["speed_mae"].value, "depth_mae": f["depth_mae"].value,
            "heading_mae": f["heading_mae"].value, "source": row.source}


def _apply(loop: Any, values: tuple[tuple[str, float], ...]) -> Any:
    """The loop configuration with tunable ``block.field`` values (the baseline's, the MPC's)."""
    for key, value in values:
        block, _, name = key.partition(".")
        if block not in ("baseline", "mpc"):
            raise ValueError(f"values: {key!r} is not a baseline.* or mpc.* parameter")
        loop = loop.replace(**{block: getattr(loop, block).replace(**{name: value})})
    return loop


def run_job(job: Job) -> dict[str, Any]:
    """One run on the console (module docstring): its figures, for a seeker its candidates,
    its best values and their time to converge."""
    from ucat_console.backend.access import LOCAL
    from ucat_console.backend.loop.clock import SimulatedClock
    from ucat_console.backend.loop.commands import CommandRefused
    from ucat_console.backend.review.metrics import TABLE_CHANNELS, RunData
    from ucat_console.backend.robots import robot
    from ucat_console.backend.supervisor import Supervisor
    from ucat_console.config import load_config
    from ucat_console.telemetry import channels as ch

    t = job.timing
    seeking = job.controller in SEEKERS
    mode = SEEK_PARAMS[job.controller][0] if seeking else ("mpc" if job.controller == "mpc_shipped" else "baseline")
    base = load_config("sim-tuned")
    params = SEEK_PARAMS[job.controller][1] if seeking else (SeekParam(),)
    seek = SeekConfig(params=params, settle_s=t.seek_settle_s, window_s=t.seek_window_s,
                      max_candidates=t.candidates, confirm=t.confirm, seed=job.seed, drift_check=False)
    loop = _apply(base.loop.replace(mode=mode, planner_seed=job.seed), job.values)
    cfg = base.replace(plant=plant_config(job.plant, job.seed), loop=loop, seek=seek,
                       console=base.console.replace(record_on_arm=False))
    held: list[Any] = []

    def factory(c: Any, events: Any) -> Any:
        io, close = robot(c.robot).build(c.devices, c.plant, events)
        held.append(io)
        return io, close

    # the compiled code is prepared before the runs (``ucat-console experiment`` does it):
    # a dask worker is a daemon process and cannot prepare it in processes of its own
    sup = Supervisor(cfg, clock=SimulatedClock(), robot_factory=factory)
    data = RunData()
    events: list[Any] = []
    sup.stream.subscribe(data.feed, TABLE_CHANNELS)
    sup.stream.subscribe(lambda c, ev: events.append(ev) if ev.source == "seek" and ev.code == "candidate" else None,
                         [ch.EVENTS])
    out: dict[str, Any] = {"job": _job_dict(job)}

    # the loop steps in this thread (``Supervisor.step``): each command below is given at the
    # simulated time the run's timing says, so a job gives the same figures every time
    fault: list[str] = []
    period = cfg.console.supervise_period

    def wait(until: Any) -> None:
        while not fault and not until():
            try:
                sup.step(period)
            except Exception as e:  # the loop failed: the run's fault, its windows without figures
                fault.append(f"{type(e).__name__}: {e}")

    def change() -> float:
        io = held[0]
        if job.change == "weak_fin":  # not one of E8's declared changes (scripts/e8_change_sweep.py)
            io.weaken_fin(PAPER_TO_ROBOT[WEAK_FIN], CASES["weak_fin"].weak)
        else:
            io.plant.change_vehicle(changed_vehicle(io.plant.cfg.vehicle, job.change))
        return sup.loop.time

    try:
        sup.set_setpoints(LOCAL, velocity=job.v_ref, depth=1.0, yaw_rate=0.0)
        sup.arm(LOCAL)
        t0 = sup.loop.time
        if not seeking:
            m0 = t0 + t.hold_s
            wait(lambda: sup.loop.time >= m0 + t.window_s)
            out["window"] = _window(data, m0, m0 + t.window_s, cfg.metrics, "fixed")
            if job.change:
                tc = change()
                out["t_change"] = tc
                end = tc + t.after_change_s
                wait(lambda: sup.loop.time >= end)
                out["after_change"] = _window(data, end - t.seek_window_s, end, cfg.metrics, "after")
        else:
            wait(lambda: sup.loop.time >= t0 + t.hold_s)
            run = sup.start_seek(LOCAL)
            s0 = sup.loop.time
            wait(lambda: run.finished)
            out["search"] = _search(run, s0, events)
            if not job.change:  # the best, in force, measured as the fixed controllers are
                m0 = sup.loop.time + t.seek_settle_s
                wait(lambda: sup.loop.time >= m0 + t.window_s)
                out["window"] = _window(data, m0, m0 + t.window_s, cfg.metrics, "best")
            elif fault:  # the loop stopped in the nominal search: no second one
                out["after_change"] = {"reason": "the loop stopped", "candidates": [], "converged_s": math.nan}
            else:
                tc = change()
                out["t_change"] = tc
                try:
                    again = sup.start_seek(LOCAL, candidates=t.reseek_candidates, seed=job.seed + 1, confirm=0)
                except CommandRefused as e:  # a failsafe ended the nominal search: tracking not held
                    out["after_change"] = {"reason": f"no second search: {e}", "candidates": [],
                                           "converged_s": math.nan}
                else:
                    wait(lambda: again.finished)
                    out["after_change"] = _search(again, tc, events)
        out["fault"] = fault[0] if fault else ""
    finally:
        sup.stop()
    return out


def _search(run: Any, s0: float, events: list[Any]) -> dict[str, Any]:
    """A search's candidates, its best, and its time to converge (s from its start); the
    candidates' windows' ends from their events (the last ``len(run.candidates)``)."""
    cands = [{"index": c.index, "values": dict(c.values), "verdict": c.verdict, "accepted": c.accepted,
              "confirms": c.confirms,
              "energy_per_metre": None if c.energy is None else c.energy.value,
              "lo": None if c.energy is None else c.energy.lo, "hi": None if c.energy is None else c.energy.hi}
             for c in run.candidates]
    best = run.best
    ends = [ev.data.get("t1", math.nan) for ev in events[len(events) - len(cands):]]  # a refused one: none
    return {"reason": run.reason, "candidates": cands, "ends": ends, "start_time": s0,
            "best": None if best is None or best.energy is None else
            {"values": dict(best.values), "energy_per_metre": best.energy.value, "lo": best.energy.lo,
             "hi": best.energy.hi},
            "converged_s": converged_s(cands, ends, s0)}


def converged_s(cands: list[dict[str, Any]], ends: list[float], s0: float) -> float:
    """Seconds from the search's start to the end of the window of its first accepted
    candidate within :data:`CONVERGED_PCT` of its best; NaN when none was accepted. The
    search's own candidates' first measures only (not the second measures after it)."""
    first = [(c, end) for c, end in zip(cands, ends) if c.get("confirms") is None
             and c["accepted"] and c["energy_per_metre"] is not None]
    if not first:
        return math.nan
    best = min(c["energy_per_metre"] for c, _ in first)
    for c, end in first:
        if c["energy_per_metre"] <= best * (1 + CONVERGED_PCT / 100):
            return end - s0
    return math.nan


def _job_dict(job: Job) -> dict[str, Any]:
    return {"plant": job.plant, "v_ref": job.v_ref, "seed": job.seed, "controller": job.controller,
            "values": dict(job.values), "change": job.change, "tag": job.tag}


def best_after_change(run: dict[str, Any]) -> dict[str, Any] | None:
    """The seeker's figure after a change: its best accepted candidate whose window ended
    within the time after the change; None when none did (tracking not held)."""
    a = run["after_change"]
    ok = [c for c in a["candidates"] if c["accepted"] and c["energy_per_metre"] is not None]
    return min(ok, key=lambda c: c["energy_per_metre"]) if ok else None


# ---------------------------------------------------------------------------------- analysis
def tune(runs: list[dict[str, Any]]) -> dict[tuple[str, float], float]:
    """Per (plant, speed): the frequency with the least energy per metre among the held-out
    runs that track; missing where none tracks."""
    best: dict[tuple[str, float], tuple[float, float]] = {}
    for r in runs:
        j, w = r["job"], r["window"]
        key, e = (j["plant"], j["v_ref"]), w["energy_per_metre"]
        if tracks(w) and math.isfinite(e) and (key not in best or e < best[key][1]):
            best[key] = (j["values"]["baseline.frequency"], e)
    return {k: v[0] for k, v in best.items()}


#: (A, B) comparisons per plant-speed case; the rules read the seekers' against the baselines
COMPARISONS = tuple((a, b) for a in SEEKERS for b in FIXED)


def compare(rows: list[dict[str, Any]], plant: str, v: float) -> list[dict[str, Any]]:
    """Every comparison of :data:`COMPARISONS` in one case, paired by seed over the seeds where both track."""
    by = {(r["controller"], r["seed"]): r for r in rows if r["plant"] == plant and r["v_ref"] == v}
    out = []
    for a, b in COMPARISONS:
        seeds = sorted(s for (c, s) in by if c == a and (b, s) in by and by[(a, s)]["tracks"] and by[(b, s)]["tracks"])
        res = paired_saving([by[(a, s)]["energy_per_metre"] for s in seeds],
                            [by[(b, s)]["energy_per_metre"] for s in seeds])
        out.append({"plant": plant, "v_ref": v, "a": a, "b": b, **res})
    return out


def compare_changes(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per change and seeker: its saving after the change against the baseline tuned before it,
    over the seeds where the seeker held tracking and the baseline tracked."""
    out = []
    for change in sorted({r["change"] for r in rows}):
        by = {(r["controller"], r["seed"]): r for r in rows if r["change"] == change}
        for a in SEEKERS:
            seeds = sorted(s for (c, s) in by if c == a and ("baseline_tuned", s) in by
                           and by[(a, s)]["tracks"] and by[("baseline_tuned", s)]["tracks"])
            res = paired_saving([by[(a, s)]["energy_per_metre"] for s in seeds],
                                [by[("baseline_tuned", s)]["energy_per_metre"] for s in seeds])
            held = sum(1 for (c, s), r in by.items() if c == a and r["tracks"])
            runs = sum(1 for (c, s) in by if c == a)
            out.append({"change": change, "a": a, "b": "baseline_tuned", "held": held, "runs": runs, **res})
    return out


def decisions(comparisons: list[dict[str, Any]], changes: list[dict[str, Any]]) -> dict[str, Any]:
    """The declared decision rules, per seeker (docs/experiments/e8-declaration.md)."""
    out: dict[str, Any] = {}
    for a in SEEKERS:
        tuned = [c for c in comparisons if c["a"] == a and c["b"] == "baseline_tuned"]
        paper = [c for c in comparisons if c["a"] == a and c["b"] == "baseline_2hz"]
        r1 = [c for c in tuned if c["comparable"] and c["lo"] > -NO_WORSE_PCT]
        p_comp = [c for c in paper if c["comparable"]]
        r2 = [c for c in p_comp if c["saving"] >= PAPER_PCT and c["lo"] > 0.0]
        ch = [c for c in changes if c["a"] == a]
        r3 = [c for c in ch if c["comparable"] and c["held"] == c["runs"] and c["saving"] >= CHANGE_PCT
              and c["lo"] > 0.0]
        out[a] = {
            "rule1": {"cases": len(tuned), "no_worse": len(r1),
                      "verdict": bool(tuned) and len(r1) == len(tuned)},
            "rule2": {"cases": len(paper), "comparable": len(p_comp), "met": len(r2),
                      "verdict": bool(p_comp) and len(r2) == len(p_comp)},
            "rule3": {"changes": len(ch), "met": len(r3), "verdict": bool(ch) and len(r3) == len(ch)},
        }
    return out


def rows_of(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per run: the figure the rules read (a seeker's best re-measured from rest is
    its own run: ``window``); for a seeker, the values it ended on (its search's best; after a
    change, the candidate whose figure is read) and why its search ended (``search_end``)."""
    rows = []
    for r in runs:
        j = r["job"]
        values, reason = j["values"], ""
        search = r.get("after_change") if j["change"] else r.get("search")
        if j["controller"] in SEEKERS and search is not None:  # what the seeker ended on, and why
            reason = search.get("reason", "")
            best = best_after_change(r) if j["change"] else search.get("best")
            values = best["values"] if best else {}
        if j["change"]:
            if j["controller"] in SEEKERS:
                b = best_after_change(r)
                e = math.nan if b is None else b["energy_per_metre"]
                ok = b is not None
            else:
                w = r["after_change"]
                e, ok = w["energy_per_metre"], tracks(w)
        else:
            w = r["window"]
            e, ok = w["energy_per_metre"], tracks(w)
        rows.append({"plant": j["plant"], "v_ref": j["v_ref"], "controller": j["controller"], "seed": j["seed"],
                     "change": j["change"], "values": values, "energy_per_metre": e, "tracks": bool(ok),
                     "fault": r.get("fault", ""), "search_end": reason})
    return rows


# ---------------------------------------------------------------------------------- the whole run
def run_e8(client: Any, seed: int, progress: bool = True, n_seeds: int | None = None,
           d: dict[str, Any] | None = None) -> dict[str, Any]:
    """Tune on the held-out seed, run the test seeds and the changes, analyse (``d``: a
    design of :func:`design`; default the declared one with ``n_seeds``)."""
    d = d or design(seed, n_seeds)
    tuned = run_all(client, run_job, tuning_jobs(d), "E8 tuning", progress)
    chosen = tune(tuned)
    freq = {(p, v): chosen.get((p, v), 2.0) for p in d["plants"] for v in d["speeds"]}
    if (d["change_plant"], d["change_speed"]) not in freq:
        raise ValueError(f"design: the change's case ({d['change_plant']}, {d['change_speed']}) is not tuned")
    runs = run_all(client, run_job, test_jobs(d, freq), "E8 runs", progress)
    changed = run_all(client, run_job, change_jobs(d, freq), "E8 changes", progress) if d["changes"] else []
    rows, change_rows = rows_of(runs), rows_of(changed)
    comparisons = [c for p in d["plants"] for v in d["speeds"] for c in compare(rows, p, v)]
    change_cmp = compare_changes(change_rows)
    conv = [{"plant": r["job"]["plant"], "v_ref": r["job"]["v_ref"], "controller": r["job"]["controller"],
             "seed": r["job"]["seed"], "change": r["job"]["change"], "converged_s": r["search"]["converged_s"],
             "after_change_converged_s": r["after_change"]["converged_s"] if "after_change" in r else None,
             "best": r["search"]["best"]} for r in runs + changed if "search" in r]
    t = d["timing"]
    return {
        "protocol": {**{k: v for k, v in d.items() if k != "timing"}, "timing": vars(t),
                     "reseek_candidates": t.reseek_candidates, "bands": BANDS,
                     "seek_params": {k: {"mode": m, "params": [[p.name, p.lo, p.hi] for p in ps]}
                                     for k, (m, ps) in SEEK_PARAMS.items()},
                     "drag_factor": DRAG_FACTOR, "no_worse_pct": NO_WORSE_PCT, "paper_pct": PAPER_PCT,
                     "change_pct": CHANGE_PCT, "converged_pct": CONVERGED_PCT,
                     "plant_hash": plant_hash(d["plants"]), "declared_hash": plant_hash(list(E8_PLANTS)),
                     "reduced": bool(len(d["seeds"]) < E8_SEEDS), "declared_timing": t == DECLARED},
        "plants": {p: plant_assumptions(p) for p in d["plants"]},
        "tuning": [{"plant": p, "v_ref": v, "frequency": freq[(p, v)], "tracks": (p, v) in chosen}
                   for p in d["plants"] for v in d["speeds"]],
        "rows": [{k: v for k, v in r.items() if k != "values"} | {"values": ", ".join(
            f"{k} {x:.4g}" for k, x in r["values"].items())} for r in rows + change_rows],
        "comparisons": comparisons,
        "change_comparisons": change_cmp,
        "convergence": conv,
        "decisions": decisions(comparisons, change_cmp),
    }


def findings(res: dict[str, Any]) -> list[str]:
    """The decision rules' outcomes, as declared, in words, per seeker."""
    p = res["protocol"]
    out = [f"Plants hash {p['plant_hash']} (declared: {p['declared_hash']})"
           + ("" if p["plant_hash"] == p["declared_hash"] else " (not the declared plants)") + "."]
    if p["reduced"]:
        out.append(f"Reduced design as declared: seeds {', '.join(str(s) for s in p['seeds'])} of the {E8_SEEDS}.")
    if not p["declared_timing"]:
        out.append("Not the declared timing: a smoke run, not E8's result.")
    for a, d in res["decisions"].items():
        r1, r2, r3 = d["rule1"], d["rule2"], d["rule3"]
        out.append(f"`{a}` rule 1 (no worse than the per-speed tuned fixed frequency: saving's 95 % interval "
                   f"above -{p['no_worse_pct']:g} % in every case): {r1['no_worse']} of {r1['cases']} cases: "
                   + ("holds." if r1["verdict"] else "does not hold."))
        out.append(f"`{a}` rule 2 (>= {p['paper_pct']:g} % below the paper's 2 Hz baseline, interval above zero, "
                   f"in every case where both track): {r2['met']} of {r2['comparable']} comparable of "
                   f"{r2['cases']}: " + ("holds." if r2["verdict"] else "does not hold."))
        out.append(f"`{a}` rule 3 (after a change, >= {p['change_pct']:g} % below the baseline tuned before it "
                   f"within {p['timing']['after_change_s']:g} s, interval above zero, tracking held in every run): "
                   f"{r3['met']} of {r3['changes']} changes: " + ("holds." if r3["verdict"] else "does not hold."))
    return out
