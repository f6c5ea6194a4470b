"""What E7's plants do open loop, stated before any closed-loop run (docs/experiments/e7-declaration.md).

For each plant and hull speed V, the fin rig's efficiency curve (``backend.fin_rig.curve``:
``eta = T V / P`` against the per-fin Strouhal number ``St = w L_f / (2 V)``, its peak and
the St range that can make the hull's thrust) over :data:`E7_SPEEDS`.

The plant parameters are frozen by a hash: SHA-256 of the JSON of every plant's full
configuration (``typedconf.to_dict``), :func:`plant_hash`, which the E7 report prints.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

from ucat_console.backend.fin_rig import CORRIDOR, ST_GRID, curve
from ucat_console.backend.sim.variants import e7_plants, plant_config
from ucat_console.typedconf import to_dict

#: E7's speeds (m/s)
E7_SPEEDS = (0.1, 0.2, 0.3, 0.4)


def plant_hash(plants: list[str]) -> str:
    """SHA-256 (hex, first 16 digits) of the plants' frozen configurations."""
    doc = {p: to_dict(plant_config(p, 0)) for p in plants}
    text = json.dumps(doc, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


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
