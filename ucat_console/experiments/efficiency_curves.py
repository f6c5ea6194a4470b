"""What E7's plants do open loop, stated before any closed-loop run (docs/experiments/e7-declaration.md).

For each plant and hull speed V, one fin of the plant (:class:`~ucat_console.experiments.fin_rig.FinRig`)
beats symmetric stroke pairs about the centre that pushes the hull forward
(``scenario.START_FIN_ANGLE``) at amplitudes :data:`AMPLITUDES` and mean rates w. The
experiment (not the plant) labels each beat with its per-fin Strouhal number
``St = w L_f / (2 V)`` (a closed stroke pair) and measures

    efficiency  eta = T V / P,   T = the fin's forward force on the hull, P = its true shaft power;

``eta(St)`` is the best over the amplitudes the servo can make at that rate; its peak is the
emergent efficiency peak. The hull needs ``T_hull(V) = -X_u V - X_uu V^2`` (its surge
damping), so four fins need ``T_hull / 4`` each; the St range "that can make the thrust" is
where some amplitude reaches it.

The plant parameters are frozen by a hash: SHA-256 of the JSON of every plant's full
configuration (``typedconf.to_dict``), :func:`plant_hash`, which the E7 report prints.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

import numpy as np

from ucat_console.backend.sim.params import PlantConfig
from ucat_console.experiments.fin_rig import FinRig
from ucat_console.experiments.scenario import START_FIN_ANGLE, plant_config
from ucat_console.typedconf import to_dict

#: E7's plants: the plate over the profile drag C_D0 and the null plant (the plate as if
#: in still water, the thrust's work paid through the shaft)
E7_CD0 = (0.02, 0.05, 0.3)
NULL_PLANT = "still_water"
#: E7's speeds (m/s)
E7_SPEEDS = (0.1, 0.2, 0.3, 0.4)
#: amplitudes (rad, half the stroke) and per-fin St grid of the open-loop sweep
AMPLITUDES = tuple(round(0.1 + 0.05 * k, 2) for k in range(11))
ST_GRID = tuple(round(0.05 * k, 2) for k in range(1, 21))
#: the paper's St corridor
CORRIDOR = (0.25, 0.35)


def e7_plants() -> list[str]:
    from ucat_console.experiments.scenario import cd0_name

    return [cd0_name(c) for c in E7_CD0] + [NULL_PLANT]


def plant_hash(plants: list[str]) -> str:
    """SHA-256 (hex, first 16 digits) of the plants' frozen configurations."""
    doc = {p: to_dict(plant_config(p, 0)) for p in plants}
    text = json.dumps(doc, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def hull_thrust(plant: PlantConfig, v: float) -> float:
    """The surge force (N) the hull needs to hold ``v`` (its damping)."""
    return -plant.vehicle.x_u * v - plant.vehicle.x_uu * v * v


def curve(plant_name: str, v: float) -> dict[str, Any]:
    """The efficiency-against-St curve of ``plant_name`` at ``v`` (module docstring)."""
    plant = plant_config(plant_name, 0)
    rig = FinRig(plant)
    l_f = plant.hydro.resolved().fin_length
    need = hull_thrust(plant, v) / 4.0
    eta, amp, feasible = [], [], []
    for st in ST_GRID:
        w = st * 2.0 * v / l_f
        best, best_a, ok = math.nan, math.nan, False
        for a in AMPLITUDES:
            if w > rig.mean_rate_limit(2.0 * a):
                continue
            m = rig.cycle(v, START_FIN_ANGLE, a, w)
            t = m.thrust(rig.cos_mount)
            ok = ok or t >= need
            if t > 0.0 and m.power > 0.0 and not (t * v / m.power <= best):
                best, best_a = t * v / m.power, a
        eta.append(best)
        amp.append(best_a)
        feasible.append(ok)
    e = np.asarray(eta)
    i = int(np.nanargmax(e)) if np.any(np.isfinite(e)) else -1
    sts = [s for s, ok in zip(ST_GRID, feasible) if ok]
    return {"plant": plant_name, "v": v, "st": list(ST_GRID), "eta": eta, "amplitude": amp,
            "feasible": feasible, "thrust_needed_per_fin": need,
            "peak_st": ST_GRID[i] if i >= 0 else math.nan, "peak_eta": float(e[i]) if i >= 0 else math.nan,
            "feasible_st": [min(sts), max(sts)] if sts else None}


def peak_in_corridor(curves: list[dict[str, Any]], plant_name: str) -> bool:
    """Whether the plant's peak lies in the corridor at every speed (the declaration's split)."""
    return all(CORRIDOR[0] <= c["peak_st"] <= CORRIDOR[1] for c in curves if c["plant"] == plant_name)


def all_curves(plants: list[str] | None = None, speeds: tuple[float, ...] = E7_SPEEDS) -> list[dict[str, Any]]:
    return [curve(p, v) for p in (plants or e7_plants()) for v in speeds]


def curves_markdown(curves: list[dict[str, Any]]) -> str:
    """The declaration's tables: each curve's eta over the St grid, its peak and feasible range."""
    head = "| plant | v (m/s) | " + " | ".join(f"{s:.2f}" for s in ST_GRID) + " |\n"
    head += "|---|---|" + "---|" * len(ST_GRID) + "\n"
    rows = []
    for c in curves:
        cells = []
        for e, ok in zip(c["eta"], c["feasible"]):
            cells.append("-" if math.isnan(e) else f"{e:.2f}{'*' if ok else ''}")
        rows.append(f"| {c['plant']} | {c['v']:g} | " + " | ".join(cells) + " |\n")
    summary = "| plant | v (m/s) | peak St | peak eta | per-fin St that makes the thrust | thrust per fin (N) |\n"
    summary += "|---|---|---|---|---|---|\n"
    for c in curves:
        f = c["feasible_st"]
        summary += (f"| {c['plant']} | {c['v']:g} | {c['peak_st']:.2f} | {c['peak_eta']:.3f} | "
                    f"{'none' if not f else f'{f[0]:.2f}-{f[1]:.2f}'} | {c['thrust_needed_per_fin']:.3f} |\n")
    return summary + "\n" + head + "".join(rows)
