"""Strouhal number, efficiency surrogate and the MPC cost (control.md sections 2-3).

Vectorised numpy over any number of candidate plans ``u = [d_1, d_2, w_1, w_2]``
(shape ``(..., 4)``). This is the readable reference that the scipy solver uses and that
the compiled kernels in :mod:`ucat_console.control.mpc_kernels` are tested against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.fin_model import ForceTable, bilinear, rotate, stroke_force_body
from ucat_console.control.params import MpcConfig

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


def eta_hat(st: ArrayLike, cfg: MpcConfig) -> NDArray:
    """Efficiency surrogate eta_max (St/St_opt) exp(1 - St/St_opt) (eq 11)."""
    x = np.asarray(st, dtype=float) / cfg.st_opt
    return cfg.eta_max * x * np.exp(1.0 - x)


def strouhal_penalty(st: ArrayLike, cfg: MpcConfig) -> NDArray:
    """c_St = max(0, eta_max - eta_hat(St)) (eq 12)."""
    return np.maximum(0.0, cfg.eta_max - eta_hat(st, cfg))


@dataclass(frozen=True)
class CostBreakdown:
    """J and its unweighted terms for one plan (what the console shows)."""

    total: float
    force: float  # c_force, N (1-norm)
    strouhal_penalty: float  # c_St
    amplitude: float  # c_amp, m
    smoothness: float  # c_diff
    st: float
    mean_force: tuple[float, float]  # (f_bar_x, f_bar_y), N, body frame


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


def cost_terms(
    u: ArrayLike,
    f_target: ArrayLike,
    v_body: float,
    theta0: float,
    u_prev: ArrayLike,
    cfg: MpcConfig,
    table: ForceTable | None = None,
) -> dict[str, NDArray]:
    """Every term of J (eqs 13-17) for plans ``u`` of shape (..., 4)."""
    u = np.asarray(u, dtype=float)
    u_prev = np.asarray(u_prev, dtype=float)
    fbx, fby = mean_force(u, theta0, cfg, table)
    c_force = np.abs(fbx - f_target[0]) + np.abs(fby - f_target[1])
    st = strouhal(u, v_body, cfg)
    c_st = strouhal_penalty(st, cfg)
    amp_k = np.abs(u[..., :H]) * cfg.fin_length / 2.0
    c_amp = np.maximum(0.0, cfg.a_min - amp_k).sum(axis=-1)
    c_diff = 0.5 * np.abs(u - u_prev).sum(axis=-1)
    total = cfg.lam_f * c_force + cfg.lam_st * c_st + cfg.lam_a * c_amp + cfg.lam_d * c_diff
    return {
        "total": total,
        "force": c_force,
        "strouhal_penalty": c_st,
        "amplitude": c_amp,
        "smoothness": c_diff,
        "st": st,
        "fbx": fbx,
        "fby": fby,
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
    )
