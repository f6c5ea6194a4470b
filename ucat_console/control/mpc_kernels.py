# Over 600 lines: both cost formulations, their analytic gradients, the sampler and the quasi-Newton solver compile together as one planner.
"""Compiled MPC kernels: cost with analytic gradient, sampler, bounded quasi-Newton.

Everything here is numba ``njit(cache=True)`` and allocation-free: the caller owns every
work array (see :class:`ucat_console.control.mpc.FinMpc`). One call of :func:`plan_kernel`
solves one fin's problem: stage 1 draws ``n`` admissible stroke pairs and keeps the best
``k`` as warm starts; stage 2 refines each with a projected BFGS method on the
sign-constrained box (each stroke keeps the sign of its warm start) and returns the best
point found, never worse than the best sample.

The cost uses the stroke-frame force g(d, w) = R(d/2) f^l(d, w) (see fin_model), so that
f_1 = R(theta0) g(d_1, w_1) and f_2 = R(theta0) R(d_1) g(d_2, w_2).

Random numbers come from splitmix64 (one uint64 of state), so a plan is reproducible
from its seed on every machine.

No clock is read here: a caller timing the two stages calls :func:`sample_kernel` and
:func:`finish_kernel` (together the same solve as :func:`plan_kernel`) with its own clock
between them. The vectors the solver shares with Python (parameters, problem, terms) and
its refinement rows have declared layouts (:data:`PARAMS`, :data:`PROBLEM`, :data:`TERMS`,
:data:`RUN_ROW`). Over 500 lines because this is one compiled solver whose parts inline into
one another (cost, gradient, sampler, quasi-Newton step); split, it would be one algorithm
spread over files.

The closed-stroke formulation (``control.cost``) is the same solver with the flag
``closed`` (a compile-time constant, like ``table``). Each formulation and force model has
its own entry points (:data:`KERNELS`, made from the two flags), so a configuration
compiles only the solver it runs. Its sampler draws
half of the stroke pairs closed (d_2 = -d_1); a closed warm start is refined on the closed
subspace (the gradient projected onto d_2 = -d_1, every trial point kept on it), so a plan
that closes comes back closed exactly; the other warm starts are refined freely and pay
``lam_c |d_1 + d_2|``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from ucat_console.control.params import FORCE_MODELS, FORMULATIONS, MpcConfig
from ucat_console.control.power import drag_coefficient
from ucat_console.robot.layout import Layout

# --- the declared layouts of the solver's vectors, and their columns as constants -------
PARAMS = Layout("the MPC's constant parameter vector", [
    ("lam_f", 1, "weight of the force error"), ("lam_st", 1, "weight of the Strouhal penalty"),
    ("lam_a", 1, "weight of the amplitude penalty"), ("lam_d", 1, "weight of the smoothness penalty"),
    ("q", 1, "0.5 rho A_f r_c^2"), ("c_l", 1, "lift coefficient"), ("c_d", 1, "drag coefficient"),
    ("l_f", 1, "fin length, m"),
    ("st_opt", 1, "optimal Strouhal number"), ("eta_max", 1, "surrogate scale"), ("v_floor", 1, "speed floor, m/s"),
    ("a_min", 1, "amplitude penalty threshold, m"),
    ("d_eps", 1, "shortest stroke, rad"), ("d_max", 1, "stroke limit, rad"), ("w_min", 1, "slowest mean rate"),
    ("w_max", 1, "fastest mean rate"),
    ("td0", 1, "force table: first d"), ("thd", 1, "its d step"), ("tw0", 1, "first w"), ("thw", 1, "its w step"),
    ("mode", 1, "force model (MODE_ANALYTIC, MODE_TABLE)"),
    ("lam_c", 1, "closed_stroke: weight of the opening"), ("lam_e", 1, "closed_stroke: weight of the energy"),
    ("kd", 1, "the drag coefficient of the energy term"), ("inertia", 1, "fin inertia, kg m2"),
    ("screen", 1, "the refinement: iterations every kept sample gets"), ("keep", 1, "and how many go on"),
    ("acc", 1, "the drives' acceleration (0: rates as planned)"), ("vmax", 1, "and largest rate"),
])
P_LAM_F, P_LAM_ST, P_LAM_A, P_LAM_D, P_Q, P_CL, P_CD, P_LF = (PARAMS.at(f) for f in PARAMS.fields[:8])
P_ST_OPT, P_ETA_MAX, P_VFLOOR, P_AMIN, P_DEPS, P_DMAX, P_WMIN, P_WMAX = (PARAMS.at(f) for f in PARAMS.fields[8:16])
P_TD0, P_THD, P_TW0, P_THW, P_MODE = (PARAMS.at(f) for f in PARAMS.fields[16:21])
P_LAM_C, P_LAM_E, P_KD, P_INERTIA, P_SCREEN, P_KEEP, P_ACC, P_VMAX = (PARAMS.at(f) for f in PARAMS.fields[21:])
N_PARAMS = PARAMS.size
MODE_ANALYTIC, MODE_TABLE = 0.0, 1.0

PROBLEM = Layout("the MPC's per-solve problem vector", [
    ("fx", 1, "force target f_x*, N"), ("fy", 1, "force target f_y*, N"), ("v", 1, "forward speed, m/s"),
    ("c0", 1, "cos theta0"), ("s0", 1, "sin theta0"), ("u_prev", 4, "the previous plan"),
])
Q_FX, Q_FY, Q_V, Q_C0, Q_S0, Q_PREV = (PROBLEM.at(f) for f in PROBLEM.fields)
N_PROBLEM = PROBLEM.size

TERMS = Layout("the MPC's cost terms output", [
    ("total", 1, "J"), ("force", 1, "force error"), ("st_pen", 1, "Strouhal penalty"), ("amp", 1, "amplitude penalty"),
    ("diff", 1, "smoothness penalty"), ("st", 1, "Strouhal number"), ("fbx", 1, "mean force x"),
    ("fby", 1, "mean force y"), ("close", 1, "opening |d_1 + d_2|"), ("energy", 1, "energy per second"),
])
T_TOTAL, T_FORCE, T_ST_PEN, T_AMP, T_DIFF, T_ST, T_FBX, T_FBY, T_CLOSE, T_ENERGY = (TERMS.at(f) for f in TERMS.fields)
N_TERMS = TERMS.size


def pack_params(cfg: MpcConfig, table_axes: tuple[float, float, float, float] | None,
                drive: tuple[float, float] | None = None) -> tuple:
    """The constant parameter vector of one MPC configuration; ``drive`` (acceleration,
    largest rate) caps each stroke's rate at what the drive makes of it (None: no cap).

    Parameters travel as tuples, not arrays: compiled code then knows no store can
    change them, which lets the sampler's loop be vectorised."""
    p = np.zeros(N_PARAMS)
    p[P_LAM_F], p[P_LAM_ST], p[P_LAM_A], p[P_LAM_D] = cfg.weights
    p[P_Q] = 0.5 * cfg.rho * cfg.fin_area * cfg.r_c**2
    p[P_CL], p[P_CD], p[P_LF] = cfg.c_l, cfg.c_d, cfg.fin_length
    p[P_ST_OPT], p[P_ETA_MAX], p[P_VFLOOR], p[P_AMIN] = cfg.st_opt, cfg.eta_max, cfg.v_floor, cfg.a_min
    p[P_DEPS], p[P_DMAX], p[P_WMIN], p[P_WMAX] = cfg.d_eps, cfg.d_max, cfg.w_min, cfg.w_max
    p[P_LAM_C], p[P_LAM_E] = cfg.lam_c, cfg.lam_e
    p[P_KD], p[P_INERTIA] = drag_coefficient(cfg), cfg.fin_inertia
    p[P_SCREEN], p[P_KEEP] = cfg.refine_screen, cfg.refine_keep
    if drive is not None:
        p[P_ACC], p[P_VMAX] = drive
    if table_axes is None:
        p[P_MODE] = MODE_ANALYTIC
    else:
        p[P_TD0], p[P_THD], p[P_TW0], p[P_THW] = table_axes
        p[P_MODE] = MODE_TABLE
    return tuple(p.tolist())


def pack_problem(f_target, v_body: float, theta0: float, u_prev) -> tuple:
    """The per-solve problem vector (a tuple, see :func:`pack_params`)."""
    return (
        float(f_target[0]), float(f_target[1]), float(v_body),
        math.cos(theta0), math.sin(theta0),
        float(u_prev[0]), float(u_prev[1]), float(u_prev[2]), float(u_prev[3]),
    )


_FAST = {"contract", "arcp", "nsz", "afn", "reassoc"}  # no "nnan"/"ninf": inf is a sentinel
_jit = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, inline="always")


# Polynomial sine/cosine and exponential. They are exact to ~1e-15 on the ranges used,
# and unlike libm calls they let the sampler's inner loop run on SIMD lanes.
_COS_C = np.array([(-1.0) ** k / math.factorial(2 * k) for k in range(11)])
_SIN_C = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(11)])
_EXP_C = np.array([1.0 / math.factorial(k) for k in range(13)])
_LN2_HI = 0.693145751953125
_LN2_LO = 1.42860682030941723212e-6


@intrinsic
def _bits_to_float(typingctx, bits):
    """Reinterpret an int64 as a float64 (IEEE-754 bit pattern)."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


@_inline
def sincos(x):
    """(sin x, cos x) for |x| <= pi: Taylor series of the half angle (|x/2| <= pi/2,
    11 terms, truncation below 2e-17) and the double-angle formulas."""
    h = 0.5 * x
    h2 = h * h
    c = _COS_C[10]
    s = _SIN_C[10]
    for k in range(9, -1, -1):
        c = c * h2 + _COS_C[k]
        s = s * h2 + _SIN_C[k]
    s = s * h
    return 2.0 * s * c, c * c - s * s


@_inline
def exp_neg(y):
    """exp(y) for y <= 1 (smaller than 1e-300 returns 0): range reduction by ln 2 and a
    degree-12 Taylor polynomial (relative error ~1e-15)."""
    if y < -690.0:
        y = -690.0
    n = math.floor(y * 1.4426950408889634 + 0.5)
    r = (y - n * _LN2_HI) - n * _LN2_LO
    e = _EXP_C[12]
    for k in range(11, -1, -1):
        e = e * r + _EXP_C[k]
    return e * _bits_to_float((np.int64(n) + np.int64(1023)) << np.int64(52))


@_inline
def _sgn(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@_inline
def rate_cap(p, a):
    """The fastest mean rate of a stroke of ``a`` = |d| rad (``control.stroke_timing``'s
    mean_rate_limit, at least w_min) and its derivative in ``a`` (0 where the floor holds)."""
    acc = p[P_ACC]
    v = p[P_VMAX]
    peak = math.sqrt(acc * a)
    if peak <= v:
        cap = 0.5 * peak
        slope = 0.25 * acc / peak if peak > 0.0 else 0.0
    else:
        t = a / v + v / acc
        cap = a / t
        slope = (v / acc) / (t * t)
    if cap < p[P_WMIN]:
        return p[P_WMIN], 0.0
    return cap, slope


@_inline
def stroke_force(p, gx_tab, gy_tab, d, w, cd, sd, table):
    """Stroke-frame force g and its partial derivatives at (d, w).

    ``cd, sd`` are cos d and sin d (shared with the caller). Returns
    (gx, gy, dgx/dd, dgy/dd, dgx/dw, dgy/dw).
    """
    if not table:
        qw2 = p[P_Q] * w * w
        gx = -qw2 * p[P_CL] * cd
        gy = -qw2 * (p[P_CL] * sd + p[P_CD])
        return gx, gy, qw2 * p[P_CL] * sd, -qw2 * p[P_CL] * cd, 2.0 * gx / w, 2.0 * gy / w
    nd = gx_tab.shape[0]
    nw = gx_tab.shape[1]
    hd = p[P_THD]
    hw = p[P_THW]
    fi = (d - p[P_TD0]) / hd
    fj = (w - p[P_TW0]) / hw
    if fi < 0.0:
        fi = 0.0
    if fi > nd - 1.000001:
        fi = nd - 1.000001
    if fj < 0.0:
        fj = 0.0
    if fj > nw - 1.000001:
        fj = nw - 1.000001
    i = int(fi)
    j = int(fj)
    td = fi - i
    tw = fj - j
    x00 = gx_tab[i, j]
    x10 = gx_tab[i + 1, j]
    x01 = gx_tab[i, j + 1]
    x11 = gx_tab[i + 1, j + 1]
    y00 = gy_tab[i, j]
    y10 = gy_tab[i + 1, j]
    y01 = gy_tab[i, j + 1]
    y11 = gy_tab[i + 1, j + 1]
    gx = (1 - td) * ((1 - tw) * x00 + tw * x01) + td * ((1 - tw) * x10 + tw * x11)
    gy = (1 - td) * ((1 - tw) * y00 + tw * y01) + td * ((1 - tw) * y10 + tw * y11)
    dgx_dd = ((1 - tw) * (x10 - x00) + tw * (x11 - x01)) / hd
    dgy_dd = ((1 - tw) * (y10 - y00) + tw * (y11 - y01)) / hd
    dgx_dw = ((1 - td) * (x01 - x00) + td * (x11 - x10)) / hw
    dgy_dw = ((1 - td) * (y01 - y00) + td * (y11 - y10)) / hw
    return gx, gy, dgx_dd, dgy_dd, dgx_dw, dgy_dw


@_jit
def closed_terms(p, kst, d1, d2, w1, w2, inv_t, want_grad):
    """The closed-stroke formulation's own terms: (c_St per stroke, c_close, c_energy, and
    their weighted gradient dJ/dd1, dJ/dd2, dJ/dw1, dJ/dw2; zero unless ``want_grad``).

    Compiled on its own rather than inlined: numba inlines before it prunes the dead
    ``closed`` branch, so inlined code would be typed and compiled into every one of the
    paper's kernels as well, lengthening their first compile."""
    # per stroke: St_k = kst w_k, c_St = (c(St_1) + c(St_2)) / 2
    x1 = kst * w1 / p[P_ST_OPT]
    x2 = kst * w2 / p[P_ST_OPT]
    ex1 = exp_neg(1.0 - x1)
    ex2 = exp_neg(1.0 - x2)
    c1 = p[P_ETA_MAX] - p[P_ETA_MAX] * x1 * ex1
    c2 = p[P_ETA_MAX] - p[P_ETA_MAX] * x2 * ex2
    c_st = 0.5 * (max(c1, 0.0) + max(c2, 0.0))
    # the opening of the cycle, and the model's mean mechanical power (drag, inertia)
    opening = d1 + d2
    a1 = abs(d1)
    a2 = abs(d2)
    kd = p[P_KD]
    half_i = 0.5 * p[P_INERTIA]
    c_energy = (kd * (a1 * w1 * w1 + a2 * w2 * w2) + half_i * (w1 * w1 + w2 * w2)) * inv_t
    if not want_grad:
        return c_st, abs(opening), c_energy, 0.0, 0.0, 0.0, 0.0
    # dc(St_k)/dw_k = -eta_max e^{1-x_k} (1 - x_k) kst / St_opt, halved
    kk = -0.5 * p[P_LAM_ST] * p[P_ETA_MAX] * kst / p[P_ST_OPT]
    g_w1 = kk * ex1 * (1.0 - x1) if c1 > 0.0 else 0.0
    g_w2 = kk * ex2 * (1.0 - x2) if c2 > 0.0 else 0.0
    lc = p[P_LAM_C] * _sgn(opening)
    # P = E / T: dP = (dE - P dT) / T, with dT/dd_k = sgn(d_k) / w_k, dT/dw_k = -|d_k| / w_k^2
    le = p[P_LAM_E] * inv_t
    g_d1 = lc + le * (kd * _sgn(d1) * w1 * w1 - c_energy * _sgn(d1) / w1)
    g_d2 = lc + le * (kd * _sgn(d2) * w2 * w2 - c_energy * _sgn(d2) / w2)
    g_w1 += le * (2.0 * kd * a1 * w1 + 2.0 * half_i * w1 + c_energy * a1 / (w1 * w1))
    g_w2 += le * (2.0 * kd * a2 * w2 + 2.0 * half_i * w2 + c_energy * a2 / (w2 * w2))
    return c_st, abs(opening), c_energy, g_d1, g_d2, g_w1, g_w2


@_inline
def cost_eval(p, q, gx_tab, gy_tab, d1, d2, w1, w2, want_grad, table, closed):
    """J at u = (d1, d2, w1, w2) as a tuple of scalars: (J, c_force, c_St, c_amp,
    c_diff, St, f_bar_x, f_bar_y, c_close, c_energy, dJ/dd1, dJ/dd2, dJ/dw1, dJ/dw2);
    the gradient is zero unless ``want_grad``; ``table`` selects the tabulated force
    model, ``closed`` the closed-stroke formulation (c_close and c_energy are 0 without
    it). Inlined, so constant flags remove the code they switch off, and unused terms
    cost nothing."""
    a1 = abs(d1)
    a2 = abs(d2)
    s1 = _sgn(d1)
    s2 = _sgn(d2)
    # the drive's timing: a rate above what it makes of the stroke is that rate
    capped1 = capped2 = False
    slope1 = slope2 = 0.0
    if p[P_ACC] > 0.0:
        cap1, slope1 = rate_cap(p, a1)
        cap2, slope2 = rate_cap(p, a2)
        if w1 > cap1:
            w1 = cap1
            capped1 = True
        if w2 > cap2:
            w2 = cap2
            capped2 = True
    sn1, c1 = sincos(d1)
    sn2, c2 = sincos(d2)
    g1x, g1y, g1x_d, g1y_d, g1x_w, g1y_w = stroke_force(p, gx_tab, gy_tab, d1, w1, c1, sn1, table)
    g2x, g2y, g2x_d, g2y_d, g2x_w, g2y_w = stroke_force(p, gx_tab, gy_tab, d2, w2, c2, sn2, table)
    # second stroke rotated by the first: h2 = R(d1) g2
    h2x = c1 * g2x - sn1 * g2y
    h2y = sn1 * g2x + c1 * g2y
    dt1 = a1 / w1
    dt2 = a2 / w2
    T = dt1 + dt2
    inv_t = 1.0 / T
    mx = (dt1 * g1x + dt2 * h2x) * inv_t
    my = (dt1 * g1y + dt2 * h2y) * inv_t
    c0 = q[Q_C0]
    s0 = q[Q_S0]
    fbx = c0 * mx - s0 * my
    fby = s0 * mx + c0 * my
    ex = fbx - q[Q_FX]
    ey = fby - q[Q_FY]
    c_force = abs(ex) + abs(ey)
    # Strouhal number: St = (a1 + a2) L_f / (2 T V)
    v = q[Q_V]
    if v < p[P_VFLOOR]:
        v = p[P_VFLOOR]
    kst = p[P_LF] / (2.0 * v)
    ssum = a1 + a2
    st = kst * ssum * inv_t
    if closed:
        c_st, c_close, c_energy, k_d1, k_d2, k_w1, k_w2 = closed_terms(
            p, kst, d1, d2, w1, w2, inv_t, want_grad)
        st_active = False
        x = ex1 = 0.0
    else:
        c_close = c_energy = k_d1 = k_d2 = k_w1 = k_w2 = 0.0
        x = st / p[P_ST_OPT]
        ex1 = exp_neg(1.0 - x)
        eta = p[P_ETA_MAX] * x * ex1
        c_st = p[P_ETA_MAX] - eta
        st_active = c_st > 0.0
        if not st_active:
            c_st = 0.0
    half_l = 0.5 * p[P_LF]
    m1 = p[P_AMIN] - a1 * half_l
    m2 = p[P_AMIN] - a2 * half_l
    c_amp = 0.0
    if m1 > 0.0:
        c_amp += m1
    if m2 > 0.0:
        c_amp += m2
    e_d1 = d1 - q[Q_PREV]
    e_d2 = d2 - q[Q_PREV + 1]
    e_w1 = w1 - q[Q_PREV + 2]
    e_w2 = w2 - q[Q_PREV + 3]
    c_diff = 0.5 * (abs(e_d1) + abs(e_d2) + abs(e_w1) + abs(e_w2))
    lam_f = p[P_LAM_F]
    lam_st = p[P_LAM_ST]
    lam_a = p[P_LAM_A]
    lam_d = p[P_LAM_D]
    total = lam_f * c_force + lam_st * c_st + lam_a * c_amp + lam_d * c_diff
    if closed:
        total += p[P_LAM_C] * c_close + p[P_LAM_E] * c_energy
    if not want_grad:
        return total, c_force, c_st, c_amp, c_diff, st, fbx, fby, c_close, c_energy, 0.0, 0.0, 0.0, 0.0
    # --- gradient (sub-gradient at kinks: sign(0) = 0) ---------------------------------
    sx = _sgn(ex) * lam_f
    sy = _sgn(ey) * lam_f
    # derivatives of dt_k and T
    dt1_d = s1 / w1
    dt1_w = -a1 / (w1 * w1)
    dt2_d = s2 / w2
    dt2_w = -a2 / (w2 * w2)
    # n = dt1 g1 + dt2 h2 ; m = n / T ; dm = (dn - m dT) / T
    # d/dd1: dt1_d g1 + dt1 g1_d + dt2 dh2/dd1, with dh2/dd1 = (-h2y, h2x)
    n_x = dt1_d * g1x + dt1 * g1x_d - dt2 * h2y
    n_y = dt1_d * g1y + dt1 * g1y_d + dt2 * h2x
    m_x_d1 = (n_x - mx * dt1_d) * inv_t
    m_y_d1 = (n_y - my * dt1_d) * inv_t
    n_x = dt1_w * g1x + dt1 * g1x_w
    n_y = dt1_w * g1y + dt1 * g1y_w
    m_x_w1 = (n_x - mx * dt1_w) * inv_t
    m_y_w1 = (n_y - my * dt1_w) * inv_t
    r_x = c1 * g2x_d - sn1 * g2y_d
    r_y = sn1 * g2x_d + c1 * g2y_d
    n_x = dt2_d * h2x + dt2 * r_x
    n_y = dt2_d * h2y + dt2 * r_y
    m_x_d2 = (n_x - mx * dt2_d) * inv_t
    m_y_d2 = (n_y - my * dt2_d) * inv_t
    r_x = c1 * g2x_w - sn1 * g2y_w
    r_y = sn1 * g2x_w + c1 * g2y_w
    n_x = dt2_w * h2x + dt2 * r_x
    n_y = dt2_w * h2y + dt2 * r_y
    m_x_w2 = (n_x - mx * dt2_w) * inv_t
    m_y_w2 = (n_y - my * dt2_w) * inv_t
    # c_force through fbar = R(theta0) m: d c = sx (c0 dmx - s0 dmy) + sy (s0 dmx + c0 dmy)
    kx = sx * c0 + sy * s0
    ky = -sx * s0 + sy * c0
    g_d1 = kx * m_x_d1 + ky * m_y_d1
    g_w1 = kx * m_x_w1 + ky * m_y_w1
    g_d2 = kx * m_x_d2 + ky * m_y_d2
    g_w2 = kx * m_x_w2 + ky * m_y_w2
    if st_active:
        # dSt = kst (dS T - S dT) / T^2 ; dc_st/dSt = -eta_max e^{1-x} (1 - x) / St_opt
        dc = -lam_st * p[P_ETA_MAX] * ex1 * (1.0 - x) / p[P_ST_OPT]
        k = dc * kst * inv_t
        g_d1 += k * (s1 - ssum * inv_t * dt1_d)
        g_d2 += k * (s2 - ssum * inv_t * dt2_d)
        g_w1 += k * (-ssum * inv_t * dt1_w)
        g_w2 += k * (-ssum * inv_t * dt2_w)
    if closed:
        g_d1 += k_d1
        g_d2 += k_d2
        g_w1 += k_w1
        g_w2 += k_w2
    if m1 > 0.0:
        g_d1 -= lam_a * half_l * s1
    if m2 > 0.0:
        g_d2 -= lam_a * half_l * s2
    hd = 0.5 * lam_d
    g_d1 += hd * _sgn(e_d1)
    g_d2 += hd * _sgn(e_d2)
    g_w1 += hd * _sgn(e_w1)
    g_w2 += hd * _sgn(e_w2)
    if capped1:  # the rate follows the stroke: dJ/dd1 gains dJ/dw1 dcap/dd1
        g_d1 += g_w1 * slope1 * s1
        g_w1 = 0.0
    if capped2:
        g_d2 += g_w2 * slope2 * s2
        g_w2 = 0.0
    return total, c_force, c_st, c_amp, c_diff, st, fbx, fby, c_close, c_energy, g_d1, g_d2, g_w1, g_w2


@_inline
def cost_grad(p, q, gx_tab, gy_tab, x, grad, table, closed):
    """J at x (len 4) with its gradient written to ``grad``."""
    r = cost_eval(p, q, gx_tab, gy_tab, x[0], x[1], x[2], x[3], True, table, closed)
    grad[0] = r[10]
    grad[1] = r[11]
    grad[2] = r[12]
    grad[3] = r[13]
    return r[0]


@_jit
def cost_terms_at(p, q, gx_tab, gy_tab, u, terms, table, closed):
    """Write J and its terms at u (len 4) to ``terms``; returns J."""
    r = cost_eval(p, q, gx_tab, gy_tab, u[0], u[1], u[2], u[3], False, table, closed)
    for i in range(N_TERMS):
        terms[i] = r[i]
    return r[0]


@_jit
def _next(state):
    """splitmix64: the next 64 random bits."""
    z = state[0] + np.uint64(0x9E3779B97F4A7C15)
    state[0] = z
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@_inline
def _rand(state):
    """splitmix64: next uniform double in [0, 1) (53 bits)."""
    return float(np.int64(_next(state) >> np.uint64(11))) * (1.0 / 9007199254740992.0)


@_inline
def _rand2(state):
    """Two uniform doubles in [0, 1) from one splitmix64 draw (32 bits each: a stroke or a
    rate drawn to 3e-10 of its range)."""
    z = _next(state)
    lo = float(np.int64(z & np.uint64(0xFFFFFFFF))) * (1.0 / 4294967296.0)
    hi = float(np.int64(z >> np.uint64(32))) * (1.0 / 4294967296.0)
    return lo, hi


SAMPLE_BLOCK = 64
FTOL = 2.220446049250313e-09  # scipy's L-BFGS-B default factr * eps
PGTOL = 1e-5
#: a refined closed-stroke plan that opens by at most this much (rad) is refined again on
#: the closed subspace, and taken if it is as good within the stopping tolerance FTOL
CLOSE_SNAP = 1e-3


@_inline
def sample_stage(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, table, closed):
    """Stage 1: n admissible samples; keeps the best len(best_j) (sorted) in best_u.

    Samples are drawn and costed in blocks of SAMPLE_BLOCK (``block`` is a (5, B)
    scratch array) so that the cost loop runs on SIMD lanes. With ``closed``, half of
    the pairs (at random) are closed: |d_2| = |d_1|."""
    k = best_j.shape[0]
    for i in range(k):
        best_j[i] = np.inf
    d_eps = p[P_DEPS]
    d_span = p[P_DMAX] - d_eps
    w_lo = p[P_WMIN]
    w_span = p[P_WMAX] - w_lo
    bd1 = block[0]
    bd2 = block[1]
    bw1 = block[2]
    bw2 = block[3]
    bj = block[4]
    done = 0
    while done < n:
        m = min(block.shape[1], n - done)
        done += m
        for i in range(m):
            r1, r2 = _rand2(rng)
            r3, r4 = _rand2(rng)
            coins = _next(rng)  # its top bit chooses the signs, the next one closes the pair
            a1 = d_eps + d_span * r1
            a2 = d_eps + d_span * r2
            if closed:
                if (coins >> np.uint64(62)) & np.uint64(1):
                    a2 = a1
            if p[P_ACC] > 0.0:  # rates the drive can make of the strokes
                bw1[i] = w_lo + max(0.0, min(p[P_WMAX], rate_cap(p, a1)[0]) - w_lo) * r3
                bw2[i] = w_lo + max(0.0, min(p[P_WMAX], rate_cap(p, a2)[0]) - w_lo) * r4
            else:
                bw1[i] = w_lo + w_span * r3
                bw2[i] = w_lo + w_span * r4
            if coins >> np.uint64(63):
                bd1[i] = a1
                bd2[i] = -a2
            else:
                bd1[i] = -a1
                bd2[i] = a2
        for i in range(m):
            bj[i] = cost_eval(p, q, gx_tab, gy_tab, bd1[i], bd2[i], bw1[i], bw2[i], False, table, closed)[0]
        for i in range(m):
            j = bj[i]
            if j < best_j[k - 1]:
                pos = k - 1
                while pos > 0 and best_j[pos - 1] > j:
                    best_j[pos] = best_j[pos - 1]
                    for c in range(4):
                        best_u[pos, c] = best_u[pos - 1, c]
                    pos -= 1
                best_j[pos] = j
                best_u[pos, 0] = bd1[i]
                best_u[pos, 1] = bd2[i]
                best_u[pos, 2] = bw1[i]
                best_u[pos, 3] = bw2[i]


@_jit
def _box(p, x0, lo, hi):
    """The sign-constrained box around a warm start."""
    for k in range(2):
        if x0[k] >= 0.0:
            lo[k] = p[P_DEPS]
            hi[k] = p[P_DMAX]
        else:
            lo[k] = -p[P_DMAX]
            hi[k] = -p[P_DEPS]
        lo[2 + k] = p[P_WMIN]
        hi[2 + k] = p[P_WMAX]


@_jit
def _tie(v):
    """Project a gradient onto the closed subspace d_2 = -d_1."""
    a = 0.5 * (v[0] - v[1])
    v[0] = a
    v[1] = -a


# A refinement's state, one row of ``runs``: the point, its gradient, its sign box, the
# inverse Hessian (row-major), the cost, and how it goes on (a fresh Hessian, the last
# accepted step length, the iterations done, whether it is over, whether it is tied to the
# closed subspace).
RUN_ROW = Layout("a refinement's row of runs", [
    ("x", 4, "the point"), ("g", 4, "its gradient"), ("lo", 4, "its sign box, low"), ("hi", 4, "and high"),
    ("h", 16, "the inverse Hessian, row-major"), ("j", 1, "the cost"), ("fresh", 1, "1: a fresh Hessian"),
    ("alpha", 1, "the last accepted step length"), ("iter", 1, "iterations done (-1: screened out)"),
    ("done", 1, "1: over"), ("tied", 1, "1: tied to the closed subspace"),
])
R_X, R_G, R_LO, R_HI, R_H, R_J, R_FRESH, R_ALPHA, R_ITER, R_DONE, R_TIED = (RUN_ROW.at(f) for f in RUN_ROW.fields)
RUN = RUN_ROW.size


@_inline
def _identity_flat(h):
    for a in range(16):
        h[a] = 1.0 if a % 5 == 0 else 0.0


@_inline
def refine_begin(p, q, gx_tab, gy_tab, run, x0, table, closed):
    """Begin a refinement (stage 2) from ``x0`` in ``run``: its sign box, cost and gradient.
    With ``closed``, a closed start (d_2 = -d_1) is refined on the closed subspace."""
    for a in range(4):
        run[R_X + a] = x0[a]
    x = run[R_X:R_X + 4]
    g = run[R_G:R_G + 4]
    _box(p, x, run[R_LO:R_LO + 4], run[R_HI:R_HI + 4])
    tied = closed and x[0] + x[1] == 0.0
    run[R_J] = cost_grad(p, q, gx_tab, gy_tab, x, g, table, closed)
    if tied:
        _tie(g)
    for a in range(16):
        run[R_H + a] = 1.0 if a % 5 == 0 else 0.0
    run[R_FRESH] = 1.0
    run[R_ALPHA] = 1.0
    run[R_ITER] = 0.0
    run[R_DONE] = 0.0
    run[R_TIED] = 1.0 if tied else 0.0


@_inline
def refine_go(p, q, gx_tab, gy_tab, run, n, max_iter, work, table, closed):
    """Up to ``n`` more iterations of the refinement in ``run`` (projected BFGS inside its
    sign box; ``max_iter`` in all), until it is over; returns its cost, which is never
    above the cost at its start. ``work`` is an (8, 4) scratch array (rows 3-6 used).

    The line search backtracks from twice the last accepted step (at most 1): on this
    non-smooth cost the quasi-Newton step is often far too long near a kink, and starting
    where the last search ended saves most of the trials (half the cost evaluations of
    starting from 1, for the same costs within 1e-5 on the benchmark's protocol)."""
    x = run[R_X:R_X + 4]
    g = run[R_G:R_G + 4]
    lo = run[R_LO:R_LO + 4]
    hi = run[R_HI:R_HI + 4]
    h = run[R_H:R_H + 16]
    xn = work[3]
    gn = work[4]
    dirn = work[5]
    yv = work[6]
    tied = run[R_TIED] != 0.0
    j = run[R_J]
    fresh = run[R_FRESH] != 0.0
    a_last = run[R_ALPHA]
    it = int(run[R_ITER])
    done = run[R_DONE] != 0.0
    steps = 0
    while not done and steps < n and it < max_iter:
        steps += 1
        it += 1
        # free variables: not held at a bound by the gradient
        slope = 0.0
        for a in range(4):
            dirn[a] = 0.0
        for a in range(4):
            if (x[a] <= lo[a] and g[a] > 0.0) or (x[a] >= hi[a] and g[a] < 0.0):
                continue
            acc = 0.0
            for b in range(4):
                if (x[b] <= lo[b] and g[b] > 0.0) or (x[b] >= hi[b] and g[b] < 0.0):
                    continue
                acc -= h[4 * a + b] * g[b]
            dirn[a] = acc
            slope += acc * g[a]
        if not slope < 0.0:
            if fresh:
                done = True
                break
            _identity_flat(h)
            fresh = True
            continue
        alpha = min(1.0, 2.0 * a_last)
        accepted = False
        jn = j
        for _ls in range(30):
            dec = 0.0
            moved = False
            for a in range(4):
                v = x[a] + alpha * dirn[a]
                if v < lo[a]:
                    v = lo[a]
                elif v > hi[a]:
                    v = hi[a]
                xn[a] = v
            if tied:
                xn[1] = -xn[0]
            for a in range(4):
                if xn[a] != x[a]:
                    moved = True
                dec += g[a] * (xn[a] - x[a])
            if not moved:
                break
            jn = cost_grad(p, q, gx_tab, gy_tab, xn, gn, table, closed)
            if tied:
                _tie(gn)
            if jn <= j + 1e-4 * dec and jn < j:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            if fresh:
                done = True
                break
            _identity_flat(h)
            fresh = True
            continue
        a_last = alpha
        # BFGS update of the inverse Hessian with s = xn - x, y = gn - g
        sy = 0.0
        for a in range(4):
            dirn[a] = xn[a] - x[a]  # s
            yv[a] = gn[a] - g[a]
            sy += dirn[a] * yv[a]
        improvement = j - jn
        for a in range(4):
            x[a] = xn[a]
            g[a] = gn[a]
        j = jn
        fresh = False
        if sy > 1e-12:
            rho = 1.0 / sy
            # hy = H y ; yhy = y' H y
            yhy = 0.0
            for a in range(4):
                acc = 0.0
                for b in range(4):
                    acc += h[4 * a + b] * yv[b]
                xn[a] = acc  # reuse xn as hy
            for a in range(4):
                yhy += yv[a] * xn[a]
            for a in range(4):
                for b in range(4):
                    h[4 * a + b] += (
                        -rho * (dirn[a] * xn[b] + xn[a] * dirn[b])
                        + (rho * rho * yhy + rho) * dirn[a] * dirn[b]
                    )
        # scipy L-BFGS-B's default stopping rules: relative decrease below ftol,
        # or projected gradient below pgtol
        if improvement <= FTOL * max(abs(j), abs(j + improvement), 1.0):
            done = True
            break
        pg = 0.0
        for a in range(4):
            v = x[a] - g[a]
            if v < lo[a]:
                v = lo[a]
            elif v > hi[a]:
                v = hi[a]
            if abs(v - x[a]) > pg:
                pg = abs(v - x[a])
        if pg <= PGTOL:
            done = True
            break
    run[R_J] = j
    run[R_FRESH] = 1.0 if fresh else 0.0
    run[R_ALPHA] = a_last
    run[R_ITER] = it
    run[R_DONE] = 1.0 if done or it >= max_iter else 0.0
    return j


@_inline
def _sample(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, u_out, table, closed):
    """Stage 1: draw n samples, keep the best len(best_j); u_out = the best."""
    sample_stage(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, table, closed)
    for c in range(4):
        u_out[c] = best_u[0, c]


@_inline
def _refine_best(p, q, gx_tab, gy_tab, max_iter, best_u, best_j, work, runs, u_out, terms, table, closed):
    """Stage 2: refine the kept samples (none when max_iter is 0), then the final terms.

    Every kept sample is refined for ``P_SCREEN`` iterations; the ``P_KEEP`` with the lowest
    cost then go on to ``max_iter`` (most samples lead into the same few basins, and which
    basin is best shows after a few iterations: on the benchmark's protocol this costs
    5e-5 on average against refining all of them to the end, for a quarter of the work).
    The best point found is returned, never worse than the best sample.

    In the closed-stroke formulation one more start follows: a best plan that opens by at
    most CLOSE_SNAP is refined again from its projection on the closed subspace (the L1
    closure term's minimum lies there, which a free refinement only approaches) and taken
    if it is as good within the stopping tolerance."""
    j_best = best_j[0]
    if max_iter > 0:
        k = best_j.shape[0]
        screen = int(p[P_SCREEN])
        keep = min(int(p[P_KEEP]), k)
        # one call site of the solver for every task (it is inlined once): tasks 0..k-1
        # screen the kept samples, the next `keep` take the best on (R_ITER = -1 marks one
        # taken on), the last is the closed-stroke projection
        for task in range(k + keep + 1):
            x0 = work[7]
            n = max_iter
            begin = True
            if task < k:
                r = task
                if not best_j[r] < np.inf:
                    runs[r, R_J] = np.inf
                    runs[r, R_DONE] = 1.0
                    continue
                x0 = best_u[r]
                n = screen
            elif task < k + keep:
                r = -1
                for c in range(k):
                    if runs[c, R_ITER] >= 0.0 and (r < 0 or runs[c, R_J] < runs[r, R_J]):
                        r = c
                if r < 0:
                    continue
                begin = False
            else:
                for c in range(k):
                    if runs[c, R_J] < j_best:
                        j_best = runs[c, R_J]
                        for a in range(4):
                            u_out[a] = runs[c, R_X + a]
                opening = u_out[0] + u_out[1]
                if not (closed and opening != 0.0 and abs(opening) <= CLOSE_SNAP):
                    break
                r = k
                x0[0] = 0.5 * (u_out[0] - u_out[1])
                x0[1] = -x0[0]
                x0[2] = u_out[2]
                x0[3] = u_out[3]
            run = runs[r]
            if begin:
                refine_begin(p, q, gx_tab, gy_tab, run, x0, table, closed)
            j = refine_go(p, q, gx_tab, gy_tab, run, n, max_iter, work, table, closed)
            if k <= task < k + keep:
                run[R_ITER] = -1.0
            elif task == k + keep and j <= j_best + FTOL * max(abs(j_best), 1.0):
                for a in range(4):
                    u_out[a] = run[R_X + a]
    cost_terms_at(p, q, gx_tab, gy_tab, u_out, terms, table, closed)


@_jit
def refine_kernel(p, q, gx_tab, gy_tab, x, max_iter, work, runs):
    """Stage 2 alone from the start point x (updated in place), to ``max_iter``; returns
    the cost (``runs``: a (1, RUN) scratch array)."""
    table = p[P_MODE] == MODE_TABLE
    refine_begin(p, q, gx_tab, gy_tab, runs[0], x, table, False)
    j = refine_go(p, q, gx_tab, gy_tab, runs[0], max_iter, max_iter, work, table, False)
    for c in range(4):
        x[c] = runs[0, R_X + c]
    return j


@_jit
def cost_grad_at(p, q, gx_tab, gy_tab, u, grad, table, closed):
    """J at u with its gradient written to ``grad`` (not inlined)."""
    return cost_grad(p, q, gx_tab, gy_tab, u, grad, table, closed)


# The entry points: four per formulation and force model (plan, sample, finish, cost), made
# from the two flags by :func:`_entry_points`. The flags are constants of each entry point
# (closure values, which numba compiles in as constants and keys its cache by), so a
# configuration compiles only the solver it runs: the analytic force model's kernels by
# default, the table's only where ``force_model = "table"`` asks for them; and each calls
# the inlined solver directly (one more inlined layer would multiply numba's inlining time).
def _entry_points(table: bool, closed: bool) -> tuple:
    """(plan, sample, finish, cost) of the force table (``table``) or the analytic model, in
    the closed-stroke formulation (``closed``) or the paper's."""

    @_jit
    def plan_kernel(p, q, gx_tab, gy_tab, n, max_iter, rng, best_u, best_j, block, work, runs, u_out, terms):
        """One solve: sampling, refinement of the best len(best_j) samples, final terms."""
        _sample(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, u_out, table, closed)
        _refine_best(p, q, gx_tab, gy_tab, max_iter, best_u, best_j, work, runs, u_out, terms, table, closed)

    @_jit
    def sample_kernel(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, u_out):
        """The first half of the plan kernel (for a caller timing the two stages)."""
        _sample(p, q, gx_tab, gy_tab, n, rng, best_u, best_j, block, u_out, table, closed)

    @_jit
    def finish_kernel(p, q, gx_tab, gy_tab, max_iter, best_u, best_j, work, runs, u_out, terms):
        """The second half of the plan kernel (for a caller timing the two stages)."""
        _refine_best(p, q, gx_tab, gy_tab, max_iter, best_u, best_j, work, runs, u_out, terms, table, closed)

    @_jit
    def cost_kernel(p, q, gx_tab, gy_tab, u, grad, terms):
        """J, its gradient and its terms at one point (for callers outside the solver)."""
        cost_terms_at(p, q, gx_tab, gy_tab, u, terms, table, closed)
        return cost_grad_at(p, q, gx_tab, gy_tab, u, grad, table, closed)

    return plan_kernel, sample_kernel, finish_kernel, cost_kernel


#: (formulation, force model) -> the entry points (plan, sample, finish, cost)
KERNELS = {(f, m): _entry_points(m == "table", f == "closed_stroke") for f in FORMULATIONS for m in FORCE_MODELS}
