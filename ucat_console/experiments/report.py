"""report.md from results.json: every number shown is read from the JSON document.

:func:`render` takes the parsed ``results.json`` (nothing else) and returns Markdown, so the
report and the JSON cannot disagree. Tables hold one number per cell, formatted by
:func:`num` with a fixed number of decimals per column.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

TITLES = {
    "E1": "E1: two-stage solver benchmark (paper Table IV)",
    "E2": "E2: Strouhal corridor, baseline vs MPC (paper Fig. 6)",
    "E3": "E3: cost-term ablation (paper Table III)",
    "E4": "E4: closed loop, power and tracking (paper Table V, Fig. 7)",
    "E4R": "E4R: E4 from rest, the paper's settings and the shipped sim-tuned",
    "E6": "E6: where St-awareness pays: a family of plants, each with its identified model",
    "E7": "E7: St-awareness on plants whose efficiency depends on the flow (declared)",
    "E8": "E8: the efficiency seeker against the tuned and the paper's gaits (declared)",
    "E5": "E5: field-style circle at 3 m with a current (paper Fig. 8)",
    "sweep": "Weight sweep over the E4 protocol",
}


def num(x: Any, digits: int) -> str:
    """A number with ``digits`` decimals; "n/a" for None / NaN."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if isinstance(x, bool):
        return "yes" if x else "no"
    return f"{x:.{digits}f}"


def yes_no(x: bool) -> str:
    return "yes" if x else "no"


def saving(r: dict[str, Any], key: str) -> str:
    """A saving cell: the number where both runs track, else "not comparable"."""
    if r.get("comparable") is False:
        return "not comparable"
    return num(r[key], 1)


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _claims(claims: Sequence[dict[str, Any]], with_plant: bool = False) -> str:
    header = (["plant"] if with_plant else []) + ["claim", "paper", "ours", "reproduced"]
    rows = [([c["plant"]] if with_plant else []) + [c["claim"], c["paper"], c["ours"], yes_no(c["reproduced"])]
            for c in claims]
    return table(header, rows)


def _figures(res: dict[str, Any]) -> str:
    return "".join(f"![{f}]({f})\n\n" for f in res.get("figures", []))


def _findings(res: dict[str, Any]) -> str:
    items = res.get("findings", [])
    return "".join(f"- {f}\n" for f in items) + ("\n" if items else "")


def _e1(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: {p['targets']} targets ({p['targets_scipy']} for the scipy reference) x "
           f"{p['cycles']} cycles at V_B = {p['v_body']} m/s, planner seed {p['seed']}; solve time is "
           f"the wall time of one plan call on this machine.\n\n"]
    by = {(r["n"], r["solver"], r["stage"]): r for r in res["rows"]}
    prow = {r["n"]: r for r in res["paper"]["rows"]}
    red = {(r["n"], r["solver"]): r["reduction_pct"] for r in res["reduction"]}
    rows = []
    for n in p["ns"]:
        pr = prow.get(n, {})
        rows.append([
            str(n), num(pr.get("sampling_cost"), 4), num(by[(n, "numba", "sampling")]["mean_cost"], 4),
            num(by[(n, "scipy", "sampling")]["mean_cost"], 4), num(pr.get("two_stage_cost"), 4),
            num(by[(n, "numba", "two_stage")]["mean_cost"], 4), num(by[(n, "scipy", "two_stage")]["mean_cost"], 4),
            num(pr.get("reduction_pct"), 1), num(red[(n, "numba")], 1), num(red[(n, "scipy")], 1),
        ])
    out.append(table(["N", "paper sampling cost", "ours sampling (numba)", "ours sampling (scipy)",
                      "paper two-stage cost", "ours two-stage (numba)", "ours two-stage (scipy)",
                      "paper reduction %", "ours reduction % (numba)", "ours reduction % (scipy)"], rows))
    rows = []
    for n in p["ns"]:
        pr = prow.get(n, {})
        rows.append([str(n), num(pr.get("sampling_ms"), 2), num(by[(n, "numba", "sampling")]["p50_ms"], 3),
                     num(by[(n, "scipy", "sampling")]["p50_ms"], 3), num(pr.get("two_stage_ms"), 2),
                     num(by[(n, "numba", "two_stage")]["p50_ms"], 3), num(by[(n, "numba", "two_stage")]["p99_ms"], 3),
                     num(by[(n, "scipy", "two_stage")]["p50_ms"], 3)])
    out.append("\nSolve time (ms):\n\n")
    out.append(table(["N", "paper sampling", "ours sampling p50 (numba)", "ours sampling p50 (scipy)",
                      "paper two-stage", "ours two-stage p50 (numba)", "ours two-stage p99 (numba)",
                      "ours two-stage p50 (scipy)"], rows))
    return "".join(out)


def _e2(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: {p['demands']} body force demands (the E1 grid as F*), allocated to four fins "
           f"(control.md section 7), {p['cycles']} cycles per fin from theta = 0, first plan excluded, "
           f"planner seed {p['seed']}. St is the plan's Strouhal number at the given speed; force error "
           f"the plan's c_force per fin and the four fins' summed force against the demand.\n\n"]
    rows = []
    for v, per in res["by_speed"].items():
        for ctrl in ("baseline", "mpc"):
            r = per[ctrl]
            rows.append([v, ctrl, num(r["st_mean"], 3), num(r["st_max"], 3), num(r["st_in_range_pct"], 1),
                         num(r["st_slope_per_n"], 3), num(r["st_force_corr"], 3), num(r["force_error_fin"], 3),
                         num(r["force_error_fin_max"], 3), num(r["force_error_body"], 3)])
    out.append(table(["V (m/s)", "controller", "St mean", "St max", "St in band %", "St slope per N",
                      "St-force correlation", "force error per fin (N)", "max per fin (N)",
                      "body force error (N)"], rows))
    out.append(_sensitivity(res, ["v"], ["st_in_range_pct", "force_error_fin"],
                            ["V (m/s)"], ["MPC St in band %", "force error per fin (N)"]))
    return "".join(out)


def _sensitivity(res: dict[str, Any], keys: Sequence[str], metrics: Sequence[str],
                 key_titles: Sequence[str], titles: Sequence[str]) -> str:
    """The rates from each initial previous plan (the first row: the protocol's)."""
    rows = [[num(x, 1) for x in r["u_prev0"]] + [*[str(r[k]) for k in keys],
             *[num(r[m], 3 if "error" in m or m == "stability" else 1) for m in metrics], num(r["frozen_pct"], 1)]
            for r in res.get("u_prev_sensitivity", [])]
    if not rows:
        return ""
    return ("\nThe same from other initial previous plans u_prev (d_1 d_2 w_1 w_2); frozen: plans "
            "exactly the initial u_prev:\n\n"
            + table(["u_prev d_1", "d_2", "w_1", "w_2", *key_titles, *titles, "frozen %"], rows))


def _e3(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: {p['targets']} targets x speeds {', '.join(str(v) for v in p['speeds'])} m/s x "
           f"{p['cycles']} cycles, first plan excluded, seeds {', '.join(str(s) for s in p['seeds'])}.\n\n"]
    rows = [[r["config"], num(r["paper_force_error"], 4), num(r["force_error"], 4),
             num(r["paper_st_deviation"], 4), num(r["st_deviation"], 4), num(r["paper_in_range_pct"], 1),
             num(r["in_range_pct"], 1), num(r["paper_stability"], 3), num(r["stability"], 3)]
            for r in res["rows"]]
    out.append(table(["configuration", "paper force error (N)", "ours force error (N)", "paper St deviation",
                      "ours St deviation", "paper in range %", "ours in range %", "paper stability",
                      "ours stability"], rows))
    out.append(_sensitivity(res, ["config"], ["force_error", "in_range_pct", "stability"],
                            ["configuration"], ["force error (N)", "in range %", "stability"]))
    if "corridor_bounds" in res:
        b = res["table_iv_bound"]
        out.append(f"\nWhat the paper's numbers allow. Table IV's mean two-stage cost {b['mean_cost']:g} at N = 500 "
                   f"with lam_f = {b['lam_f']:g} bounds its mean force error from above: every other term is >= 0, "
                   f"so c_force <= J / lam_f = {num(b['force_error_at_most'], 3)} N (an upper bound: Table III's "
                   "0.156 N lies below it and does not contradict it). Inside the corridor a stroke pair with "
                   "equal rates has w <= 2 V St_high / L_f, where the model's largest mean force is F_max; over "
                   "the grid no such plan can have a mean force error below mean(max(0, |f*| - F_max)). The "
                   "bounds are for equal-rate pairs only: a slow and a fast stroke whose cycle St (eq 10) lies in "
                   "the corridor make more (docs/findings.md):\n\n")
        out.append(table(["V (m/s)", "w at St 0.35 (rad/s)", "F_max, d_2 = -d_1 (N)", "F_max, equal rates, any strokes (N)",
                          "grid mean |f*| (N)", "least mean force error in the corridor (N)"],
                         [[num(r["v"], 1), num(r["w_max_in_corridor"], 2), num(r["f_max_symmetric"], 3),
                           num(r["f_max"], 3),
                           num(r["mean_demand"], 3), num(r["least_mean_force_error"], 3)]
                          for r in res["corridor_bounds"]]))
    return "".join(out)


def _plants(plants: dict[str, Any]) -> str:
    rows = [[name, a["model"], a["coefficients"], num(a["rho"], 1), num(a["c_d"], 3), num(a["c_l"], 3),
             num(a["area"], 3), num(a["r_c"], 3), num(a["fin_length"], 3), num(a["c_d0"], 3),
             num(a["lift_ratio"], 2), num(a["added_mass"], 2), str(a["strips"])]
            for name, a in plants.items()]
    return table(["plant", "fin model", "calibrated to", "rho", "C_D", "C_L", "A_f", "r_c", "L_f", "C_D0",
                  "C_Lmax / C_N", "added mass", "strips"], rows)


def _e4(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: depth {p['depth']} m, references {', '.join(str(v) for v in p['speeds'])} m/s, "
           f"controllers {', '.join(p['controllers'])}, seeds {', '.join(str(s) for s in p['seeds'])}; "
           f"each run starts cruising at its reference, settles {p['settle_s']:g} s and is measured over "
           f"{p['window_s']:g} s. Power is the encoder-based estimate of control.md section 9 (the paper's "
           f"method); shaft power is the plant's, battery power the drives' electrical input by the plant's drive "
           f"model (docs/power.md). Savings are against the baseline at the same "
           f"reference, where both track (velocity MAE <= {p.get('tracking_mae', 0.03):g} m/s; else not "
           f"comparable); reached: mean speed >= {p['reached_share']:g} of the reference.\n\n"
           "Plant assumptions:\n\n", _plants(res["plants"]), "\n"]
    for plant in res["plants"]:
        out.append(f"\nPlant `{plant}`:\n\n")
        rows = []
        for r in (r for r in res["rows"] if r["plant"] == plant):
            rows.append([num(r["v_ref"], 1), r["mode"], num(r["paper_power"], 3), num(r["power_est"], 4),
                         num(r["power_est_sd"], 4), num(r["power_true"], 4), num(r["power_electrical"], 3),
                         num(r["paper_saving"], 1), saving(r, "saving_est"), saving(r, "saving_true"),
                         saving(r, "saving_el"), num(r["paper_velocity_mae"], 4),
                         num(r["velocity_mae"], 4), num(r["velocity_mean"], 3), yes_no(r["reached"]),
                         num(r["paper_st_mae"], 4), num(r["st_mae"], 4), num(r["st_plant_mae"], 4),
                         num(r["depth_mae"], 4), num(r["late_plans"], 1)])
        out.append(table(["v_ref (m/s)", "controller", "paper power (W)", "ours power (W)", "sd (W)",
                          "ours shaft (W)", "ours battery (W)", "paper saving %", "ours saving %",
                          "ours shaft saving %", "ours battery saving %",
                          "paper vel MAE", "ours vel MAE", "mean speed", "reached", "paper St MAE",
                          "ours St MAE (plans)", "ours St MAE (plant)", "depth MAE (m)", "late plans"], rows))
        out.append("\n" + _claims(res["claims"][plant]))
    return "".join(out)


def _e4r(res: dict[str, Any]) -> str:
    p = res["protocol"]
    t = p["sim_tuned"]
    out = [f"Protocol: from rest (hull still, fins at the forward-thrust centre), depth {p['depth']} m, "
           f"references {', '.join(str(v) for v in p['speeds'])} m/s, controllers "
           f"{', '.join(p['controllers'])} (mpc_closed: the closed-stroke formulation with the same "
           f"model and weights), seeds {', '.join(str(s) for s in p['seeds'])}; settle {p['settle_s']:g} s, "
           f"measured over {p['window_s']:g} s. Settings: `paper` (Table I's weights and PIDs, the paper's "
           f"body layer and its baseline, eq 19) and `sim_tuned` (the shipped sim-tuned: lam_f {t['lam_f']:g}, "
           f"lam_st {t['lam_st']:g}, lam_d {t['lam_d']:g}, centre_rate {t.get('centre_rate', 0):g} rad/s; "
           f"the {t.get('body_layer', 'paper')} body layer, thrust gain {t.get('thrust_gain', 1):g}, velocity "
           f"loop kp {t['velocity_kp']:g} ki {t['velocity_ki']:g}; the fin-model baseline). "
           f"Power is the estimate (control.md section 9), shaft power the plant's, battery the drives' "
           f"electrical input (docs/power.md), J/m the battery's energy per metre; savings where both track (velocity MAE <= {p['tracking_mae']:g} m/s).\n\n"]
    for setting in p["settings"]:
        for plant in res["plants"]:
            rows = [r for r in res["rows"] if r["settings"] == setting and r["plant"] == plant]
            if not rows:
                continue
            out.append(f"\nSettings `{setting}`, plant `{plant}`:\n\n")
            out.append(table(
                ["v_ref (m/s)", "controller", "mean v", "vel MAE", "power (W)", "shaft (W)", "battery (W)",
                 "battery J/m", "saving %", "battery J/m saving %", "shaft J/m saving %", "St MAE (plans)",
                 "St MAE (plant)",
                 "stroke (rad)", "rate (rad/s)", "opening (rad)", "winding (rad/min)"],
                [[num(r["v_ref"], 1), r["controller"], num(r["velocity_mean"], 3), num(r["velocity_mae"], 3),
                  num(r["power_est"], 3), num(r["power_true"], 3), num(r["power_electrical"], 3),
                  num(r["energy_per_metre_electrical"], 3), saving(r, "saving_est"), saving(r, "saving_epm_el"),
                  saving(r, "saving_epm_true"), num(r["st_mae"], 3),
                  num(r["st_plant_mae"], 3), num(r["stroke"], 2), num(r["rate"], 2), num(r["opening"], 3),
                  num(r["winding"], 1)] for r in rows]))
    return "".join(out)


def _e6(res: dict[str, Any]) -> str:
    p = res["protocol"]
    t = p["settings"]
    out = [f"Declared before it was run (docs/experiments/e6-declaration.md). Plants: the plate "
           f"calibrated to the paper's fin coefficients times a scale G (G times the thrust per w^2, paid with G "
           f"times the shaft's load), each as the plate in the flow and as the still-water null plant "
           f"({', '.join(p['plants'])}). Each plant's model is identified first from its own recorded "
           f"identification manoeuvre (`ucat-console identify`'s path). Runs from rest at "
           f"{', '.join(str(v) for v in p['speeds'])} m/s, seeds {', '.join(str(s) for s in p['seeds'])}, "
           f"settle {p['settle_s']:g} s, measured {p['window_s']:g} s, the shipped sim-tuned's weights and "
           f"body layer (lam_f {t['lam_f']:g}, lam_st {t['lam_st']:g}, lam_d {t['lam_d']:g}, centre_rate "
           f"{t.get('centre_rate', 0):g} rad/s; the {t.get('body_layer', 'paper')} body layer, its thrust gain "
           f"each model's: the identified scale with the paper's model, 1 with the identified one), "
           f"closed-stroke lam_c {p['closed_stroke']['lam_c']:g} /rad, lam_e {p['closed_stroke']['lam_e']:g} /W. "
           f"Controllers: baseline (the fin-model inverse with the paper's coefficients; savings are against "
           f"it), baseline_id (the same with the identified ones), mpc (the paper's formulation and model), "
           f"mpc_id (the paper's formulation, identified model), mpc_closed_id (closed strokes, identified model). "
           f"Savings of the battery's energy per metre (and the shaft's beside it) against the baseline where both "
           f"track (vel MAE <= {p['tracking_mae']:g} m/s); the baseline leaves the corridor where fewer than "
           f"{100 * p['corridor_share']:g} % of its plans have St in [0.25, 0.35].\n\n",
           "Identified models:\n\n",
           table(["plant", "scale", "fin model", "C_D", "+-", "C_L", "+-", "windows", "steady", "rms (N)"],
                 [[d["plant"], num(d["scale"], 1), d["model"], num(d["c_d"], 3), num(d["c_d_ci"], 3),
                   num(d["c_l"], 3), num(d["c_l_ci"], 3), str(d["windows"]), str(d["steady_windows"]),
                   num(d["rms_residual"], 3)] for d in res["identified"]]),
           "\nRuns:\n\n"]
    out.append(table(
        ["plant", "v_ref (m/s)", "controller", "mean v", "vel MAE", "battery (W)", "battery J/m",
         "battery J/m saving %", "shaft J/m saving %", "St in range (share)", "baseline out of corridor", "stroke (rad)", "rate (rad/s)",
         "opening (rad)"],
        [[r["plant"], num(r["v_ref"], 1), r["controller"], num(r["velocity_mean"], 3), num(r["velocity_mae"], 3),
          num(r["power_electrical"], 3), num(r["energy_per_metre_electrical"], 3), saving(r, "saving_epm_el"),
          saving(r, "saving_epm_true"),
          num(r["st_in_range"], 3), yes_no(r["baseline_out_of_corridor"]), num(r["stroke"], 2),
          num(r["rate"], 2), num(r["opening"], 3)] for r in res["rows"]]))
    return "".join(out)


def _e5(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: {p['mode']}, depth {p['depth']} m (start {p['start_depth']} m), "
           f"{p['v_ref']} m/s, yaw rate {p['yaw_rate']} rad/s, {p['duration_s']:g} s, current "
           f"{p['current_ned']} m/s (NED), seed {p['seed']}; metrics over the second half "
           f"(from {p['measured_from_s']:g} s). Yaw rate is positive clockwise seen from above (NED, z down).\n\n",
           "Plant assumptions:\n\n", _plants(res["plants"]), "\n"]
    rows = [[r["plant"], num(r["depth_mae"], 4), num(r["depth_final"], 3), num(r["velocity_mae"], 4),
             num(r["velocity_err_p95"], 4), num(r["velocity_within_0025_pct"], 1), num(r["yaw_rate_mean"], 4),
             num(r["yaw_rate_mae"], 4), num(r["turn_deg"], 1), num(r["radius_m"], 2),
             yes_no(r["clockwise_from_above"]), num(r["power_est"], 4)] for r in res["rows"]]
    out.append(table(["plant", "depth MAE (m)", "final depth (m)", "vel MAE (m/s)", "vel error p95 (m/s)",
                      "within band %", "mean yaw rate", "yaw rate MAE", "turned (deg)", "radius (m)",
                      "clockwise from above", "power (W)"], rows))
    out.append("\n" + _claims(res["claims"], with_plant=True))
    return "".join(out)


def _sweep(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Protocol: the E4 protocol on plant `{p['plant']}`, formulation {p.get('formulation', 'paper')}, references "
           f"{', '.join(str(v) for v in p['speeds'])} m/s, seeds {', '.join(str(s) for s in p['seeds'])}, "
           f"lam_st in {p['lam_st']}, lam_d in {p['lam_d']}, settle {p['settle_s']:g} s, window {p['window_s']:g} s.\n\n"]
    out.append(sweep_table(res))
    return "".join(out)


def sweep_table(res: dict[str, Any]) -> str:
    rows = [[num(r["v_ref"], 1), r["mode"], num(r["lam_st"], 2), num(r["lam_d"], 2), num(r["power_est"], 4),
             num(r["energy_per_metre"], 3), saving(r, "saving_est"), saving(r, "saving_epm"),
             num(r["velocity_mae"], 4), num(r["st_mae"], 4), num(r["depth_mae"], 4)]
            for r in sorted(res["rows"], key=lambda r: (r["v_ref"], r["mode"], r["lam_st"] or 0.0, r["lam_d"] or 0.0))]
    return table(["v_ref (m/s)", "controller", "lam_st", "lam_d", "power (W)", "energy per metre (J/m)",
                  "saving %", "J/m saving %", "vel MAE (m/s)", "St MAE", "depth MAE (m)"], rows)


def _ci(c: dict[str, Any]) -> str:
    if not c["comparable"]:
        return f"not comparable ({c['pairs']} pairs)"
    return f"{c['saving']:.1f} [{c['lo']:.1f}, {c['hi']:.1f}] ({c['pairs']})"


def _e7(res: dict[str, Any]) -> str:
    p = res["protocol"]
    out = [f"Declared before it was run (docs/experiments/e7-declaration.md); plants hash **{p['plant_hash']}** "
           f"(declared {p['declared_hash']}). Plants {', '.join(p['plants'])}; from rest at "
           f"{', '.join(str(v) for v in p['speeds'])} m/s; seeds {', '.join(str(s) for s in p['seeds'])}"
           f"{' (the declared reduced design)' if p.get('reduced') else ''}; settle {p['settle_s']:g} s, measured "
           f"{p['window_s']:g} s; the shipped sim-tuned's {p['body_layer']} body layer and weights (lam_f "
           f"{p['lam_f']:g}, lam_st {p['lam_st']:g}, lam_d {p['lam_d']:g}, lam_c {p['lam_c']:g}, lam_e "
           f"{p['lam_e']:g}); best fixed frequency tuned on seed {p['held_out']} over "
           f"{', '.join(f'{f:g}' for f in p['frequencies'])} Hz. Matched tracking: DVL speed MAE <= "
           f"{p['match_mae']:g} m/s and true mean speed within {p['match_mean']:g} m/s of the reference. "
           f"Savings of the battery's energy per metre (the primary figure; the shaft's beside it), A against "
           f"B, over the seeds where both match, with paired bootstrap 95 % intervals ({p['bootstrap']} "
           f"resamples); (n) = pairs.\n\n",
           "Open-loop curves (declared):\n\n",
           table(["plant", "v (m/s)", "peak St", "peak eta", "St that makes the thrust", "thrust per fin (N)"],
                 [[c["plant"], num(c["v"], 1), num(c["peak_st"], 2), num(c["peak_eta"], 3),
                   "none" if not c["feasible_st"] else f"{c['feasible_st'][0]:.2f}-{c['feasible_st'][1]:.2f}",
                   num(c["thrust_needed_per_fin"], 3)] for c in res["curves"]]),
           "\nIdentified models:\n\n",
           table(["plant", "C_D", "+-", "C_L", "+-"],
                 [[d["plant"], num(d["c_d"], 3), num(d["c_d_ci"], 3), num(d["c_l"], 3), num(d["c_l_ci"], 3)]
                  for d in res["identified"]]),
           "\nBest fixed frequency (held-out seed):\n\n",
           table(["plant", "v (m/s)", "frequency (Hz)", "a tracking frequency found"],
                 [[t["plant"], num(t["v_ref"], 1), num(t["frequency"], 2), yes_no(t["matched"])]
                  for t in res["tuning"]]),
           "\nDecision rules, per case (St term: closed-stroke MPC against its no-St ablation):\n\n",
           table(["plant", "v (m/s)", "peak St", "peak in corridor", "St-term saving % [95 % CI]",
                  "vs best baseline % [95 % CI]", "pays"],
                 [[c["plant"], num(c["v_ref"], 1), num(c["peak_st"], 2), yes_no(c["peak_in_corridor"]),
                   "n/a" if c["st_saving"] is None else f"{c['st_saving']:.1f} [{c['st_lo']:.1f}, {c['st_hi']:.1f}]",
                   "n/a" if c["vs_best"] is None else f"{c['vs_best']:.1f} [{c['vs_best_lo']:.1f}, {c['vs_best_hi']:.1f}]",
                   yes_no(c["pays"])] for c in res["decisions"]["cases"]]),
           "\nEvery comparison (saving % [95 % CI] (pairs)):\n\n",
           table(["plant", "v (m/s)", "A", "B", "saving of A against B: battery", "shaft"],
                 [[c["plant"], num(c["v_ref"], 1), c["a"], c["b"], _ci(c), _ci(s)]
                  for c, s in zip(res["comparisons"], res.get("comparisons_shaft", res["comparisons"]))]),
           "\nEvery run is in e7_runs.csv; per case (mean over seeds; matched = runs that match):\n\n"]
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in res["rows"]:
        groups.setdefault((r["plant"], r["v_ref"], r["controller"]), []).append(r)

    def mean(rs: list[dict[str, Any]], k: str) -> float:
        vals = [r[k] for r in rs if r[k] is not None]
        return sum(vals) / len(vals) if vals else float("nan")

    out.append(table(["plant", "v (m/s)", "controller", "matched", "mean v", "vel MAE", "battery J/m", "battery W",
                      "shaft J/m", "shaft W", "St in range", "stroke (rad)", "rate (rad/s)"],
                     [[k[0], num(k[1], 1), k[2], f"{sum(r['matched'] for r in rs)}/{len(rs)}",
                       num(mean(rs, "velocity_mean"), 3), num(mean(rs, "velocity_mae"), 3),
                       num(mean(rs, "energy_per_metre_electrical"), 3), num(mean(rs, "power_electrical"), 3),
                       num(mean(rs, "energy_per_metre_true"), 3), num(mean(rs, "power_true"), 4),
                       num(mean(rs, "st_in_range"), 2), num(mean(rs, "stroke"), 2), num(mean(rs, "rate"), 2)]
                      for k, rs in groups.items()]))
    return "".join(out)


def _e8(res: dict[str, Any]) -> str:
    p, t = res["protocol"], res["protocol"]["timing"]
    seekers = "; ".join(f"`{k}`: mode {v['mode']} over " + ", ".join(f"{n} [{lo:g}, {hi:g}]" for n, lo, hi in v["params"])
                        for k, v in p["seek_params"].items())
    out = [f"Declared before it was run (docs/experiments/e8-declaration.md); plants hash **{p['plant_hash']}** "
           f"(declared {p['declared_hash']}). Plants {', '.join(p['plants'])}; "
           f"{', '.join(str(v) for v in p['speeds'])} m/s; test seeds {', '.join(str(s) for s in p['seeds'])}"
           f"{' (the declared reduced design)' if p['reduced'] else ''}; fixed frequency tuned on seed "
           f"{p['held_out']} over {', '.join(f'{f:g}' for f in p['frequencies'])} Hz. From rest, "
           f"{t['hold_s']:g} s held, then {t['window_s']:g} s measured (a seeker: {t['candidates']} candidates of "
           f"{t['seek_settle_s']:g} s settle and {t['seek_window_s']:g} s measure, then its best measured so). "
           f"Seekers: {seekers}. Changes ({', '.join(p['changes'])}) on {p['change_plant']} at "
           f"{p['change_speed']:g} m/s, {t['after_change_s']:g} s after each ({p['reseek_candidates']} candidates). "
           f"Savings of the battery's energy per metre, A against B, over the seeds where both track, with paired "
           f"bootstrap 95 % intervals; (n) = pairs.\n\n",
           "Tuned fixed frequency (held-out seed):\n\n",
           table(["plant", "v (m/s)", "frequency (Hz)", "a tracking frequency found"],
                 [[r["plant"], num(r["v_ref"], 1), num(r["frequency"], 2), yes_no(r["tracks"])] for r in res["tuning"]]),
           "\nEvery comparison (saving % [95 % CI] (pairs)):\n\n",
           table(["plant", "v (m/s)", "A", "B", "saving of A against B"],
                 [[c["plant"], num(c["v_ref"], 1), c["a"], c["b"], _ci(c)] for c in res["comparisons"]]),
           "\nAfter a change (the seeker against the baseline tuned before it):\n\n",
           table(["change", "A", "tracking held", "saving % [95 % CI] (pairs)"],
                 [[c["change"], c["a"], f"{c['held']}/{c['runs']}", _ci(c)] for c in res["change_comparisons"]]),
           "\nTime to converge (s from the search's start; per run):\n\n",
           table(["plant", "v (m/s)", "seeker", "seed", "change", "converged (s)", "after the change (s)"],
                 [[c["plant"], num(c["v_ref"], 1), c["controller"], str(c["seed"]), c["change"] or "-",
                   num(c["converged_s"], 0), num(c["after_change_converged_s"], 0)] for c in res["convergence"]]),
           "\nEvery run is in e8_runs.csv.\n"]
    return "".join(out)


_SECTIONS = {"E1": _e1, "E2": _e2, "E3": _e3, "E4": _e4, "E4R": _e4r, "E5": _e5, "E6": _e6, "E7": _e7, "E8": _e8,
             "sweep": _sweep}


def render(doc: dict[str, Any]) -> str:
    """The whole report from the parsed results.json."""
    m = doc["meta"]
    out = [f"# {m['title']}\n\n",
           f"Command: `{m['command']}`; {'quick (reduced) runs' if m['quick'] else 'full runs'}; "
           f"base seed {m['seed']}; executor: {m['executor']}; finished {m['finished']}.\n\n"]
    rt = [[name, num(res["runtime_s"], 1)] for name, res in doc["experiments"].items()]
    out.append(table(["experiment", "runtime (s)"], rt))
    for name, res in doc["experiments"].items():
        out.append(f"\n## {TITLES[name]}\n\n")
        out.append(_SECTIONS[name](res))
        if "claims" in res and name in ("E1", "E2", "E3"):
            out.append("\n" + _claims(res["claims"]))
        out.append("\n" + _findings(res))
        out.append(_figures(res))
    return "".join(out)
