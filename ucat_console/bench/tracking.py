"""``ucat-console bench tracking``: does the robot go where it is sent, in every mode?

Manoeuvres on the simulated U-CAT (the default plate plant, the configuration given,
the shipped ``sim-tuned`` by default: what ``scripts/run.sh`` starts the console with), each
run headless in every fin controller (:data:`MODES`: the baseline, the MPC, the MPC with the
rear pair synchronised, and the MPC's closed-stroke formulation):

* ``depth_step``: cruising at 0.2 m/s at 0.5 m, the depth setpoint steps to 1.5 m at
  :data:`STEP_AT` s: the time to 90 % of the step, the overshoot, and whether the depth stays
  within +-5 cm from 45 s after the step; ``depth_step_2m`` the same to 2.5 m (its time to
  90 % within what the dive-rate limit allows, 0.06 m/s, plus 10 s);
* ``speed_step``: cruising at 0.1 m/s at 1 m, the speed setpoint steps to 0.35 m/s at
  STEP_AT s (the heading through it);
* ``straight``: 0.2 m/s at 1 m, yaw rate setpoint 0: the largest heading error against the
  heading held at the start (after :data:`SETTLE` s);
* ``turn``: the same with a yaw rate setpoint of 0.1 rad/s: the mean rate error and the
  standard deviation of the heading error against the commanded heading (after SETTLE s);
* ``speed_<v>``: from rest at 1 m to v in {0.1, 0.2, 0.3} m/s: the share of DVL samples
  within +-0.025 m/s of v from 30 s on, and the fins' battery energy per metre travelled then
  (``j_per_m``, the simulator's truth: what a change of the controller costs);
* ``gait_change`` (the baseline only, whose beat frequency is its gait): cruising at 0.1 m/s
  at 1 m at 2 Hz, the frequency changes to 0.5 Hz at STEP_AT s (cycles from 0.5 s to 2 s: the
  body loops' schedule follows): the heading from the start;
* ``e5``: the paper's Fig. 8: from rest at 0.5 m to 3 m, 0.2 m/s, 0.1 rad/s, in a current of
  (0.03, 0.02, 0) m/s, 300 s: after the dive (from when the depth first comes within 5 cm),
  the depth MAE, the share of DVL samples within +-0.025 m/s, the mean yaw rate and its sign.

Over every manoeuvre, each fin's executed cycles (``FinCycle``) give the delivered force
against the asked one twice: by the controller's fin model from the executed strokes (what
the robot can know, the telemetry channel), and by the simulator's true force (the plant's
force integrated over the cycle). The figures: median direction error and the share of
cycles more than 90 degrees off, and the executed against the planned cycle duration.

Heading is also judged from each manoeuvre's start (``heading_all_deg``: the largest error
against the heading at the start, every manoeuvre without a turn), and the depth's largest
error from :data:`DEPTH_FROM` s on at a constant depth setpoint (``depth_dev``).

``--seeds N`` runs seeds ``--seed`` ... ``--seed`` + N - 1 and reports each figure's median and
worst case over them; the goals are judged on the worst case. ``--cases`` names the nominal
robot and disturbance cases (:data:`CASES`: the robot 1 % light or heavy, 25 % heavier, one fin's drive at half
speed, a 0.05 m/s current across its path, the still-water and eeUVsim plants, the latter
also with the controller's fin model set to its coefficients, as identification finds them), each on the
manoeuvres of its own goals; ``--manoeuvres`` keeps some manoeuvres only. ``--jobs`` runs that
many processes (default: one per CPU). 20 seeds by default; ``--seeds 1`` prints every figure
of one seed and can write the plots. The goals (:data:`GOALS`); each figure is printed with its goal
and whether it is met. ``--json`` writes everything, ``--plots DIR`` the step responses and
the turns as PNG (matplotlib, the ``experiments`` extra).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: the fin controllers measured: (label, loop mode, MPC formulation)
MODES: tuple[tuple[str, str, str], ...] = (
    ("baseline", "baseline", "paper"),
    ("mpc", "mpc", "paper"),
    ("mpc_sync", "mpc_sync", "paper"),
    ("mpc_closed", "mpc", "closed_stroke"),
)
STEP_AT = 20.0  # s: the depth step's time
SETTLE = 20.0  # s: heading figures from here on
SPEED_FROM = 30.0  # s: speed figures from here on
SPEEDS = (0.1, 0.2, 0.3)
E5_CURRENT = (0.03, 0.02, 0.0)
BAND = 0.025  # m/s
DEPTH_FROM = 30.0  # s: ``depth_dev`` from here on
WEAK_FIN = 2  # the paper fin whose drive is weak in the ``weak_fin`` case
GAIT_FROM, GAIT_TO = 2.0, 0.5  # Hz: the baseline's beat frequency before and after the gait change

#: the goals: figure (manoeuvre/name) -> (comparison, bound)
GOALS: dict[str, tuple[str, float]] = {
    "depth_step/t90": ("<=", 30.0),
    "depth_step/overshoot": ("<=", 0.10),
    "depth_step/settled_error": ("<=", 0.05),
    "straight/heading_error_max_deg": ("<=", 3.0),
    "turn/rate_error": ("<=", 0.01),
    "turn/heading_error_sd_deg": ("<=", 5.0),
    "speed_0.1/within": (">=", 0.90),
    "speed_0.2/within": (">=", 0.90),
    "speed_0.3/within": (">=", 0.90),
    "e5/depth_mae": ("<=", 0.05),
    "e5/within": (">=", 0.90),
    "e5/turned_as_commanded": (">=", 1.0),
    "force/model/median_deg": ("<=", 15.0),
    "force/model/share_over_90": ("<", 0.05),
    "force/true/median_deg": ("<=", 15.0),
    "force/true/share_over_90": ("<", 0.05),
    "depth_step/heading_all_deg": ("<=", 5.0),
    "straight/heading_all_deg": ("<=", 3.0),
    "speed_0.1/heading_all_deg": ("<=", 5.0),
    "speed_0.2/heading_all_deg": ("<=", 5.0),
    "speed_0.3/heading_all_deg": ("<=", 5.0),
    "depth_step_2m/t90": ("<=", 0.9 * 2.0 / 0.06 + 10.0),
    "depth_step_2m/heading_all_deg": ("<=", 5.0),
    "speed_step/heading_all_deg": ("<=", 5.0),
    "gait_change/heading_all_deg": ("<=", 5.0),
}

CROSS_CURRENT = (0.0, 0.05, 0.0)  # m/s NED: across a northward run (a guess: a pool's return flow)


@dataclass(frozen=True)
class Case:
    """A disturbance case: the robot or its water off the nominal, and the goals judged in it
    (their manoeuvres are the ones run)."""

    goals: dict[str, tuple[str, float]]
    buoyancy: float = 1.0  # buoyancy / weight
    mass: float = 1.0  # factor on the vehicle's mass
    weak: float = 1.0  # the weak fin's (:data:`WEAK_FIN`) drive speed factor
    current: tuple[float, float, float] | None = None  # NED m/s, instead of the manoeuvre's own
    plant: str | None = None  # a plant variant (``backend/sim/variants.py``) instead of the default
    model: str | None = None  # the controller's fin model set to these coefficients (as identified)


_HEADING = {"depth_step/heading_all_deg": ("<=", 5.0), "straight/heading_all_deg": ("<=", 3.0)}
#: the disturbance cases by name
CASES: dict[str, Case] = {
    "light_1pc": Case({"straight/depth_dev": ("<=", 0.10), "depth_step/heading_all_deg": ("<=", 5.0)},
                      buoyancy=1.01),
    "heavy_1pc": Case({"straight/depth_dev": ("<=", 0.10), "depth_step/heading_all_deg": ("<=", 5.0)},
                      buoyancy=0.99),
    "mass_x1.25": Case({**_HEADING, "straight/depth_dev": ("<=", 0.10)}, mass=1.25),
    "weak_fin": Case({"depth_step/heading_all_deg": ("<=", 10.0), "straight/heading_all_deg": ("<=", 10.0)},
                     weak=0.5),
    "current": Case({**_HEADING, "straight/depth_dev": ("<=", 0.10)}, current=CROSS_CURRENT),
    "still_water": Case({**_HEADING, "depth_step/t90": ("<=", 30.0), "speed_0.2/within": (">=", 0.90)},
                        plant="still_water"),
    "eeuvsim": Case({**_HEADING, "depth_step/t90": ("<=", 30.0), "speed_0.2/within": (">=", 0.90)},
                    plant="eeuvsim"),
    "eeuvsim_identified": Case({**_HEADING, "depth_step/t90": ("<=", 30.0), "speed_0.2/within": (">=", 0.90)},
                               plant="eeuvsim", model="eeuvsim"),
}


@dataclass(frozen=True)
class Manoeuvre:
    name: str
    duration: float
    velocity: float
    depth: float
    yaw_rate: float = 0.0
    start_depth: float | None = None
    start_velocity: float = 0.0
    current: tuple[float, float, float] = (0.0, 0.0, 0.0)
    step_to: float | None = None  # the depth setpoint from STEP_AT on
    speed_to: float | None = None  # the speed setpoint from STEP_AT on
    gait_to: float | None = None  # the baseline's beat frequency (Hz) from STEP_AT on (the baseline only)


def manoeuvres(quick: bool = False) -> list[Manoeuvre]:
    k = 0.5 if quick else 1.0
    out = [
        Manoeuvre("depth_step", STEP_AT + 90.0 * k, 0.2, 0.5, start_velocity=0.2, step_to=1.5),
        Manoeuvre("depth_step_2m", STEP_AT + 110.0 * k, 0.2, 0.5, start_velocity=0.2, step_to=2.5),
        Manoeuvre("speed_step", STEP_AT + 80.0 * k, 0.1, 1.0, start_velocity=0.1, speed_to=0.35),
        Manoeuvre("straight", 120.0 * k, 0.2, 1.0, start_velocity=0.2),
        Manoeuvre("turn", 120.0 * k, 0.2, 1.0, yaw_rate=0.1, start_velocity=0.2),
    ]
    out += [Manoeuvre(f"speed_{v:g}", 120.0 * k, v, 1.0) for v in SPEEDS]
    out.append(Manoeuvre("gait_change", STEP_AT + 80.0 * k, 0.1, 1.0, start_velocity=0.1, gait_to=GAIT_TO))
    out.append(Manoeuvre("e5", 300.0 * k, 0.2, 3.0, yaw_rate=0.1, start_depth=0.5, current=E5_CURRENT))
    return out


@dataclass
class _Log:
    """What one run records: the truth at the power ticks, DVL speeds, executed cycles."""

    t: list[float] = field(default_factory=list)
    depth: list[float] = field(default_factory=list)
    yaw: list[float] = field(default_factory=list)
    yaw_rate: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)  # J: the fins' battery energy since the start
    dvl_t: list[float] = field(default_factory=list)
    dvl_v: list[float] = field(default_factory=list)
    model_err: list[float] = field(default_factory=list)  # rad
    true_err: list[float] = field(default_factory=list)
    duration_ratio: list[float] = field(default_factory=list)


def run_manoeuvre(app: Any, mode: str, formulation: str, m: Manoeuvre, seed: int = 0,
                  case: str | None = None) -> dict[str, Any]:
    """One manoeuvre in one mode (in a disturbance case of :data:`CASES`): its figures
    (module docstring) and its trace."""
    from ucat_console.backend.loop.closed_loop import ClosedLoop
    from ucat_console.backend.loop.commands import SetBlock, SetSetpoints
    from ucat_console.backend.sim_robot_io import SimRobotIO
    from ucat_console.robot.fins import PAPER_TO_ROBOT
    from ucat_console.control.allocation import BodySetpoints
    from ucat_console.control.fin_cycle import direction_error
    from ucat_console.backend.fin_rig import START_FIN_ANGLE
    from ucat_console.backend.sim.variants import DEFAULT_PLANT, plant_config
    from ucat_console.telemetry import channels as ch
    from ucat_console.telemetry.stream import TelemetryStream

    c = CASES[case] if case is not None else Case({})
    mpc = app.loop.mpc.replace(formulation=formulation)
    if c.model is not None:
        from ucat_console.backend.sim.params import FinHydroConfig

        k = FinHydroConfig(coefficients=c.model).resolved()
        mpc = mpc.replace(rho=k.rho, c_d=k.c_d, c_l=k.c_l, fin_length=k.fin_length)
    cfg = app.loop.replace(mode=mode, planner_seed=seed, mpc=mpc)
    if m.gait_to is not None:
        cfg = cfg.replace(baseline=cfg.baseline.replace(frequency=GAIT_FROM))
    z0 = m.depth if m.start_depth is None else m.start_depth
    plant = plant_config(c.plant or DEFAULT_PLANT, seed, m.current if c.current is None else c.current)
    if (c.buoyancy, c.mass) != (1.0, 1.0):
        plant = plant.replace(vehicle=plant.vehicle.replace(buoyancy_ratio=c.buoyancy,
                                                            mass=plant.vehicle.mass * c.mass))
    io = SimRobotIO(plant, depth=z0, velocity=m.start_velocity)
    if c.weak != 1.0:
        io.weaken_fin(PAPER_TO_ROBOT[WEAK_FIN], c.weak)
    io.plant.reset(position_ned=(0.0, 0.0, z0), body_velocity=(m.start_velocity, 0.0, 0.0, 0.0, 0.0, 0.0),
                   fin_angles=(START_FIN_ANGLE,) * 4, seed=seed)
    stream = TelemetryStream(validate=False)
    loop = ClosedLoop(cfg, io, stream, setpoints=BodySetpoints(m.velocity, m.depth, m.yaw_rate))
    log = _Log()
    starts: dict[int, dict[float, tuple[float, float]]] = {pf: {} for pf in range(4)}

    def on(channel: str, msg: Any) -> None:
        if channel == ch.POWER:
            tr = io.truth()
            log.t.append(msg.t)
            log.depth.append(tr.depth)
            log.yaw.append(tr.euler[2])
            log.yaw_rate.append(tr.velocity[5])
            log.x.append(tr.position[0])
            log.y.append(tr.position[1])
            log.energy.append(sum(io.plant.fin_battery_energy()))
        elif channel == ch.DVL:
            if msg.valid:
                log.dvl_t.append(msg.t)
                log.dvl_v.append(msg.vx)
        elif channel.endswith("/strouhal"):
            starts[msg.fin][msg.t] = io.plant.fin_impulse()[msg.fin]
        elif channel.endswith("/cycle"):
            imp1 = io.plant.fin_impulse()[msg.fin]
            imp0 = starts[msg.fin].pop(msg.t - msg.duration, None)
            for k in [k for k in starts[msg.fin] if k < msg.t]:
                del starts[msg.fin][k]
            starts[msg.fin][msg.t] = imp1
            log.model_err.append(msg.direction_error)
            if imp0 is not None and msg.duration > 0.0:
                true = ((imp1[0] - imp0[0]) / msg.duration, (imp1[1] - imp0[1]) / msg.duration)
                log.true_err.append(direction_error(msg.target, true))
            if msg.planned_duration > 0.0:
                log.duration_ratio.append(msg.duration / msg.planned_duration)

    chans = [ch.POWER, ch.DVL] + [ch.fin_strouhal(i) for i in range(4)] + [ch.fin_cycle(i) for i in range(4)]
    stream.subscribe(on, chans)
    if m.step_to is not None or m.speed_to is not None or m.gait_to is not None:
        loop.run_until(STEP_AT)
        loop.submit(SetSetpoints(depth=m.step_to, velocity=m.speed_to))
        if m.gait_to is not None:
            loop.submit(SetBlock("baseline", cfg.baseline.replace(frequency=m.gait_to)))
    loop.run_until(m.duration)
    loop.close()
    return {"figures": _figures(m, log), "log": log}


def _figures(m: Manoeuvre, log: _Log) -> dict[str, float]:
    t = np.asarray(log.t)
    z = np.asarray(log.depth)
    yaw = np.unwrap(np.asarray(log.yaw))
    r = np.asarray(log.yaw_rate)
    dt = np.asarray(log.dvl_t)
    dv = np.asarray(log.dvl_v)
    out: dict[str, float] = {}
    if m.step_to is not None:
        z0, z1 = m.depth, float(m.step_to)
        after = t >= STEP_AT
        reached = np.nonzero(after & (z >= z0 + 0.9 * (z1 - z0)))[0]
        out["t90"] = float(t[reached[0]] - STEP_AT) if reached.size else math.inf
        out["overshoot"] = float(max(0.0, z[after].max() - z1) / (z1 - z0))
        late = t >= STEP_AT + 45.0
        out["settled_error"] = float(np.abs(z[late] - z1).max()) if late.any() else math.inf
        out["final_depth"] = float(z[-1])
    if m.name in ("straight", "turn", "depth_step"):
        w = t >= SETTLE
        ref = yaw[0] + m.yaw_rate * (t - t[0])
        err = np.degrees(yaw - ref)
        if m.name == "turn":
            out["rate_error"] = float(abs(r[w].mean() - m.yaw_rate))
            out["heading_error_sd_deg"] = float(err[w].std())
        else:
            out["heading_error_max_deg"] = float(np.abs(err[w]).max())
    if m.yaw_rate == 0.0:
        out["heading_all_deg"] = float(np.abs(np.degrees(yaw - yaw[0])).max())
    if m.step_to is None and m.start_depth is None:
        late = t >= DEPTH_FROM
        out["depth_dev"] = float(np.abs(z[late] - m.depth).max()) if late.any() else math.inf
    if m.name.startswith("speed_"):
        w = dt >= SPEED_FROM
        out["within"] = float(np.mean(np.abs(dv[w] - m.velocity) <= BAND)) if w.any() else 0.0
        out["mean_speed"] = float(dv[w].mean()) if w.any() else math.nan
        late = t >= SPEED_FROM
        if late.sum() > 1:
            path = float(np.hypot(np.diff(np.asarray(log.x)[late]), np.diff(np.asarray(log.y)[late])).sum())
            energy = np.asarray(log.energy)[late]
            spent = float(energy[-1] - energy[0])
            out["j_per_m"] = spent / path if path > 0.0 else math.inf
    if m.name == "e5":
        near = np.nonzero(np.abs(z - m.depth) <= 0.05)[0]
        t_dive = float(t[near[0]]) if near.size else math.inf
        out["dive_s"] = t_dive
        w = t >= t_dive
        out["depth_mae"] = float(np.abs(z[w] - m.depth).mean()) if w.any() else math.inf
        wv = dt >= t_dive
        out["within"] = float(np.mean(np.abs(dv[wv] - m.velocity) <= BAND)) if wv.any() else 0.0
        out["yaw_rate_mean"] = float(r[w].mean()) if w.any() else math.nan
        out["turned_as_commanded"] = float(w.any() and np.sign(r[w].mean()) == np.sign(m.yaw_rate)
                                           and abs(r[w].mean() - m.yaw_rate) <= 0.02)
    return out


def _force_figures(errs: list[float]) -> dict[str, float]:
    a = np.degrees(np.asarray([e for e in errs if e == e]))
    if not a.size:
        return {"median_deg": math.nan, "share_over_90": math.nan, "cycles": 0}
    return {"median_deg": float(np.median(a)), "share_over_90": float(np.mean(a > 90.0)), "cycles": int(a.size)}


def run_mode(app: Any, label: str, mode: str, formulation: str, quick: bool = False,
             seed: int = 0, case: str | None = None,
             only: frozenset[str] | None = None) -> tuple[dict[str, Any], dict[str, _Log]]:
    """Every manoeuvre in one mode (a case's own manoeuvres in a disturbance case; of those,
    the ones named in ``only``): (figures by manoeuvre and the fin force's, logs)."""
    figures: dict[str, Any] = {}
    logs: dict[str, _Log] = {}
    model_err: list[float] = []
    true_err: list[float] = []
    ratio: list[float] = []
    wanted = None if case is None else {k.split("/")[0] for k in CASES[case].goals}
    for m in manoeuvres(quick):
        if (wanted is not None and m.name not in wanted) or (only is not None and m.name not in only) \
                or (m.gait_to is not None and mode != "baseline"):
            continue
        r = run_manoeuvre(app, mode, formulation, m, seed, case)
        figures[m.name] = r["figures"]
        logs[m.name] = r["log"]
        model_err += r["log"].model_err
        true_err += r["log"].true_err
        ratio += r["log"].duration_ratio
    figures["force"] = {"model": _force_figures(model_err), "true": _force_figures(true_err),
                        "duration_ratio_median": float(np.median(ratio)) if ratio else math.nan}
    return figures, logs


def _lookup(figures: dict[str, Any], key: str) -> float:
    v: Any = figures
    for part in key.split("/"):
        v = v.get(part, math.nan) if isinstance(v, dict) else math.nan
    return float(v)


def verdicts(figures: dict[str, Any], goals: dict[str, tuple[str, float]] | None = None) -> dict[str, dict[str, Any]]:
    """Each goal (of :data:`GOALS` by default): the figure, the bound and whether it is met."""
    out = {}
    for key, (op, bound) in (GOALS if goals is None else goals).items():
        if key.split("/")[0] not in figures:  # a manoeuvre this mode does not run
            continue
        v = _lookup(figures, key)
        met = (v <= bound) if op == "<=" else (v >= bound) if op == ">=" else (v < bound)
        out[key] = {"value": v, "goal": f"{op} {bound:g}", "met": bool(met)}
    return out


def over_seeds(per_seed: dict[int, dict[str, Any]], goals: dict[str, tuple[str, float]]) -> dict[str, dict[str, Any]]:
    """Each goal over the seeds: the median and the worst case (the seed it came from), the
    goal judged on the worst case."""
    out = {}
    for key, (op, bound) in goals.items():
        values = {seed: _lookup(f, key) for seed, f in per_seed.items()}
        bad = {s: (math.inf if v != v else -v if op == ">=" else v) for s, v in values.items()}
        worst_seed = max(bad, key=lambda s: bad[s])
        worst = values[worst_seed]
        met = (worst <= bound) if op == "<=" else (worst >= bound) if op == ">=" else (worst < bound)
        out[key] = {"median": float(np.median(list(values.values()))), "worst": worst, "worst_seed": worst_seed,
                    "goal": f"{op} {bound:g}", "met": bool(met), "seeds_met": sum(
                        bool((v <= bound) if op == "<=" else (v >= bound) if op == ">=" else (v < bound))
                        for v in values.values())}
    return out


def plot(logs: dict[str, dict[str, _Log]], out: Path) -> list[Path]:
    """The depth steps, the turns' heading errors and the E5 paths, every mode on one
    figure each (PNG)."""
    from ucat_console.bench.extras import require_extra

    require_extra("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    files = []
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, ls in logs.items():
        lg = ls["depth_step"]
        ax.plot(np.asarray(lg.t) - STEP_AT, lg.depth, label=label)
    ax.axhline(1.5, color="k", lw=0.6)
    ax.axhspan(1.45, 1.55, color="g", alpha=0.1)
    ax.set(xlabel="time from the step (s)", ylabel="depth (m)", title="Depth step 0.5 -> 1.5 m at 0.2 m/s")
    ax.invert_yaxis()
    ax.legend()
    files.append(out / "depth_step.png")
    fig.savefig(files[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, ls in logs.items():
        lg = ls["turn"]
        t = np.asarray(lg.t)
        yaw = np.unwrap(np.asarray(lg.yaw))
        ax.plot(t, np.degrees(yaw - (yaw[0] + 0.1 * (t - t[0]))), label=label)
    ax.set(xlabel="time (s)", ylabel="heading error (deg)", title="Turn at 0.1 rad/s, 0.2 m/s")
    ax.legend()
    files.append(out / "turn.png")
    fig.savefig(files[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 6))
    for label, ls in logs.items():
        lg = ls["e5"]
        ax.plot(lg.y, lg.x, label=label)
    ax.set(xlabel="east (m)", ylabel="north (m)", title="E5: 0.2 m/s, 0.1 rad/s, 3 m, with a current")
    ax.set_aspect("equal")
    ax.legend()
    files.append(out / "e5_path.png")
    fig.savefig(files[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)
    return files


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("tracking", help="depth, heading and speed tracking in every mode (the simulated robot)")
    p.add_argument("--config", default="sim-tuned", metavar="NAME|FILE",
                   help="configuration: a shipped one's name or a file (default: sim-tuned)")
    p.add_argument("--modes", nargs="+", choices=[m[0] for m in MODES], default=[m[0] for m in MODES])
    p.add_argument("--quick", action="store_true", help="half-length manoeuvres (a smoke run)")
    p.add_argument("--seed", type=int, default=0, help="plant and planner seed (the first of --seeds)")
    p.add_argument("--seeds", type=int, default=20,
                   help="how many seeds, from --seed on (median and worst case; default 20)")
    p.add_argument("--cases", nargs="+", choices=["nominal", *CASES], default=["nominal"],
                   help="the nominal robot and the disturbance cases to run (default: the nominal robot)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="processes running the runs (default: one per CPU)")
    p.add_argument("--manoeuvres", nargs="+", choices=[m.name for m in manoeuvres()], default=None,
                   help="only these manoeuvres (default: all)")
    p.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write the plots (PNG) here")
    p.set_defaults(func=run_bench)


def _run_one(task: tuple[Any, str, str, str, bool, int, str | None, frozenset[str] | None]
             ) -> tuple[str, str, int, dict[str, Any]]:
    app, label, mode, formulation, quick, seed, case, only = task
    figures, _ = run_mode(app, label, mode, formulation, quick, seed, case, only)
    return case or "nominal", label, seed, figures


def run_bench(args: argparse.Namespace) -> int:
    from ucat_console.compiled import prepare_all
    from ucat_console.config import load_config

    if args.seeds < 1 or args.jobs < 1:
        raise ValueError(f"--seeds and --jobs: at least 1, got {args.seeds} and {args.jobs}")
    app = load_config(args.config)
    prepare_all(args.config)
    seeds = list(range(args.seed, args.seed + args.seeds))
    modes = [m for m in MODES if m[0] in args.modes]
    if args.seeds == 1 and args.cases == ["nominal"] and args.manoeuvres is None:
        return _run_single(app, args, modes)
    cases: list[str | None] = [None if c == "nominal" else c for c in dict.fromkeys(args.cases)]
    only = None if args.manoeuvres is None else frozenset(args.manoeuvres)
    tasks = [(app, label, mode, formulation, args.quick, seed, case, only)
             for case in cases for label, mode, formulation in modes for seed in seeds]
    t0 = time.perf_counter()
    if args.jobs > 1:
        import multiprocessing

        # every mode's compiled code loaded before the processes fork: each has it at once
        for _, mode, formulation in modes:
            run_manoeuvre(app, mode, formulation, Manoeuvre("warm", 2.0, 0.2, 1.0, start_velocity=0.2), 0,
                          "weak_fin")

        with multiprocessing.get_context("fork").Pool(args.jobs) as pool:
            done = pool.map(_run_one, tasks, chunksize=1)
    else:
        done = [_run_one(t) for t in tasks]
    per: dict[str, dict[str, dict[int, dict[str, Any]]]] = {}
    for case, label, seed, figures in done:
        per.setdefault(case, {}).setdefault(label, {})[seed] = figures
    results: dict[str, Any] = {"config": str(args.config), "seeds": seeds, "quick": args.quick, "cases": {}}
    for case in cases:
        name = case or "nominal"
        goals = GOALS if case is None else CASES[case].goals
        results["cases"][name] = {}
        for label, _, _ in modes:
            ran = set(next(iter(per[name][label].values())))
            v = over_seeds(per[name][label], {k: g for k, g in goals.items() if k.split("/")[0] in ran})
            results["cases"][name][label] = {"goals": v, "figures": per[name][label]}
            met = sum(x["met"] for x in v.values())
            print(f"{name} / {label}: {met}/{len(v)} goals met on the worst of {len(seeds)} seeds")
            for key, x in v.items():
                print(f"    {key:34s} median {x['median']:8.3f} worst {x['worst']:8.3f} (seed {x['worst_seed']})"
                      f"  goal {x['goal']:8s} {'met' if x['met'] else 'NOT MET'} ({x['seeds_met']}/{len(seeds)})")
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0


def _run_single(app: Any, args: argparse.Namespace, modes: list[tuple[str, str, str]]) -> int:
    """One seed, the nominal robot: every figure of every mode and the plots."""
    results: dict[str, Any] = {"config": str(args.config), "seed": args.seed, "quick": args.quick, "modes": {}}
    logs: dict[str, dict[str, _Log]] = {}
    for label, mode, formulation in modes:
        t0 = time.perf_counter()
        figures, lg = run_mode(app, label, mode, formulation, args.quick, args.seed)
        logs[label] = lg
        v = verdicts(figures)
        results["modes"][label] = {"figures": figures, "goals": v}
        met = sum(x["met"] for x in v.values())
        print(f"{label}: {met}/{len(v)} goals met ({time.perf_counter() - t0:.1f} s)")
        for key, x in v.items():
            print(f"    {key:34s} {x['value']:9.3f}  goal {x['goal']:8s} {'met' if x['met'] else 'NOT MET'}")
        f = figures["force"]
        print(f"    executed / planned cycle duration (median) {f['duration_ratio_median']:.3f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2, default=float))
        print(f"wrote {args.json}")
    if args.plots:
        for f in plot(logs, args.plots):
            print(f"wrote {f}")
    return 0
