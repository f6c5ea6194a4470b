"""PNG figures of the experiments (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ucat_console.experiments.closed_loop_runs import TRACKING_MAE  # noqa: E402

CORRIDOR_COLOUR = "#cfe8cf"
MODE_COLOURS = {"baseline": "tab:gray", "mpc": "tab:blue", "mpc_sync": "tab:orange", "mpc_closed": "tab:green"}


def _save(fig: Any, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def e1_figure(res: dict[str, Any], out: Path) -> str:
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for solver, ls in (("numba", "-"), ("scipy", "--")):
        for stage, mk in (("sampling", "o"), ("two_stage", "s")):
            rows = [r for r in res["rows"] if r["solver"] == solver and r["stage"] == stage]
            ns = [r["n"] for r in rows]
            a.plot(ns, [r["mean_cost"] for r in rows], ls, marker=mk, label=f"{solver} {stage}")
            b.plot(ns, [r["p50_ms"] for r in rows], ls, marker=mk, label=f"{solver} {stage}")
    pr = res["paper"]["rows"]
    a.plot([r["n"] for r in pr], [r["sampling_cost"] for r in pr], "k:", marker="o", label="paper sampling")
    a.plot([r["n"] for r in pr], [r["two_stage_cost"] for r in pr], "k:", marker="s", label="paper two-stage")
    b.plot([r["n"] for r in pr], [r["two_stage_ms"] for r in pr], "k:", marker="s", label="paper two-stage")
    a.set_xscale("log"), b.set_xscale("log"), b.set_yscale("log")
    a.set_xlabel("samples N"), b.set_xlabel("samples N")
    a.set_ylabel("mean final cost"), b.set_ylabel("median solve time (ms)")
    a.legend(fontsize=7), b.legend(fontsize=7)
    return _save(fig, out / "e1_cost_time.png")


def e2_figure(points: Sequence[dict[str, Any]], speeds: Sequence[float], st_band: tuple[float, float],
              out: Path) -> str:
    fig, axes = plt.subplots(1, len(speeds), figsize=(4 * len(speeds), 3.6), sharey=True)
    for ax, v in zip(axes, speeds):
        ax.axhspan(*st_band, color=CORRIDOR_COLOUR, label="St corridor")
        for ctrl, c in (("baseline", "tab:gray"), ("mpc", "tab:blue")):
            pts = [p for p in points if p["v"] == v and p["controller"] == ctrl]
            ax.scatter([p["requested"] for p in pts], [p["st"] for p in pts], s=6, color=c, label=ctrl, alpha=0.6)
        ax.set_title(f"V = {v} m/s")
        ax.set_xlabel("requested fin force |f*| (N)")
    axes[0].set_ylabel("Strouhal number of the plan")
    axes[0].legend(fontsize=7)
    return _save(fig, out / "e2_st_corridor.png")


def e3_figure(res: dict[str, Any], out: Path) -> str:
    rows = res["rows"]
    x = range(len(rows))
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.bar([i - 0.2 for i in x], [r["in_range_pct"] for r in rows], 0.4, label="ours")
    ax.bar([i + 0.2 for i in x], [r["paper_in_range_pct"] for r in rows], 0.4, label="paper", color="k", alpha=0.5)
    ax.set_xticks(list(x), [r["config"] for r in rows], rotation=15, fontsize=8)
    ax.set_ylabel("St in corridor (%)")
    ax.legend()
    return _save(fig, out / "e3_ablation.png")


def e4_timeseries(traces: dict[str, Any], speed: float, st_band: tuple[float, float], out: Path) -> str:
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    (ad, av), (ap, ast) = axes
    for mode, tr in traces.items():
        c = MODE_COLOURS.get(mode)
        ad.plot(tr["t"], tr["depth"], color=c, label=mode)
        av.plot(tr["t"], tr["velocity"], color=c, label=mode)
        ap.plot(tr["t"], tr["power"], color=c, label=mode)
        ast.plot(tr["t"], tr["st_mean"], color=c, label=mode)
    av.axhline(speed, color="k", ls="--", lw=0.8)
    ast.axhspan(*st_band, color=CORRIDOR_COLOUR)
    ad.set_ylabel("depth (m)"), av.set_ylabel("forward velocity (m/s)")
    ap.set_ylabel("total mechanical power (W)"), ast.set_ylabel("mean fin St (plant)")
    ap.set_xlabel("time (s)"), ast.set_xlabel("time (s)")
    ad.invert_yaxis()
    av.legend(fontsize=7)
    return _save(fig, out / "e4_timeseries.png")


def e4_power(res: dict[str, Any], out: Path) -> str:
    plants = list(res["plants"])
    fig, axes = plt.subplots(1, len(plants), figsize=(4 * len(plants), 3.6), sharey=True)
    for ax, plant in zip(axes, plants):
        for mode, c in MODE_COLOURS.items():
            rows = [r for r in res["rows"] if r["plant"] == plant and r["mode"] == mode]
            ax.errorbar([r["v_ref"] for r in rows], [r["power_est"] for r in rows],
                        yerr=[r["power_est_sd"] for r in rows], color=c, marker="o", label=mode, capsize=3)
        ax.set_title(plant)
        ax.set_xlabel("reference velocity (m/s)")
    axes[0].set_ylabel("mean mechanical power (W)")
    axes[0].legend(fontsize=7)
    return _save(fig, out / "e4_power.png")


def e5_figure(traces: dict[str, Any], res: dict[str, Any], out: Path) -> str:
    p = res["protocol"]
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    (axy, ad), (av, ar) = axes
    for plant, tr in traces.items():
        axy.plot(tr["y"], tr["x"], label=plant)
        ad.plot(tr["t"], tr["depth"], label=plant)
        av.plot(tr["t"], tr["velocity_dvl"], label=plant)
        ar.plot(tr["t"], tr["yaw_rate"], label=plant)
    axy.set_xlabel("east (m)"), axy.set_ylabel("north (m)"), axy.set_aspect("equal", adjustable="datalim")
    ad.axhline(p["depth"], color="k", ls="--", lw=0.8), ad.invert_yaxis(), ad.set_ylabel("depth (m)")
    av.axhline(p["v_ref"], color="k", ls="--", lw=0.8), av.set_ylabel("DVL forward velocity (m/s)")
    ar.axhline(p["yaw_rate"], color="k", ls="--", lw=0.8), ar.set_ylabel("yaw rate (rad/s)")
    for ax in (ad, av, ar):
        ax.set_xlabel("time (s)")
    axy.legend(fontsize=7)
    return _save(fig, out / "e5_field.png")


def e4r_figure(res: dict[str, Any], out: Path) -> str:
    """The battery's energy per metre against the reference, per setting and plant (E4R)."""
    settings, plants = res["protocol"]["settings"], list(res["plants"])
    fig, axes = plt.subplots(len(settings), len(plants), figsize=(4 * len(plants), 3.2 * len(settings)),
                             squeeze=False, sharex=True)
    for i, setting in enumerate(settings):
        for j, plant in enumerate(plants):
            ax = axes[i][j]
            for ctrl in res["protocol"]["controllers"]:
                rows = [r for r in res["rows"] if r["settings"] == setting and r["plant"] == plant
                        and r["controller"] == ctrl]
                v = [r["v_ref"] for r in rows]
                ax.plot(v, [r["energy_per_metre_electrical"] for r in rows], "o-", label=ctrl,
                        color=MODE_COLOURS.get(ctrl))
                for r in rows:
                    if not r["tracks"]:
                        ax.plot(r["v_ref"], r["energy_per_metre_electrical"], "x", color="k")
            ax.set_yscale("log")
            ax.set_title(f"{setting}, {plant}", fontsize=8)
            ax.set_xlabel("reference (m/s)")
            ax.set_ylabel("battery energy per metre (J/m)")
    axes[0][0].legend(fontsize=7, title="x: not tracking", title_fontsize=7)
    return _save(fig, out / "e4r_energy_per_metre.png")


def e6_figure(res: dict[str, Any], out: Path) -> str:
    """The battery's energy-per-metre saving against the coefficients' scale (E6): the closed-stroke MPC with
    its identified model (solid) and eq 19 with the identified C_D (dotted), comparable
    cases only; savings below the axis are drawn on it (with their value)."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    gains = {d["plant"]: d["scale"] for d in res["identified"]}
    wakes = {d["plant"]: d["model"] for d in res["identified"]}
    lo = -100.0
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    for ax, wake in zip(axes, ("plate", "still_water")):
        for ctrl, style in (("mpc_closed_id", "o-"), ("baseline_id", "^:")):
            for v, colour in zip(res["protocol"]["speeds"], colours):
                rows = sorted((r for r in res["rows"] if r["controller"] == ctrl and r["v_ref"] == v
                               and wakes[r["plant"]] == wake and r["comparable"]),
                              key=lambda r: gains[r["plant"]])
                g = [gains[r["plant"]] for r in rows]
                y = [max(lo, r["saving_epm_el"]) for r in rows]
                ax.plot(g, y, style, color=colour, label=f"{ctrl} {v:g} m/s", ms=5)
                for r, gg, yy in zip(rows, g, y):
                    if r["saving_epm_el"] < lo:
                        ax.annotate(f"{r['saving_epm_el']:.0f}", (gg, yy), fontsize=6,
                                    xytext=(3, 3), textcoords="offset points")
        ax.axhline(res["protocol"]["target_pct"], color="tab:red", lw=0.8, ls="--")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_xlim(0.8 * min(gains.values()), 1.25 * max(gains.values()))
        ax.set_xticks(sorted(set(gains.values())), [f"{g:g}" for g in sorted(set(gains.values()))])
        ax.set_ylim(lo - 8.0, 70.0)
        ax.set_xlabel("scale G of the fin's coefficients")
        ax.set_title(f"{wake} (dashed: the {res['protocol']['target_pct']:g} % target)", fontsize=9)
    axes[0].set_ylabel("battery energy per metre saved vs baseline (%)")
    axes[1].legend(fontsize=6, ncol=2)
    return _save(fig, out / "e6_saving_vs_gain.png")


def sweep_figure(res: dict[str, Any], out: Path) -> str:
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for r in res["rows"]:
        label = "baseline" if r["mode"] == "baseline" else f"st {r['lam_st']:g} d {r['lam_d']:g}"
        ax.scatter(r["velocity_mae"], r["power_est"], color=MODE_COLOURS.get(r["mode"]), s=18)
        ax.annotate(f"{label} @{r['v_ref']:g}", (r["velocity_mae"], r["power_est"]), fontsize=6)
    ax.axvline(TRACKING_MAE, color="0.6", ls="--", lw=0.8)  # savings are quoted left of it only
    ax.set_xlabel("velocity MAE (m/s)")
    ax.set_ylabel("mean mechanical power (W)")
    return _save(fig, out / "sweep_power_vs_error.png")
