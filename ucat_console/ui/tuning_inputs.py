"""The live-tuning inputs' specifications: which parameters, labelled and stepped how.

The parameters are the tunable fields of the loop's registered blocks
(``backend.loop.blocks``, read at each call); each is built from the typed configuration's
field metadata (``typedconf.param``): the label shows the allowed range, the hint the field's
description, and a choice field is a dropdown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from ucat_console.backend.loop import blocks as tunable
from ucat_console.typedconf import choices_of, describe_range


def step_for(value: float, is_int: bool) -> float:
    """An input step of about a tenth of the value's magnitude (1 at least for integers)."""
    if value == 0 or not math.isfinite(value):
        return 1.0 if is_int else 0.01
    step = 10.0 ** math.floor(math.log10(abs(value))) / 10.0
    return max(1.0, step) if is_int else step


@dataclass(frozen=True)
class ParamSpec:
    """One tunable parameter as an input shows it."""

    key: str  # "mpc.lam_st", "pid.depth.kp"
    label: str
    hint: str
    step: float
    is_int: bool
    choices: tuple[str, ...] | None = None  # a choice field: a dropdown, not a number


def param_specs(tuning: dict[str, Any]) -> dict[str, list[ParamSpec]]:
    """Block -> input specs, from the typed configuration's field metadata, for each
    registered block in ``tuning`` (block -> its config), in the registry's order."""
    out: dict[str, list[ParamSpec]] = {}
    for block in tunable.block_names():
        if block not in tuning:
            continue
        entry = tunable.block(block)
        cfg = tuning[block]
        by_name = {f.name: f for f in fields(cfg)}
        specs = []
        for name in entry.fields:
            f = by_name[name]
            value = getattr(cfg, name)
            allowed = choices_of(f)
            if allowed is not None:  # e.g. mpc.formulation
                specs.append(ParamSpec(f"{block}.{name}", name, f.metadata.get("doc", ""), 0.0, False, allowed))
                continue

            is_int = isinstance(value, int)
            label = f"{entry.label}{name} {describe_range(f)}"
            doc = f.metadata.get("doc", "")
            hint = f"{doc} (allowed {describe_range(f)})"
            specs.append(ParamSpec(f"{block}.{name}", label, hint, step_for(value, is_int), is_int))
        out[block] = specs
    return out
