"""``ucat-console bench plant``: the simulated fin's physics checked against itself, its
calibration, a published reference and the paper.

Four parts (docs/fin-plant.md, "Checks"):

* ``energy``: for every shipped plant variant, one fin beats symmetric stroke pairs over a
  grid of centres, amplitudes, rates and hull speeds (``backend.fin_rig``); the largest
  ratio of the power it delivers to the hull to its shaft power, ``T V / P`` (goal: below 1
  everywhere);
* ``bollard``: the plate's mean still-water force of symmetric stroke pairs against the
  identified model it is calibrated to, ``q w^2 sqrt(C_L^2 + C_D^2) cos(d/2)``, through the
  plant's own servo profile and at a steady rate;
* ``efficiency``: each E7 plant's efficiency ``eta = T V / P`` against the paper's St
  (``w L_f / (2 V)``), beside Lighthill's elongated-body theory for a low-aspect-ratio plate
  pitching about its leading edge (Lighthill, J. Fluid Mech. 44:265, 1970) with the same
  profile drag, and the band where oscillating foils are most efficient in experiments
  (St 0.2-0.4 on the trailing edge's excursion: Triantafyllou et al., Phys. Fluids A 3:2835,
  1991; Floryan, Van Buren and Smits, PNAS 115:8116, 2018), converted to the paper's St;
* ``cruise``: the closed loop at 0.1-0.4 m/s (baseline and MPC, the shipped sim-tuned, three
  seeds): power and energy per metre against the paper's Table V.

Elongated-body theory, for a plate of span ``s`` (along the shaft) and chord ``c`` from the
shaft pitching ``theta0 sin(2 pi f t)`` about its leading edge at speed U: the added mass per
length ``m = pi rho s^2 / 4``, the trailing edge's lateral velocity ``c theta'`` and slope
``theta``, so the mean thrust ``T = m theta0^2 (c^2 omega^2 - U^2) / 4`` and the mean power
``P = m U c^2 theta0^2 omega^2 / 2`` (inviscid: ``eta = (1 - (U / c omega)^2) / 2``); with
the plate's profile drag ``D_0 = rho C_D0 A_f U^2 / 2``, ``eta = (T - D_0) U / P``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ucat_console.robot.fin_plate import plate_geometry

#: the paper's Table V: (controller, v) -> mean power (W)
PAPER_POWER = {("baseline", 0.1): 1.900, ("baseline", 0.2): 3.251, ("baseline", 0.3): 3.724,
               ("mpc", 0.1): 1.612, ("mpc", 0.2): 2.212, ("mpc", 0.3): 3.049, ("mpc", 0.4): 3.341}
#: the trailing edge's St where oscillating foils are most efficient in experiments
EFFICIENT_BAND = (0.2, 0.4)
CRUISE_SPEEDS = (0.1, 0.2, 0.3, 0.4)
CRUISE_SEEDS = (0, 1, 2)


def register_bench(kinds: argparse._SubParsersAction) -> None:
    p = kinds.add_parser("plant", help="the simulated fin's physics: energy, bollard thrust, efficiency, cruise power")
    p.add_argument("--parts", nargs="+", choices=("energy", "bollard", "efficiency", "cruise"),
                   default=["energy", "bollard", "efficiency", "cruise"])
    p.add_argument("--quick", action="store_true", help="a coarse grid, one seed (a smoke run)")
    p.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    p.add_argument("--plots", type=Path, default=None, help="write the efficiency figure (PNG) here")
    p.set_defaults(func=run_bench)


# ------------------------------------------------------------------------------ energy
def energy_check(quick: bool = False) -> dict[str, Any]:
    """The largest T V / P of each shipped plant variant over the grid (module docstring)."""
    from ucat_console.backend.fin_rig import FinRig
    from ucat_console.backend.sim.variants import PLANT_VARIANTS, e7_plants, family_name, plant_config

    names = [*PLANT_VARIANTS, *e7_plants(), *(family_name(g, m) for g in (1.0, 2.3, 4.6, 9.2)
                                              for m in ("plate", "still_water"))]
    centres = (-2.0, -1.2, -0.4, 0.4) if not quick else (-1.2,)
    amplitudes = (0.1, 0.3, 0.6) if not quick else (0.3,)
    rates = (1.0, 2.5, 5.0, 9.0) if not quick else (2.5,)
    speeds = (0.0, 0.1, 0.2, 0.3, 0.4, 0.6) if not quick else (0.3,)
    out = {}
    for name in dict.fromkeys(names):
        rig = FinRig(plant_config(name, 0))
        worst, at = -math.inf, None
        for c in centres:
            for a in amplitudes:
                for w in rates:
                    for v in speeds:
                        m = rig.cycle(v, c, a, min(w, rig.mean_rate_limit(2 * a)), cycles=2, measured=1)
                        ratio = m.thrust(rig.cos_mount) * v / m.power if m.power > 0 else -math.inf
                        if ratio > worst:
                            worst, at = ratio, {"centre": c, "amplitude": a, "rate": w, "speed": v}
        out[name] = {"max_useful_over_shaft": worst, "at": at}
    return out


# ----------------------------------------------------------------------------- bollard
def bollard_check() -> list[dict[str, Any]]:
    """Still-water mean force of symmetric pairs against the identified model's."""
    from ucat_console.backend.sim.params import PlantConfig, ServoConfig
    from ucat_console.backend.fin_rig import START_FIN_ANGLE, FinRig

    plant = PlantConfig()
    c = plant.hydro.resolved()
    q = 0.5 * c.rho * c.area * c.r_c ** 2
    rows = []
    for label, cfg in (("servo", plant), ("steady", plant.replace(servo=ServoConfig(acceleration=5000.0)))):
        rig = FinRig(cfg)
        for d in (0.2, 0.6, 1.2):
            for w in (2.0, 4.0, 6.0):
                if w > rig.mean_rate_limit(d):
                    continue
                m = rig.cycle(0.0, START_FIN_ANGLE, d / 2.0, w)
                model = q * w * w * math.hypot(c.c_l, c.c_d) * math.cos(d / 2.0)
                rows.append({"profile": label, "stroke": d, "rate": w, "plate_N": math.hypot(m.fx, m.fy),
                             "model_N": model, "ratio": math.hypot(m.fx, m.fy) / model, "shaft_W": m.power})
    return rows


# -------------------------------------------------------------------------- efficiency
def ebt_efficiency(st: float, theta0: float, cd0: float, plant: Any) -> float:
    """Elongated-body theory's efficiency (module docstring) at the paper's St (``w L_f / (2 V)``,
    w the mean |rate| of a sinusoid of amplitude ``theta0``), for the plate of ``plant``."""
    c = plant.hydro.resolved()
    chord, span = plate_geometry(c.r_c, c.area)
    u = 1.0  # the efficiency depends on St alone
    mean_rate = st * 2.0 * u / c.fin_length
    omega = mean_rate * math.pi / (2.0 * theta0)  # a sinusoid's mean |rate| is 2 omega theta0 / pi
    m = math.pi * c.rho * span ** 2 / 4.0
    thrust = m * theta0 ** 2 * ((chord * omega) ** 2 - u * u) / 4.0
    power = m * u * chord ** 2 * theta0 ** 2 * omega ** 2 / 2.0
    drag = 0.5 * c.rho * cd0 * c.area * u * u
    return (thrust - drag) * u / power


def trailing_edge_st(paper_st: float, plant: Any) -> float:
    """The Strouhal number on the trailing edge's excursion (the literature's) of a beat whose
    paper St (on the length L_f) is ``paper_st``: the plate reaches R = sqrt(3) r_c."""
    c = plant.hydro.resolved()
    return paper_st * plate_geometry(c.r_c, c.area)[0] / c.fin_length


def efficiency_check(speed: float = 0.2) -> dict[str, Any]:
    from ucat_console.backend.fin_rig import CORRIDOR, curve
    from ucat_console.backend.sim.variants import DEFAULT_PLANT, e7_plants, plant_config

    plants = list(dict.fromkeys([*e7_plants(), DEFAULT_PLANT]))
    out: dict[str, Any] = {"speed": speed, "corridor": list(CORRIDOR), "curves": {}, "ebt": {}}
    base = plant_config(DEFAULT_PLANT, 0)
    scale = trailing_edge_st(1.0, base)
    out["trailing_edge_per_paper_st"] = scale
    out["efficient_band_paper_st"] = [EFFICIENT_BAND[0] / scale, EFFICIENT_BAND[1] / scale]
    for p in plants:
        cv = curve(p, speed)
        out["curves"][p] = {k: cv[k] for k in ("st", "eta", "peak_st", "peak_eta")}
        h = plant_config(p, 0).hydro
        if h.model == "plate":
            ebt = [ebt_efficiency(s, 0.3, h.c_d0, base) for s in cv["st"]]
            out["ebt"][p] = {"st": cv["st"], "eta": ebt, "theta0": 0.3}
    return out


def efficiency_figure(res: dict[str, Any], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    lo, hi = res["efficient_band_paper_st"]
    ax.axvspan(lo, hi, color="0.9", label="most efficient in experiments (TE St 0.2-0.4)")
    c0, c1 = res["corridor"]
    ax.axvspan(c0, c1, color="tab:green", alpha=0.12, label="the paper's corridor")
    colours = iter(("tab:blue", "tab:orange", "tab:red", "tab:purple", "tab:brown"))
    for p, cv in res["curves"].items():
        if p not in res["ebt"]:
            continue
        col = next(colours)
        st = np.asarray(cv["st"])
        eta = np.asarray(cv["eta"], dtype=float)
        ax.plot(st, eta, "-o", ms=3, color=col, label=f"{p}: plate (peak St {cv['peak_st']:.2f})")
        e = np.asarray(res["ebt"][p]["eta"])
        ax.plot(st, np.where(e > 0, e, np.nan), "--", color=col, lw=1,
                label=f"{p}: elongated-body theory, same C_D0")
    ax.set_xlabel("St (the paper's: w L_f / 2V)")
    ax.set_ylabel("eta = T V / P")
    ax.set_ylim(0.0, 0.55)
    ax.set_title(f"One fin at {res['speed']:g} m/s: the plate against Lighthill's theory", fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path.mkdir(parents=True, exist_ok=True)
    out = path / "fin-efficiency.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


# ------------------------------------------------------------------------------ cruise
def cruise_check(quick: bool = False) -> list[dict[str, Any]]:
    """Baseline and MPC at 0.1-0.4 m/s on the default plant with the shipped sim-tuned."""
    from ucat_console.config import load_config
    from ucat_console.backend.scenario import Scenario, run_scenario

    app = load_config("sim-tuned")
    speeds = (0.2,) if quick else CRUISE_SPEEDS
    seeds = (0,) if quick else CRUISE_SEEDS
    rows = []
    for ctrl in ("baseline", "mpc"):
        for v in speeds:
            runs = [run_scenario(Scenario(mode=ctrl, v_ref=v, seed=s, mpc=app.loop.mpc, body=app.loop.body,
                                          settle_s=10.0 if quick else 30.0, window_s=10.0 if quick else 60.0))
                    for s in seeds]
            row = {"controller": ctrl, "v_ref": v, "runs": len(runs)}
            for k in ("power_true", "power_est", "power_electrical", "energy_per_metre_true",
                      "energy_per_metre_electrical", "velocity_mean", "velocity_mae"):
                vals = [r[k] for r in runs if k in r and r[k] == r[k]]
                row[k] = float(np.mean(vals)) if vals else math.nan
            paper = PAPER_POWER.get((ctrl, v))
            row["paper_W"] = paper if paper is not None else math.nan
            row["electrical_over_paper"] = row["power_electrical"] / paper if paper else math.nan
            row["estimate_over_paper"] = row["power_est"] / paper if paper else math.nan
            rows.append(row)
    return rows


def run_bench(args: argparse.Namespace) -> int:
    from ucat_console.bench.machine import machine_info

    res: dict[str, Any] = {"machine": machine_info(None), "quick": args.quick}
    t0 = time.perf_counter()
    if "energy" in args.parts:
        res["energy"] = energy_check(args.quick)
        print("energy: the largest T V / P over the grid, per plant")
        for name, e in res["energy"].items():
            print(f"    {name:22s} {e['max_useful_over_shaft']:6.3f}  at {e['at']}")
    if "bollard" in args.parts:
        res["bollard"] = bollard_check()
        print("bollard: the plate's mean still-water force over the identified model's")
        for r in res["bollard"]:
            print(f"    {r['profile']:6s} d {r['stroke']:.1f} w {r['rate']:.0f}: {r['plate_N']:.3f} N / "
                  f"{r['model_N']:.3f} N = {r['ratio']:.3f}   shaft {r['shaft_W']:.3f} W")
    if "efficiency" in args.parts:
        res["efficiency"] = eff = efficiency_check()
        print(f"efficiency at {eff['speed']:g} m/s (the trailing edge's St is "
              f"{eff['trailing_edge_per_paper_st']:.2f} x the paper's):")
        for p, cv in eff["curves"].items():
            ebt = eff["ebt"].get(p)
            print(f"    {p:14s} peak St {cv['peak_st']:.2f} eta {cv['peak_eta']:.3f}"
                  + (f"; elongated-body theory at that St {np.interp(cv['peak_st'], ebt['st'], ebt['eta']):.3f}"
                     if ebt else ""))
        if args.plots:
            print(f"wrote {efficiency_figure(eff, args.plots)}")
    if "cruise" in args.parts:
        res["cruise"] = cruise_check(args.quick)
        print("cruise (sim-tuned, mean of seeds): W, against the paper's Table V")
        for r in res["cruise"]:
            print(f"    {r['controller']:8s} {r['v_ref']:.1f} m/s: shaft {r['power_true']:.2f} W, estimate "
                  f"{r['power_est']:.2f} W, electrical {r['power_electrical']:.2f} W; paper {r['paper_W']:.2f} W "
                  f"(electrical / paper {r['electrical_over_paper']:.2f}); {r['energy_per_metre_electrical']:.1f} J/m "
                  f"electrical, {r['energy_per_metre_true']:.1f} J/m shaft; speed {r['velocity_mean']:.3f}")
    res["seconds"] = time.perf_counter() - t0
    if args.json:
        args.json.write_text(json.dumps(res, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0
