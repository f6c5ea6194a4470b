"""E7: does St-awareness save energy on a plant whose efficiency depends on the flow?

Declared before it was run (docs/experiments/e7-declaration.md, which prints the plants'
hash, :func:`~ucat_console.experiments.efficiency_curves.plant_hash`). Plants: the plate
over the profile drag C_D0 (:data:`~ucat_console.backend.sim.variants.E7_CD0`) and
the null plant (``still_water``: the plate as if in still water, the thrust's work paid
through the shaft, so that how a force is made costs the same at any St).
Every run starts from rest, with the shipped sim-tuned's MPC weights and body layer.

Controllers (:data:`E7_CONTROLLERS`):

* ``baseline_2hz``: the paper's fixed-frequency baseline at 2 Hz (fin-model inverse with
  the identified coefficients);
* ``baseline_best``: the same at the frequency of :data:`TUNING_FREQUENCIES` with the
  least battery energy per metre among those that track, chosen per plant and speed on a
  held-out seed (:data:`HELD_OUT_SEED` + base seed) before the measured runs;
* ``mpc_paper_id``: the paper's MPC (its formulation) with the identified model;
* ``mpc_closed_id``: the closed-stroke MPC with the identified model;
* ``mpc_closed_nost``: the same without its St term (``lam_st = 0``), the ablation;
* ``oracle``: plans with the plant's true force and battery power (``experiments.oracle``).

Primary metric (:data:`PRIMARY`): the battery's energy per metre (the drives' electrical
input by the plant's drive model, ``robot.motor``) at matched tracking (DVL speed MAE <=
:data:`MATCH_MAE` and true mean speed within :data:`MATCH_MEAN` of the reference); the shaft's
energy per metre (:data:`SECONDARY`) is reported beside it, with the rules applied to it too.
A comparison of controller A against B in a plant-speed case uses the seeds where both
match; its saving is ``100 (1 - mean E_A / mean E_B)`` with a paired bootstrap 95 %
interval over those seeds (:func:`paired_saving`); fewer than :data:`MIN_PAIRS` pairs: not
comparable. The decision rules (:func:`decisions`) are the declaration's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ucat_console.control.params import BaselineConfig
from ucat_console.experiments.closed_loop_runs import _label, e4_timing, e4r_settings, identify_plant
from ucat_console.experiments.distributed import run_all
from ucat_console.backend.fin_rig import CORRIDOR
from ucat_console.backend.scenario import Scenario
from ucat_console.backend.sim.variants import NULL_PLANT, e7_plants, plant_assumptions
from ucat_console.experiments.efficiency_curves import E7_SPEEDS, all_curves, plant_hash
from ucat_console.experiments.scenario import run_scenario

#: the energy per metre the decision rules read, and the one reported beside it
PRIMARY = "energy_per_metre_electrical"
SECONDARY = "energy_per_metre_true"
E7_CONTROLLERS = ("baseline_2hz", "baseline_best", "mpc_paper_id", "mpc_closed_id", "mpc_closed_nost", "oracle")
E7_SEEDS = 10
HELD_OUT_SEED = 1000
TUNING_FREQUENCIES = (0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0)
MATCH_MAE = 0.03
MATCH_MEAN = 0.01
MIN_PAIRS = 2
BOOTSTRAP = 2000
#: decision rules
ST_PAYS_PCT = 5.0
NULL_BAND_PCT = 3.0


def e7_design(quick: bool, seed: int, n_seeds: int | None = None) -> dict[str, Any]:
    """Plants, speeds, seeds and tuning frequencies of a run."""
    if n_seeds is not None and not 1 <= n_seeds <= E7_SEEDS:
        raise ValueError(f"--seeds: {n_seeds} is not in 1..{E7_SEEDS}")
    if quick:
        return {"plants": ["plate_cd0.05", NULL_PLANT], "speeds": [0.2], "seeds": [seed, seed + 1],
                "frequencies": [1.0, 2.0], "held_out": HELD_OUT_SEED + seed}
    n = E7_SEEDS if n_seeds is None else n_seeds
    return {"plants": e7_plants(), "speeds": list(E7_SPEEDS), "seeds": [seed + k for k in range(n)],
            "frequencies": list(TUNING_FREQUENCIES), "held_out": HELD_OUT_SEED + seed}


def _configs(ident: dict[str, Any]) -> dict[str, tuple[str, Any, Any, str]]:
    """controller -> (mode, MpcConfig, BodyConfig, planner) for a plant's identified model."""
    mpc, body = e4r_settings()["sim_tuned"]
    model = mpc.replace(c_d=ident["c_d"], c_l=ident["c_l"])
    b = body.replace(thrust_gain=1.0)  # forces in the identified model's (or the true) newtons
    closed = model.replace(formulation="closed_stroke")
    return {"baseline": ("baseline", model, b, ""), "mpc_paper_id": ("mpc", model, b, ""),
            "mpc_closed_id": ("mpc", closed, b, ""), "mpc_closed_nost": ("mpc", closed.replace(lam_st=0.0), b, ""),
            "oracle": ("mpc", closed.replace(lam_st=0.0), b, "oracle")}


def _scenario(plant: str, v: float, seed: int, quick: bool, cfg: tuple[str, Any, Any, str], tag: str,
              frequency: float = 2.0) -> Scenario:
    settle, window = e4_timing(quick)
    mode, m, b, planner = cfg
    return Scenario(mode=mode, v_ref=v, seed=seed, plant=plant, settle_s=settle, window_s=window,
                    start_velocity=0.0, mpc=m, body=b, baseline=BaselineConfig(frequency=frequency),
                    planner=planner, tag=tag)


def matched(run: dict[str, Any]) -> bool:
    """Matched tracking: DVL speed MAE <= MATCH_MAE and true mean speed within MATCH_MEAN."""
    return bool(run["velocity_mae"] <= MATCH_MAE
                and abs(run["velocity_mean"] - run["scenario"]["v_ref"]) <= MATCH_MEAN)


def paired_saving(a: Sequence[float], b: Sequence[float], seed: int = 0) -> dict[str, Any]:
    """Saving of A against B (%, ``100 (1 - mean a / mean b)``) over paired samples, with a
    paired bootstrap 95 % interval (resampling the pairs)."""
    a_, b_ = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = a_.size
    if n < MIN_PAIRS:
        return {"pairs": int(n), "saving": math.nan, "lo": math.nan, "hi": math.nan, "comparable": False}
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n, size=(BOOTSTRAP, n))
    boot = 100.0 * (1.0 - a_[idx].mean(axis=1) / b_[idx].mean(axis=1))
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return {"pairs": int(n), "saving": float(100.0 * (1.0 - a_.mean() / b_.mean())), "lo": float(lo),
            "hi": float(hi), "comparable": True}


#: (A, B) comparisons reported in every case; the decision rules read the first two
COMPARISONS = (("mpc_closed_id", "mpc_closed_nost"), ("mpc_closed_id", "baseline_best"),
               ("mpc_closed_nost", "baseline_best"), ("mpc_paper_id", "baseline_best"),
               ("oracle", "baseline_best"), ("baseline_2hz", "baseline_best"), ("mpc_closed_id", "oracle"))


def compare(runs: list[dict[str, Any]], plant: str, v: float, key: str = PRIMARY) -> list[dict[str, Any]]:
    """Every comparison of :data:`COMPARISONS` in one plant-speed case, on the energy per metre
    ``key``."""
    by = {}
    for r in runs:
        s = r["scenario"]
        if s["plant"] == plant and s["v_ref"] == v:
            by[(s["controller"], s["seed"])] = r
    out = []
    for a, b in COMPARISONS:
        seeds = sorted(k[1] for k in by if k[0] == a and (b, k[1]) in by
                       and matched(by[k]) and matched(by[(b, k[1])]))
        res = paired_saving([by[(a, s)][key] for s in seeds], [by[(b, s)][key] for s in seeds])
        out.append({"plant": plant, "v_ref": v, "a": a, "b": b, **res})
    return out


def decisions(comparisons: list[dict[str, Any]], peaks: dict[tuple[str, float], float]) -> dict[str, Any]:
    """The declared decision rules over the cases' comparisons (docs/experiments/e7-declaration.md)."""
    st = {(c["plant"], c["v_ref"]): c for c in comparisons if (c["a"], c["b"]) == ("mpc_closed_id", "mpc_closed_nost")}
    vs = {(c["plant"], c["v_ref"]): c for c in comparisons if (c["a"], c["b"]) == ("mpc_closed_id", "baseline_best")}
    cases = []
    for key, c in st.items():
        b = vs[key]
        pays = bool(c["comparable"] and c["saving"] >= ST_PAYS_PCT and c["lo"] > 0.0
                    and b["comparable"] and b["saving"] > 0.0 and b["lo"] > 0.0)
        cases.append({"plant": key[0], "v_ref": key[1], "st_saving": c["saving"], "st_lo": c["lo"],
                      "st_hi": c["hi"], "vs_best": b["saving"], "vs_best_lo": b["lo"], "vs_best_hi": b["hi"],
                      "comparable": bool(c["comparable"] and b["comparable"]), "pays": pays,
                      "peak_st": peaks.get(key, math.nan),
                      "peak_in_corridor": bool(CORRIDOR[0] <= peaks.get(key, math.nan) <= CORRIDOR[1])})
    flow = [c for c in cases if c["plant"] != NULL_PLANT]
    comp = [c for c in flow if not math.isnan(c["st_saving"])]
    inside = [c["st_saving"] for c in comp if c["peak_in_corridor"]]
    outside = [c["st_saving"] for c in comp if not c["peak_in_corridor"]]
    null = [c for c in cases if c["plant"] == NULL_PLANT]
    null_ok = [c for c in null if not math.isnan(c["st_saving"])]
    rule1 = sum(c["pays"] for c in flow)
    return {
        "cases": cases,
        "rule1": {"pays_in": rule1, "flow_cases": len(flow), "comparable": len(comp),
                  "verdict": bool(comp and rule1 * 2 > len(comp))},
        "rule2": {"inside_mean": float(np.mean(inside)) if inside else math.nan, "inside_n": len(inside),
                  "outside_mean": float(np.mean(outside)) if outside else math.nan, "outside_n": len(outside),
                  "verdict": bool(inside and outside and np.mean(inside) > np.mean(outside))},
        "rule3": {"cases": len(null), "comparable": len(null_ok),
                  "max_abs": max((abs(c["st_saving"]) for c in null_ok), default=math.nan),
                  "verdict": bool(null_ok and len(null_ok) == len(null)
                                  and all(abs(c["st_saving"]) < NULL_BAND_PCT for c in null_ok))},
    }


def _tune(runs: list[dict[str, Any]]) -> dict[tuple[str, float], float]:
    """Per (plant, speed): the tuning frequency with the least energy per metre (:data:`PRIMARY`)
    among the held-out runs that match; 2 Hz where none matches."""
    best: dict[tuple[str, float], tuple[float, float]] = {}
    for r in runs:
        s = r["scenario"]
        key = (s["plant"], s["v_ref"])
        e = r[PRIMARY]
        if matched(r) and not math.isnan(e) and (key not in best or e < best[key][1]):
            best[key] = (s["baseline"]["frequency"], e)
    return {k: v[0] for k, v in best.items()}


def run_e7(client: Any, quick: bool, seed: int, progress: bool = True, n_seeds: int | None = None) -> dict[str, Any]:
    design = e7_design(quick, seed, n_seeds)
    plants, speeds, seeds = design["plants"], design["speeds"], design["seeds"]
    curves = all_curves(plants, tuple(speeds))
    peaks = {(c["plant"], c["v"]): c["peak_st"] for c in curves}
    idents = run_all(client, identify_plant, [(p, seed, quick) for p in plants], "E7 identification",
                     progress, star=True)
    identified = {d["plant"]: d for d in idents}
    configs = {p: _configs(identified[p]) for p in plants}
    # the best fixed frequency, on the held-out seed
    tuning = [_scenario(p, v, design["held_out"], quick, configs[p]["baseline"], "E7:tune", f)
              for p in plants for v in speeds for f in design["frequencies"]]
    tuned_runs = run_all(client, run_scenario, tuning, "E7 tuning", progress)
    chosen = _tune(tuned_runs)
    freq = {(p, v): chosen.get((p, v), 2.0) for p in plants for v in speeds}
    scenarios = []
    for p in plants:
        for v in speeds:
            for ctrl in E7_CONTROLLERS:
                cfg = configs[p]["baseline" if ctrl.startswith("baseline") else ctrl]
                f = freq[(p, v)] if ctrl == "baseline_best" else 2.0
                scenarios += [_scenario(p, v, s, quick, cfg, f"E7:{ctrl}", f) for s in seeds]
    runs = run_all(client, run_scenario, scenarios, "E7 runs", progress)
    _label(runs, ("experiment", "controller"))
    comparisons = [c for p in plants for v in speeds for c in compare(runs, p, v)]
    shaft = [c for p in plants for v in speeds for c in compare(runs, p, v, SECONDARY)]
    rows = []
    for r in runs:
        s = r["scenario"]
        rows.append({"plant": s["plant"], "v_ref": s["v_ref"], "controller": s["controller"], "seed": s["seed"],
                     "frequency": s["baseline"]["frequency"] if s["controller"].startswith("baseline") else None,
                     "matched": matched(r), "velocity_mean": r["velocity_mean"], "velocity_mae": r["velocity_mae"],
                     PRIMARY: r[PRIMARY], "power_electrical": r["power_electrical"],
                     SECONDARY: r[SECONDARY], "power_true": r["power_true"],
                     "st_in_range": r["st_in_range"], "stroke": r["stroke"], "rate": r["rate"]})
    settle, window = e4_timing(quick)
    mpc, body = e4r_settings()["sim_tuned"]
    return {
        "protocol": {**design, "controllers": list(E7_CONTROLLERS), "settle_s": settle, "window_s": window,
                     "match_mae": MATCH_MAE, "match_mean": MATCH_MEAN, "bootstrap": BOOTSTRAP,
                     "st_pays_pct": ST_PAYS_PCT, "null_band_pct": NULL_BAND_PCT, "corridor": list(CORRIDOR),
                     "plant_hash": plant_hash(plants), "declared_hash": plant_hash(e7_plants()),
                     "lam_f": mpc.lam_f, "lam_st": mpc.lam_st, "lam_d": mpc.lam_d, "lam_c": mpc.lam_c,
                     "lam_e": mpc.lam_e, "body_layer": body.layer, "reduced": bool(not quick and len(seeds) < E7_SEEDS)},
        "plants": {p: plant_assumptions(p) for p in plants},
        "curves": [{k: c[k] for k in ("plant", "v", "peak_st", "peak_eta", "feasible_st", "thrust_needed_per_fin")}
                   for c in curves],
        "identified": [identified[p] for p in plants],
        "tuning": [{"plant": p, "v_ref": v, "frequency": freq[(p, v)], "matched": (p, v) in chosen}
                   for p in plants for v in speeds],
        "rows": rows,
        "comparisons": comparisons,
        "decisions": decisions(comparisons, peaks),
        "comparisons_shaft": shaft,
        "decisions_shaft": decisions(shaft, peaks),
    }


def findings(res: dict[str, Any]) -> list[str]:
    """The decision rules' outcomes, as declared, in words: on the battery's energy per metre,
    then on the shaft's."""
    p = res["protocol"]
    out = [f"Plants hash {p['plant_hash']} (declared: {p['declared_hash']})"
           + ("" if p["plant_hash"] == p["declared_hash"] else " (a subset of the declared plants: quick run)") + "."]
    if p.get("reduced"):
        out.append(f"Reduced design as declared: seeds {', '.join(str(s) for s in p['seeds'])} of the 10.")
    out += [f"On the battery's energy per metre (primary): {s}" for s in _rules(res["decisions"], p)]
    if "decisions_shaft" in res:
        out += [f"On the shaft's energy per metre: {s}" for s in _rules(res["decisions_shaft"], p)]
    return out


def _rules(d: dict[str, Any], p: dict[str, Any]) -> list[str]:
    r1, r2, r3 = d["rule1"], d["rule2"], d["rule3"]
    out = []
    out.append(f"Rule 1 (St-awareness pays: closed-stroke MPC >= {p['st_pays_pct']:g} % below its no-St ablation, "
               f"interval above zero, and below the best-tuned baseline, interval above zero): holds in "
               f"{r1['pays_in']} of {r1['flow_cases']} plate cases ({r1['comparable']} comparable): "
               + ("St-awareness pays." if r1["verdict"] else "St-awareness does not pay (not in a majority of the comparable plate cases)."))
    if r2["inside_n"] and r2["outside_n"]:
        out.append(f"Rule 2 (larger saving where the plant's peak lies in the corridor): mean St-term saving "
                   f"{r2['inside_mean']:.1f} % in {r2['inside_n']} cases with the peak inside, "
                   f"{r2['outside_mean']:.1f} % in {r2['outside_n']} outside: "
                   + ("holds." if r2["verdict"] else "does not hold."))
    else:
        out.append("Rule 2: not decidable (no comparable case on one side of the corridor).")
    out.append(f"Rule 3 (null plant: |St-term saving| < {p['null_band_pct']:g} % at every speed): "
               f"{r3['comparable']} of {r3['cases']} cases comparable, largest |saving| "
               f"{r3['max_abs']:.1f} %: " + ("holds." if r3["verdict"] else "does not hold."))
    return out
