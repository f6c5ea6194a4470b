"""Counterfactual replay: a recorded session's planner inputs through the MPC with other
weights, side by side with what was recorded.

Each recorded :class:`~ucat_console.telemetry.messages.FinPlan` holds every input of the
planner (target force, measured forward speed, start angle, previous plan). For each one,
``FinMpc(config).plan(target, v_body, theta0, u_prev, seed=seed)`` is run with the
session's MPC configuration (the ``[loop.mpc]`` table of its recorded configuration, an older
recording's ``[mpc]``, then its
recorded weights) changed by the requested weights, and the drives' timing the session's
planners used (:func:`recorded_drive`). The recorded start angle is the fin's
measured angle, which winds up over whole turns in a long session; like the live planner
(:class:`~ucat_console.backend.loop.planners.MpcFinPlanner`), the replay plans from it
wrapped to (-pi, pi], so a plan is made from the same inputs as it was live.

Predicted mechanical power of a plan ``u = [d_1, d_2, w_1, w_2]``: each stroke k turns the
fin through ``|d_k|`` at the mean rate ``w_k`` for ``dt_k = |d_k| / w_k``; its drag power at
that rate is ``P_k = 0.5 rho C_D A_f (r_c w_k)^3``
(:func:`ucat_console.control.power.drag_power`), and the plan's power is the
duration-weighted mean ``sum(P_k dt_k) / sum(dt_k)``. It leaves out inertia (which the
motors pay back and forth) and assumes the planned mean rate throughout a stroke; the same
formula is applied to the recorded plan, so the two columns compare like with like.
"""

from __future__ import annotations

import logging
import math
import statistics
import tomllib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ucat_console.backend.sessions.reader import SessionSource
from ucat_console.control import FinMpc, MpcConfig
from ucat_console.control.params import ExecutorConfig
from ucat_console.control.baseline import wrap_angle
from ucat_console.control.power import drag_power
from ucat_console.telemetry.channels import N_FINS, fin_plan
from ucat_console.telemetry.messages import FinPlan

log = logging.getLogger(__name__)

#: the weights a replay may change (MpcConfig fields)
WEIGHT_NAMES = ("lam_f", "lam_st", "lam_a", "lam_d")


def parse_weights(text: str) -> dict[str, float]:
    """``"lam_st=2.0,lam_f=1.5"`` -> ``{"lam_st": 2.0, "lam_f": 1.5}``.

    Unknown names, repeated names, missing or non-finite values raise ValueError naming
    the key; ranges are checked when the configuration is built (:func:`replay_config`).
    """
    out: dict[str, float] = {}
    if not isinstance(text, str):
        raise ValueError(f"weights: expected text like 'lam_st=2.0,lam_f=1.5', got {text!r}")
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep:
            raise ValueError(f"weights: {item!r} is not name=value")
        if key not in WEIGHT_NAMES:
            raise ValueError(f"{key}: unknown weight; known: {', '.join(WEIGHT_NAMES)}")
        if key in out:
            raise ValueError(f"{key}: given twice")
        try:
            v = float(value)
        except ValueError:
            raise ValueError(f"{key}: {value.strip()!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{key}: {value.strip()!r} is not finite")
        out[key] = v
    return out


def _recorded_doc(reader: SessionSource) -> dict:
    text = reader.config_toml
    if not text.strip():
        return {}
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{reader.path}: recorded configuration is not valid TOML: {e}") from None


def _recorded_block(doc: dict, name: str) -> tuple[Any, str]:
    """The recorded controller block ``name`` and its dotted key: the loop's table
    (``[loop.mpc]``), or an older recording's top-level one (``[mpc]``, ``config.migrate_loop_blocks``)."""
    loop = doc.get("loop")
    if isinstance(loop, dict) and name in loop:
        return loop[name], f"loop.{name}"
    return doc.get(name), name


def recorded_drive(reader: SessionSource) -> ExecutorConfig | None:
    """The fin drives' timing the session's planners made their plans with: the recorded
    ``[loop.executor]`` table when it has the drives' ``acceleration`` (written by the versions
    whose planners time strokes by the drive), else None (plans as solved)."""
    ex, key = _recorded_block(_recorded_doc(reader), "executor")
    if not isinstance(ex, dict) or "acceleration" not in ex:
        return None
    try:
        return ExecutorConfig.from_dict(ex)
    except ValueError as e:
        raise ValueError(f"{reader.path}: recorded configuration: {key}.{e}") from None


def recorded_config(reader: SessionSource) -> MpcConfig:
    """The MPC configuration in force when the session was recorded (defaults for what
    the file does not say; of a split session, its first part's)."""
    cfg = MpcConfig()
    mpc, key = _recorded_block(_recorded_doc(reader), "mpc")
    if isinstance(mpc, dict):
        try:
            cfg = MpcConfig.from_dict(mpc)
        except ValueError as e:
            raise ValueError(f"{reader.path}: recorded configuration: {key}.{e}") from None
    recorded = {k: v for k, v in reader.weights.items() if k in WEIGHT_NAMES}
    return cfg.replace(**recorded) if recorded else cfg


def replay_config(base: MpcConfig, weights: Mapping[str, float]) -> MpcConfig:
    for k in weights:
        if k not in WEIGHT_NAMES:
            raise ValueError(f"{k}: unknown weight; known: {', '.join(WEIGHT_NAMES)}")
    return base.replace(**dict(weights))


def predicted_power(u: Sequence[float], cfg: MpcConfig) -> float:
    """Duration-weighted mean drag power (W) of plan ``u = [d_1, d_2, w_1, w_2]``."""
    d = np.abs(np.asarray(u[:2], dtype=float))
    w = np.asarray(u[2:], dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero rate: NaN, not a warning
        dt = d / w
        return float(np.sum(drag_power(w, cfg) * dt) / np.sum(dt))


@dataclass(frozen=True)
class ReplayRow:
    t: float
    fin: int
    mode: str
    recorded_u: tuple[float, float, float, float]
    recorded_st: float
    recorded_force_error: float  # c_force, N
    recorded_cost: float
    recorded_power: float  # W, predicted from the recorded plan
    u: tuple[float, float, float, float]
    st: float
    force_error: float
    cost: float
    power: float


@dataclass(frozen=True)
class ReplayResult:
    config: MpcConfig
    rows: tuple[ReplayRow, ...]
    skipped: int  # recorded plans the planner refused (their inputs are in the log)

    def summary(self) -> list[dict[str, float | int | str]]:
        """Means per fin (in fin order) and over all fins."""
        groups: dict[str, list[ReplayRow]] = {}
        for r in sorted(self.rows, key=lambda r: r.fin):
            groups.setdefault(str(r.fin), []).append(r)
        if self.rows:
            groups["all"] = list(self.rows)
        out: list[dict[str, float | int | str]] = []
        for name, rows in groups.items():
            out.append({
                "fin": name,
                "plans": len(rows),
                "recorded_st": statistics.fmean(r.recorded_st for r in rows),
                "st": statistics.fmean(r.st for r in rows),
                "recorded_force_error": statistics.fmean(r.recorded_force_error for r in rows),
                "force_error": statistics.fmean(r.force_error for r in rows),
                "recorded_power": statistics.fmean(r.recorded_power for r in rows),
                "power": statistics.fmean(r.power for r in rows),
            })
        return out


SeedRule = int | None | Callable[[FinPlan, int], int | None]


def recorded_seed(plan: FinPlan, index: int) -> int | None:
    """The seed the live planner used for this plan (None when it recorded none)."""
    return plan.seed if plan.seed >= 0 else None


def counterfactual(
    reader: SessionSource,
    weights: Mapping[str, float],
    *,
    seed: SeedRule = recorded_seed,
    base: MpcConfig | None = None,
    fins: Iterable[int] | None = None,
    start: float | None = None,
    end: float | None = None,
    progress: Callable[[int], None] | None = None,
) -> ReplayResult:
    """Re-plan every recorded FinPlan with ``weights`` changed (of every part, in time
    order, when ``reader`` is a whole split session).

    ``seed``: one seed for every plan, None (each fin's planner continues its random
    stream), or a function ``(plan, index) -> seed``; by default each plan's recorded seed,
    so the recorded weights reproduce the recorded plans exactly. ``base``: the configuration before
    the change (default: the recorded one). ``progress(n)`` is called after every 50th plan
    (``n`` plans done). Plans the planner refuses are counted in ``skipped`` and summarised
    in one log line.
    """
    record_cfg = base if base is not None else recorded_config(reader)
    cfg = replay_config(record_cfg, weights)
    fin_set = set(range(N_FINS) if fins is None else fins)
    for f in fin_set:
        if not 0 <= f < N_FINS:
            raise ValueError(f"fins: {f} is not a fin index (0-{N_FINS - 1})")
    drive = recorded_drive(reader)
    planners = {f: FinMpc(cfg, drive=drive) for f in fin_set}
    channels = [fin_plan(f) for f in sorted(fin_set)]
    rows: list[ReplayRow] = []
    skipped = 0
    first_refusal = ""
    for i, (_, msg) in enumerate(reader.messages(channels, start, end)):
        if progress is not None and i and i % 50 == 0:
            progress(i)
        s = seed(msg, i) if callable(seed) else seed
        try:
            plan = planners[msg.fin].plan(msg.target, msg.v_body, wrap_angle(msg.theta0), msg.u_prev, seed=s,
                                          duration=msg.align)
        except (ValueError, FloatingPointError) as e:
            skipped += 1
            first_refusal = first_refusal or f"fin {msg.fin} at t={msg.t:.3f}: {e}"
            continue
        rec_power = predicted_power(msg.u, record_cfg)
        rows.append(ReplayRow(
            t=msg.t, fin=msg.fin, mode=msg.mode, recorded_u=msg.u,
            recorded_st=msg.st, recorded_force_error=msg.cost_force,
            recorded_cost=msg.cost_total, recorded_power=rec_power,
            u=plan.u, st=plan.cost.st, force_error=plan.cost.force, cost=plan.cost.total,
            power=predicted_power(plan.u, cfg),
        ))
    if skipped:
        log.warning("%d of %d recorded plans not replayed (the planner refused their inputs); the first: %s",
                    skipped, skipped + len(rows), first_refusal)
    return ReplayResult(cfg, tuple(rows), skipped)
