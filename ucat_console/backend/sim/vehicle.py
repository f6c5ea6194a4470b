"""6-DOF rigid-body model of the U-CAT hull (Fossen), as compiled stepping functions.

Equations of motion in the body frame (FRD), with the current constant in NED and
irrotational (nu_c = (R^T V_c, 0), nu_r = nu - nu_c):

    (M_RB + M_A) nu_dot = tau - C_RB(nu) nu - C_A(nu_r) nu_r - D(nu_r) nu_r - g(eta)
                          + M_A nu_c_dot,          nu_c_dot = (nu_c1 x omega, 0)

* M_RB has the CG offset r_g: [[m I, -m S(r_g)], [m S(r_g), I_o]], with I_o the inertia about
  the body origin from the CG inertia by the parallel-axis theorem, I_o = I_g - m S(r_g)^2.
* M_A = -diag(X_u', Y_v', Z_w', K_p', M_q', N_r').
* C(nu) nu for both M_RB and M_A is Kirchhoff's form (Fossen's Theorem 3.2): with
  (p1, p2) = M nu, C(nu) nu = (omega x p1, v x p1 + omega x p2).
* D(nu_r) nu_r = -(lin_i + quad_i |nu_r,i|) nu_r,i per axis (Fossen signs, coefficients <= 0).
* g(eta): weight W at r_g and buoyancy B at r_b, resolved in the body frame through the
  attitude, so the CG below the CB gives a restoring moment.

State vector ``xv`` (float64, :data:`STATE`): position NED, quaternion w,x,y,z body->NED,
body velocity u,v,w,p,q,r, and the body acceleration of the last step (read by the IMU
model). Integration is semi-implicit Euler: velocities first,
then position and attitude with the new velocities (the attitude through the exact
quaternion exponential of the rotation over the step), stable and accurate at 1 kHz for
this hull (its fastest mode, roll, has a natural frequency of about 6.5 rad/s).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ucat_console.backend.sim.params import VehicleConfig
from ucat_console.robot.layout import Layout
from ucat_console.robot.rotations import quat_mul, skew
from ucat_console.robot.units import GRAVITY

# the declared layouts of the hull's arrays; their columns as constants (module globals, which
# the compiled functions take as constants)
STATE = Layout("the vehicle state xv", [
    ("pos", 3, "position, world NED (m)"),
    ("quat", 4, "attitude quaternion w, x, y, z, body -> NED"),
    ("nu", 6, "body velocity over ground u, v, w (m/s), p, q, r (rad/s)"),
    ("nu_dot", 6, "body acceleration of the last step (read by the IMU model)"),
])
POS, QUAT, NU, NU_DOT = (STATE.at(f) for f in STATE.fields)
NX = STATE.size

PARAMS = Layout("the vehicle parameter vector pv", [
    ("weight", 1, "weight W = m g (N)"),
    ("buoyancy", 1, "buoyancy B (N)"),
    ("r_g", 3, "centre of gravity, body FRD (m)"),
    ("r_b", 3, "centre of buoyancy, body FRD (m)"),
    ("current", 3, "water current, world NED (m/s)"),
    ("disturbance", 3, "disturbance force at the body origin, world NED (N)"),
    ("tau_ext", 6, "extra wrench at the body origin, body frame (N, N m; Plant.set_body_wrench)"),
    ("d_lin", 6, "linear damping per axis (Fossen signs)"),
    ("d_quad", 6, "quadratic damping per axis (Fossen signs)"),
])
P_W, P_B, P_RG, P_RB, P_CUR, P_DIST, P_TAU, P_DLIN, P_DQUAD = (PARAMS.at(f) for f in PARAMS.fields)
NPV = PARAMS.size

#: the scratch buffer of :func:`vehicle_step` (``body_acceleration``'s)
WORK = Layout("the hull step's scratch buffer", [
    ("force", 6, "the total generalised force"),
    ("nu_r", 6, "the velocity through the water"),
    ("momentum", 6, "M nu of the Coriolis terms"),
])
W_FORCE, W_NU_R, W_MOMENTUM = (WORK.at(f) for f in WORK.fields)
NWORK = WORK.size


def vehicle_matrices(cfg: VehicleConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M_RB, M_A, (M_RB + M_A)^-1) as 6x6 arrays."""
    m = cfg.mass
    rg = np.asarray(cfg.cg, dtype=float)
    s = skew(rg)
    i_g = np.diag([cfg.ixx, cfg.iyy, cfg.izz])
    i_o = i_g - m * s @ s
    mrb = np.zeros((6, 6))
    mrb[:3, :3] = m * np.eye(3)
    mrb[:3, 3:] = -m * s
    mrb[3:, :3] = m * s
    mrb[3:, 3:] = i_o
    ma = -np.diag([cfg.x_udot, cfg.y_vdot, cfg.z_wdot, cfg.k_pdot, cfg.m_qdot, cfg.n_rdot])
    m_total = mrb + ma
    if np.min(np.linalg.eigvalsh(m_total)) <= 0.0:
        raise ValueError("vehicle: M_RB + M_A is not positive definite; check mass, inertias and cg")
    return mrb, ma, np.linalg.inv(m_total)


def vehicle_params(
    cfg: VehicleConfig, tau_ext: tuple[float, ...] = (0.0,) * 6
) -> np.ndarray:
    """The vehicle parameter vector read by the compiled step (:data:`PARAMS`)."""
    pv = np.zeros(NPV)
    w = cfg.mass * GRAVITY
    pv[P_W] = w
    pv[P_B] = w * cfg.buoyancy_ratio
    pv[PARAMS.span("r_g")] = cfg.cg
    pv[PARAMS.span("r_b")] = cfg.cb
    pv[PARAMS.span("current")] = cfg.current_ned
    pv[PARAMS.span("disturbance")] = cfg.disturbance_ned
    pv[PARAMS.span("tau_ext")] = tau_ext
    pv[PARAMS.span("d_lin")] = (cfg.x_u, cfg.y_v, cfg.z_w, cfg.k_p, cfg.m_q, cfg.n_r)
    pv[PARAMS.span("d_quad")] = (cfg.x_uu, cfg.y_vv, cfg.z_ww, cfg.k_pp, cfg.m_qq, cfg.n_rr)
    return pv


def initial_state(
    position_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
    quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    body_velocity: tuple[float, ...] = (0.0,) * 6,
) -> np.ndarray:
    """A vehicle state vector; the quaternion is normalised."""
    q = np.asarray(quaternion, dtype=float)
    n = float(np.linalg.norm(q))
    if len(q) != 4 or not np.all(np.isfinite(q)) or n < 1e-9:
        raise ValueError(f"quaternion: expected four finite numbers, not all zero, got {quaternion!r}")
    for name, v, k in (("position_ned", position_ned, 3), ("body_velocity", body_velocity, 6)):
        a = np.asarray(v, dtype=float)
        if a.shape != (k,) or not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: expected {k} finite numbers, got {v!r}")
    xv = np.zeros(NX)
    xv[STATE.span("pos")] = position_ned
    xv[STATE.span("quat")] = q / n
    xv[STATE.span("nu")] = body_velocity
    return xv


@njit(cache=True)
def body_current(r: np.ndarray, pv: np.ndarray, out: np.ndarray) -> None:
    """Water current in the body frame, R^T V_c, into ``out[0:3]``."""
    for i in range(3):
        out[i] = r[0, i] * pv[P_CUR] + r[1, i] * pv[P_CUR + 1] + r[2, i] * pv[P_CUR + 2]


@njit(cache=True)
def _kirchhoff(m: np.ndarray, nu: np.ndarray, p: np.ndarray, out: np.ndarray, sign: float) -> None:
    """out += sign * C(nu) nu for the symmetric inertia m (p: 6-element scratch)."""
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += m[i, j] * nu[j]
        p[i] = acc
    vx, vy, vz, wx, wy, wz = nu[0], nu[1], nu[2], nu[3], nu[4], nu[5]
    out[0] += sign * (wy * p[2] - wz * p[1])
    out[1] += sign * (wz * p[0] - wx * p[2])
    out[2] += sign * (wx * p[1] - wy * p[0])
    out[3] += sign * ((vy * p[2] - vz * p[1]) + (wy * p[5] - wz * p[4]))
    out[4] += sign * ((vz * p[0] - vx * p[2]) + (wz * p[3] - wx * p[5]))
    out[5] += sign * ((vx * p[1] - vy * p[0]) + (wx * p[4] - wy * p[3]))


@njit(cache=True)
def body_acceleration(
    xv: np.ndarray,
    tau_fins: np.ndarray,
    mrb: np.ndarray,
    ma: np.ndarray,
    minv: np.ndarray,
    pv: np.ndarray,
    r: np.ndarray,
    nuc: np.ndarray,
    work: np.ndarray,
    out: np.ndarray,
) -> None:
    """nu_dot (6) for state ``xv`` under the fin wrench ``tau_fins``; ``r`` must hold R(q)
    and ``nuc`` the current in the body frame (:func:`body_current`)."""
    nu = xv[NU : NU + 6]
    f = work[W_FORCE:W_FORCE + 6]
    nur = work[W_NU_R:W_NU_R + 6]
    p = work[W_MOMENTUM:W_MOMENTUM + 6]
    for i in range(6):
        nur[i] = nu[i]
    for i in range(3):
        nur[i] -= nuc[i]
    # external: fins, test/experiment wrench, disturbance (NED -> body)
    for i in range(6):
        f[i] = tau_fins[i] + pv[P_TAU + i]
    for i in range(3):
        f[i] += r[0, i] * pv[P_DIST] + r[1, i] * pv[P_DIST + 1] + r[2, i] * pv[P_DIST + 2]
    # restoring: weight (+z NED) at r_g, buoyancy (-z NED) at r_b
    gz0, gz1, gz2 = r[2, 0], r[2, 1], r[2, 2]  # NED z axis in body coordinates
    w = pv[P_W]
    b = pv[P_B]
    fgx, fgy, fgz = w * gz0, w * gz1, w * gz2
    fbx, fby, fbz = -b * gz0, -b * gz1, -b * gz2
    f[0] += fgx + fbx
    f[1] += fgy + fby
    f[2] += fgz + fbz
    xg, yg, zg = pv[P_RG], pv[P_RG + 1], pv[P_RG + 2]
    xb, yb, zb = pv[P_RB], pv[P_RB + 1], pv[P_RB + 2]
    f[3] += (yg * fgz - zg * fgy) + (yb * fbz - zb * fby)
    f[4] += (zg * fgx - xg * fgz) + (zb * fbx - xb * fbz)
    f[5] += (xg * fgy - yg * fgx) + (xb * fby - yb * fbx)
    # damping on the relative velocity
    for i in range(6):
        f[i] += (pv[P_DLIN + i] + pv[P_DQUAD + i] * abs(nur[i])) * nur[i]
    # Coriolis and centripetal terms
    _kirchhoff(mrb, nu, p, f, -1.0)
    _kirchhoff(ma, nur, p, f, -1.0)
    # added mass of the current seen from the turning body: M_A nu_c_dot
    cdx = nuc[1] * nu[5] - nuc[2] * nu[4]
    cdy = nuc[2] * nu[3] - nuc[0] * nu[5]
    cdz = nuc[0] * nu[4] - nuc[1] * nu[3]
    for i in range(6):
        f[i] += ma[i, 0] * cdx + ma[i, 1] * cdy + ma[i, 2] * cdz
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += minv[i, j] * f[j]
        out[i] = acc


@njit(cache=True)
def vehicle_step(
    xv: np.ndarray,
    tau_fins: np.ndarray,
    mrb: np.ndarray,
    ma: np.ndarray,
    minv: np.ndarray,
    pv: np.ndarray,
    dt: float,
    r: np.ndarray,
    nuc: np.ndarray,
    work: np.ndarray,
) -> None:
    """Advance ``xv`` in place by one step ``dt`` (semi-implicit Euler, exact quaternion update).

    ``r`` must hold R(q) of the state and ``nuc`` its body-frame current (:func:`body_current`),
    as the caller has them for the fin forces; ``work`` (``NWORK``) is scratch.
    """
    acc = xv[NU_DOT : NU_DOT + 6]
    body_acceleration(xv, tau_fins, mrb, ma, minv, pv, r, nuc, work, acc)
    for i in range(6):
        xv[NU + i] += acc[i] * dt
    u, v, w = xv[NU], xv[NU + 1], xv[NU + 2]
    for i in range(3):
        xv[POS + i] += (r[i, 0] * u + r[i, 1] * v + r[i, 2] * w) * dt
    # q <- q (x) exp(omega dt / 2)
    wx, wy, wz = xv[NU + 3], xv[NU + 4], xv[NU + 5]
    rate = math.sqrt(wx * wx + wy * wy + wz * wz)
    half = 0.5 * rate * dt
    if rate > 1e-12:
        c = math.cos(half)
        s = math.sin(half) / rate
    else:
        c = 1.0
        s = 0.5 * dt
    dw, dx, dy, dz = c, s * wx, s * wy, s * wz
    qw, qx, qy, qz = xv[QUAT], xv[QUAT + 1], xv[QUAT + 2], xv[QUAT + 3]
    nw, nx, ny, nz = quat_mul(qw, qx, qy, qz, dw, dx, dy, dz)
    norm = math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    xv[QUAT] = nw / norm
    xv[QUAT + 1] = nx / norm
    xv[QUAT + 2] = ny / norm
    xv[QUAT + 3] = nz / norm
