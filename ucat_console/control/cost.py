"""Strouhal number, efficiency surrogate and the MPC cost (control.md sections 2-3).

Vectorised numpy over any number of candidate plans ``u = [d_1, d_2, w_1, w_2]``
(shape ``(..., 4)``). This is the readable reference that the scipy solver uses and that
the compiled kernels in :mod:`ucat_console.control.mpc_kernels` are tested against.

Two formulations (``MpcConfig.formulation``):

- ``"paper"``: eq 17, ``J = lam_f c_force + lam_St c_St(St) + lam_a c_amp + lam_d c_diff``
  with St the cycle's (eq 10).
- ``"closed_stroke"``: the same force, amplitude and smoothness terms, and

      c_St     = (c_St(St_1) + c_St(St_2)) / 2,   St_k = w_k L_f / (2 max(V_B, v_floor))
      c_close  = |d_1 + d_2|                      (the cycle ends where it started)
      c_energy = sum_k (k_D |d_k| w_k^2 + I w_k^2 / 2) / sum_k dt_k
      J = lam_f c_force + lam_St c_St + lam_a c_amp + lam_d c_diff + lam_c c_close + lam_e c_energy

  St_k is the Strouhal number of a cycle of two strokes like stroke k, so a slow and a fast
  stroke each pay for their own St and cannot average into the corridor (eq 10 averages the
  two durations: a 0.9 rad/s stroke and an 8 rad/s return give a cycle St in the corridor).
  c_energy is the model's mechanical power over the cycle, W: each stroke turns the fin
  through |d_k| at the mean rate w_k, so its drag energy is k_D w_k^3 dt_k = k_D |d_k| w_k^2
  (k_D = 0.5 rho C_D A_f r_c^3, :func:`ucat_console.control.power.drag_coefficient`), and it
  starts from rest and ends at rest, so the drive (which does not regenerate) pays I w_k^2 / 2
  to spin it up and gets nothing back (I = ``fin_inertia``). It is the cycle's energy divided
  by the cycle's duration, not the energy alone: a plan is one cycle of a receding horizon,
  and a short cycle that costs less energy but repeats more often would spend more per
  second and per metre. With the L1 force term the energy term does not trade force for
  power while ``lam_e dP/dF < lam_f`` (dP/dF = 1.5 P/F for F ~ w^2 at a given stroke): it
  chooses among the plans that make the force the most economical one.

  What I is decides what "economical" means. By default it is the blade's own 2.8e-5 kg m2:
  the reversals are then nearly free, the cost does not tell short quick strokes from long
  ones at the same rate, and the plans keep the stroke the solver's seeded samples found
  first (on the simulated robot the short ones cost the battery up to twice as much per
  metre). What the drive really spins up at each stroke is the blade, the water it carries
  and the motor's rotor through the gearhead, ``robot.fin_plate.STROKE_INERTIA`` (0.035 kg
  m2): with it the plans take long strokes whatever the seed (dP/dF at the fastest mean rate
  6.7 W/N for strokes of 0.5 rad, 3.9 W/N for 1 rad, below sim-tuned's lam_f / lam_e of 10),
  and hold the heading less well (docs/findings.md).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.fin_model import ForceTable, bilinear, rotate, stroke_force_body
from ucat_console.control.params import MpcConfig
from ucat_console.control.power import drag_coefficient

H = 2  # strokes per cycle


def strouhal(u: ArrayLike, v_body: float, cfg: MpcConfig) -> NDArray:
    """St = 2 f A / max(V_B, v_floor) with f = H / (2 sum dt) and A = mean |d| L_f / 2."""
    u = np.asarray(u, dtype=float)
    d, w = u[..., :H], u[..., H:]
    dt = np.abs(d) / w
    freq = H / (2.0 * dt.sum(axis=-1))
    amp = (np.abs(d) * cfg.fin_length / 2.0).mean(axis=-1)
    return 2.0 * freq * amp / max(float(v_body), cfg.v_floor)


def stroke_strouhal(w: float, v_body: float, cfg: MpcConfig) -> float:
    """St of one stroke at mean rate ``w``: :func:`strouhal` of a cycle of two such strokes,
    ``w L_f / (2 max(V_B, v_floor))`` (the stroke angle cancels)."""
    return abs(float(w)) * cfg.fin_length / (2.0 * max(float(v_body), cfg.v_floor))


def stroke_strouhals(u: ArrayLike, v_body: float, cfg: MpcConfig) -> NDArray:
    """St_k of each stroke, shape (..., H): :func:`stroke_strouhal` of its mean rate."""
    w = np.asarray(u, dtype=float)[..., H:]
    return np.abs(w) * cfg.fin_length / (2.0 * max(float(v_body), cfg.v_floor))


def cycle_power(u: ArrayLike, cfg: MpcConfig) -> NDArray:
    """The model's mean mechanical power (W) of cycles ``u``: drag and inertia (module docstring)."""
    u = np.asarray(u, dtype=float)
    a, w = np.abs(u[..., :H]), u[..., H:]
    energy = (drag_coefficient(cfg) * a * w**2 + 0.5 * cfg.fin_inertia * w**2).sum(axis=-1)
    return energy / (a / w).sum(axis=-1)


def eta_hat(st: ArrayLike, cfg: MpcConfig) -> NDArray:
    """Efficiency surrogate eta_max (St/St_opt) exp(1 - St/St_opt) (eq 11)."""
    x = np.asarray(st, dtype=float) / cfg.st_opt
    return cfg.eta_max * x * np.exp(1.0 - x)


def strouhal_penalty(st: ArrayLike, cfg: MpcConfig) -> NDArray:
    """c_St = max(0, eta_max - eta_hat(St)) (eq 12)."""
    return np.maximum(0.0, cfg.eta_max - eta_hat(st, cfg))


class CostBreakdown(NamedTuple):
    """J and its unweighted terms for one plan (what the console shows). A typed named
    tuple, not a dataclass: one is built for every solve, and a tuple is built four times
    faster (a frozen dataclass sets each field through ``object.__setattr__``)."""

    total: float
    force: float  # c_force, N (1-norm)
    strouhal_penalty: float  # c_St
    amplitude: float  # c_amp, m
    smoothness: float  # c_diff
    st: float  # the cycle's St (eq 10), in both formulations
    mean_force: tuple[float, float]  # (f_bar_x, f_bar_y), N, body frame
    closure: float = 0.0  # c_close, rad (closed_stroke; 0 for the paper's cost)
    energy: float = 0.0  # c_energy, W (closed_stroke; 0 for the paper's cost)


def mean_force(
    u: ArrayLike, theta0: float, cfg: MpcConfig, table: ForceTable | None = None
) -> tuple[NDArray, NDArray]:
    """Time-weighted cycle-mean body force f_bar (eq 13) of plans u from angle theta0.

    With ``table`` the stroke-frame force is read from the table (the solver's table
    model); otherwise eqs 3-8 are evaluated directly.
    """
    u = np.asarray(u, dtype=float)
    d, w = u[..., :H], u[..., H:]
    theta_start = theta0 + np.concatenate([np.zeros_like(d[..., :1]), np.cumsum(d, -1)[..., :-1]], -1)
    if table is None:
        fx, fy = stroke_force_body(theta_start, d, w, cfg)
    else:
        gx_tab, gy_tab = table.stroke_frame()
        gx, gy = bilinear(table.d, table.w, gx_tab, gy_tab, d, w)
        fx, fy = rotate(theta_start, gx, gy)
    dt = np.abs(d) / w
    weights = dt / dt.sum(axis=-1, keepdims=True)
    return (weights * fx).sum(axis=-1), (weights * fy).sum(axis=-1)


def timed_rates(u: ArrayLike, cfg: MpcConfig, drive: tuple[float, float]) -> NDArray:
    """Plans ``u`` with each rate at most what a drive of (acceleration, largest rate) makes
    of its stroke (``control.stroke_timing.mean_rate_limit``, at least w_min)."""
    u = np.array(u, dtype=float)
    acc, v_max = drive
    a = np.abs(u[..., :H])
    peak = np.sqrt(acc * a)
    with np.errstate(divide="ignore", invalid="ignore"):
        trapezoid = a / (a / v_max + v_max / acc)
    cap = np.maximum(np.where(peak <= v_max, 0.5 * peak, trapezoid), cfg.w_min)
    u[..., H:] = np.minimum(u[..., H:], cap)
    return u


def cost_terms(
    u: ArrayLike,
    f_target: ArrayLike,
    v_body: float,
    theta0: float,
    u_prev: ArrayLike,
    cfg: MpcConfig,
    table: ForceTable | None = None,
    drive: tuple[float, float] | None = None,
) -> dict[str, NDArray]:
    """Every term of J for plans ``u`` of shape (..., 4) in the configured formulation
    (module docstring; eqs 13-17 for the paper's); with ``drive`` (acceleration, largest
    rate) each rate is first capped at what the drive makes of its stroke (:func:`timed_rates`)."""
    u = np.asarray(u, dtype=float) if drive is None else timed_rates(u, cfg, drive)
    u_prev = np.asarray(u_prev, dtype=float)
    fbx, fby = mean_force(u, theta0, cfg, table)
    c_force = np.abs(fbx - f_target[0]) + np.abs(fby - f_target[1])
    st = strouhal(u, v_body, cfg)
    amp_k = np.abs(u[..., :H]) * cfg.fin_length / 2.0
    c_amp = np.maximum(0.0, cfg.a_min - amp_k).sum(axis=-1)
    c_diff = 0.5 * np.abs(u - u_prev).sum(axis=-1)
    if cfg.formulation == "closed_stroke":
        c_st = strouhal_penalty(stroke_strouhals(u, v_body, cfg), cfg).mean(axis=-1)
        c_close = np.abs(u[..., 0] + u[..., 1])
        c_energy = cycle_power(u, cfg)
    else:
        c_st = strouhal_penalty(st, cfg)
        c_close = c_energy = np.zeros_like(c_force)
    total = (cfg.lam_f * c_force + cfg.lam_st * c_st + cfg.lam_a * c_amp + cfg.lam_d * c_diff
             + cfg.lam_c * c_close + cfg.lam_e * c_energy)
    return {
        "total": total,
        "force": c_force,
        "strouhal_penalty": c_st,
        "amplitude": c_amp,
        "smoothness": c_diff,
        "st": st,
        "fbx": fbx,
        "fby": fby,
        "closure": c_close,
        "energy": c_energy,
    }


def breakdown_from_terms(terms: dict[str, NDArray]) -> CostBreakdown:
    """The breakdown of one plan from :func:`cost_terms` output of shape ()."""
    return CostBreakdown(
        total=float(terms["total"]),
        force=float(terms["force"]),
        strouhal_penalty=float(terms["strouhal_penalty"]),
        amplitude=float(terms["amplitude"]),
        smoothness=float(terms["smoothness"]),
        st=float(terms["st"]),
        mean_force=(float(terms["fbx"]), float(terms["fby"])),
        closure=float(terms["closure"]),
        energy=float(terms["energy"]),
    )
