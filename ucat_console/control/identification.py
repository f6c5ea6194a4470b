"""The fin model identified from what the robot measures: C_D and C_L (or one scale of both,
or the simulated fin's plate model).

Data: each fin's encoder angle and rate (``FinState``), the DVL's forward speed, the IMU's
attitude and yaw rate (the plate fit: the DVL's three velocities and the IMU's three rates);
and from the configuration the hull's surge damping (``X_u``, ``X_uu``), its mass and added
mass (``m - X_udot``) and where the fins sit (mounting angle, arms).

Model. The controller's quasi-steady fin model (control.md section 1) made instantaneous,
as the fin sweeps: at angle theta and rate w in a stroke that began at theta_s,

    f_x = q (-C_L cos(theta + (theta - theta_s)) + C_D sin(theta_s)),   q = 0.5 rho A_f (r_c w)^2

(the fin-frame force of eq 5 with the opening theta - theta_s, rotated by theta; a stroke
begins where the rate changes sign or the fin stops), and the fin pushes the hull forward
by -f_x cos(mounting angle). Summed over the fins, the thrust is linear in the
coefficients: T(t) = C_L a(t) + C_D b(t).

Force balance over a window [t_0, t_0 + W] (W = ``window_s``), in its time means::

    C_L mean(a) + C_D mean(b) = mean(D(u)) + M du/dt,    D(u) = -(X_u u + X_uu u |u|),  M = m - X_udot

with du/dt the slope of a straight line through the window's DVL speeds. Windows where the
fins beat (mean |rate| >= ``min_rate``), the DVL reports, and the IMU says the hull is level
(roll and pitch within ``max_tilt``) and not turning (``max_yaw_rate``) enter the fit. A
window is *steady* when the acceleration term is at most ``steady_share`` of the drag: there
thrust balances drag and the fit does not lean on M. A recording needs at least one steady
window (else it is refused, naming why); the accelerating windows add their equations.

Fit: ``scipy.optimize.least_squares`` on the window residuals (N), coefficients >= 0; 95 %
confidence intervals from the Jacobian (covariance s^2 (J^T J)^-1, Student t with n - p
degrees of freedom). One centre of the strokes gives one combination of C_L and C_D; a
recording that cannot tell them apart (the manoeuvre's several centres can) is refused for
``fit = "coefficients"`` and can be fitted with ``fit = "scale"`` (one factor on the
configured C_D and C_L).

``fit = "plate"`` fits the plant's own model instead (``control.plate_model``, the plate of
docs/fin-plant.md) in the flow past each fin that the DVL's velocity and the IMU's rates
give (the hull's heave and pitch at the fins included: they change the thrust by up to a
fifth). It is calibrated to the still-water model (C_D, C_L) as the plant's plate is: its
normal force C_D = C_D0 + C_D90, its lift held at ``lift_ratio`` of it (C_Lmax =
``lift_ratio`` C_D), its rotational circulation C_R = 2 sqrt(C_D^2 + C_L^2) / 3 and its line
at atan2(C_D, C_L) from the fin's; so the fit is (C_D, C_L, C_D0) by nonlinear least squares
on the same windows, with intervals from the Jacobian as above.

scipy.optimize is imported inside :func:`identify` only (the console's run path does not
load it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.plate_model import FinMount, Plate, hinge_flow, plate_regressors
from ucat_console.control.params import ManoeuvreConfig, MpcConfig
from ucat_console.typedconf import Config, param

FITS = ("coefficients", "scale", "plate")


@dataclass(frozen=True)
class IdentifyConfig(Config):
    """How a recording is cut into windows and which windows count."""

    fit: str = param("coefficients", choices=FITS,
                     doc="fit C_D and C_L, one scale of both, or the plate model's C_D, C_L and profile drag C_D0 (plate)")
    window_s: float = param(5.0, lo=0.5, hi=120.0, unit="s", doc="length of a force-balance window")
    steady_share: float = param(
        0.1, lo=0.0, hi=1.0, lo_open=True, doc="a window is steady when M du/dt is at most this share of the drag"
    )
    min_rate: float = param(0.3, lo=0.0, hi=50.0, unit="rad/s", doc="fins beat: mean |rate| at least this")
    max_tilt: float = param(10.0, lo=0.0, hi=90.0, lo_open=True, unit="deg", doc="largest roll or pitch")
    max_yaw_rate: float = param(0.1, lo=0.0, hi=10.0, lo_open=True, unit="rad/s", doc="largest mean |yaw rate|")
    min_dvl: int = param(8, lo=3, hi=10_000, doc="valid DVL reports a window needs")
    lift_ratio: float = param(0.6, lo=0.0, hi=2.0,
                              doc="plate: the plate's largest lift over its normal force, C_Lmax / C_N (held)")
    plate_strips: int = param(8, lo=1, hi=64, doc="plate: blade-element strips")


@dataclass(frozen=True)
class Hull:
    """The hull in surge, from the configuration (Fossen's signs: damping < 0)."""

    mass: float  # m - X_udot, kg
    x_u: float  # N s/m
    x_uu: float  # N s2/m2
    mount: FinMount  # where the fins sit (the plate fit's flow past each fin)

    @property
    def mounting_angle(self) -> float:
        """The fin plane's horizontal axis from the body x axis (rad)."""
        return self.mount.angle

    def drag(self, u: ArrayLike) -> NDArray[np.float64]:
        u = np.asarray(u, dtype=float)
        return -(self.x_u * u + self.x_uu * u * np.abs(u))


@dataclass(frozen=True)
class FinTrack:
    """One fin's encoder samples (s, rad, rad/s)."""

    t: NDArray[np.float64]
    angle: NDArray[np.float64]
    rate: NDArray[np.float64]


@dataclass(frozen=True)
class Measurements:
    """What the fit reads: fin tracks, the DVL's velocity, the IMU's attitude and rates (body
    frame; the plate fit reads the lateral and vertical ones for the flow past the fins)."""

    fins: tuple[FinTrack, ...]
    dvl_t: NDArray[np.float64]
    dvl_u: NDArray[np.float64]  # valid reports only, m/s
    dvl_v: NDArray[np.float64]
    dvl_w: NDArray[np.float64]
    imu_t: NDArray[np.float64]
    imu_roll: NDArray[np.float64]  # rad
    imu_pitch: NDArray[np.float64]
    imu_roll_rate: NDArray[np.float64]  # rad/s
    imu_pitch_rate: NDArray[np.float64]
    imu_yaw_rate: NDArray[np.float64]


@dataclass(frozen=True)
class Window:
    """One force-balance window (N, m/s, m/s2)."""

    t0: float
    t1: float
    speed: float
    accel: float
    drag: float
    a: float  # mean thrust regressor of C_L
    b: float  # of C_D
    steady: bool
    thrust: float = math.nan  # the fitted model's mean thrust
    #: plate: mean thrust regressors of C_D0, C_D90 and C_R (the lift held at its ratio)
    plate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    residual: float = math.nan  # thrust - (drag + M accel)


@dataclass(frozen=True)
class Identification:
    """The fitted coefficients with 95 % confidence half-widths and the windows' residuals."""

    fit: str
    c_d: float
    c_l: float
    c_d_ci: float
    c_l_ci: float
    scale: float  # the fitted scale (fit "scale"), else the fitted C_D over the configured one
    scale_ci: float
    windows: tuple[Window, ...]
    rms_residual: float  # N
    mass: float  # the hull's M used, kg
    c_d0: float = math.nan  # fit "plate": the plate's profile drag C_D0
    c_d0_ci: float = math.nan

    @property
    def steady_windows(self) -> int:
        return sum(w.steady for w in self.windows)

    def toml_fragment(self, sources: str = "") -> str:
        """The ``[loop.mpc]`` table to load (``--config``), with the fit in comments."""
        lines = ["# fin coefficients identified by `ucat-console identify`"
                 + (f" from {sources}" if sources else ""),
                 f"# fit {self.fit}: {len(self.windows)} windows ({self.steady_windows} steady), "
                 f"rms residual {self.rms_residual:.4f} N; 95 % intervals:",
                 f"# c_d {self.c_d:.4f} +- {self.c_d_ci:.4f}, c_l {self.c_l:.4f} +- {self.c_l_ci:.4f}"]
        if self.fit == "plate":
            lines.append(f"# plate: profile drag c_d0 {self.c_d0:.4f} +- {self.c_d0_ci:.4f} (the plate's lift "
                         "held at its ratio to the normal force)")
        lines += ["[loop.mpc]", f"c_d = {self.c_d:.6g}", f"c_l = {self.c_l:.6g}", ""]
        return "\n".join(lines)


def stroke_starts(angle: NDArray, rate: NDArray) -> NDArray:
    """theta_s per sample: the angle where the stroke in progress began (the rate changed
    sign or was zero)."""
    sign = np.sign(rate)
    start = np.zeros(angle.size, dtype=bool)
    start[0] = True
    start[1:] = (sign[1:] == 0.0) | (sign[1:] != sign[:-1])
    idx = np.where(start, np.arange(angle.size), 0)
    np.maximum.accumulate(idx, out=idx)
    return angle[idx]


def thrust_regressors(track: FinTrack, mpc: MpcConfig, hull: Hull) -> tuple[NDArray, NDArray]:
    """(a, b) per sample: the fin's forward thrust is C_L a + C_D b (module docstring)."""
    th, w = track.angle, track.rate
    th_s = stroke_starts(th, w)
    q = 0.5 * mpc.rho * mpc.fin_area * (mpc.r_c * w) ** 2 * math.cos(hull.mounting_angle)
    return q * np.cos(2.0 * th - th_s), -q * np.sin(th_s)


def _plate(fin: int, track: FinTrack, m: Measurements, mpc: MpcConfig, hull: Hull, cfg: IdentifyConfig,
           phi: float) -> tuple[NDArray, NDArray, NDArray]:
    """The plate fit's regressors per sample (zeros for the other fits): the thrust per unit of
    C_D0, C_D90 and C_R in the flow the DVL's velocity and the IMU's rates make past the fin,
    the lift held at ``lift_ratio`` of the normal force."""
    if cfg.fit != "plate":
        z = np.zeros(track.t.size)
        return z, z, z
    body = [np.interp(track.t, m.dvl_t, x) for x in (m.dvl_u, m.dvl_v, m.dvl_w)]
    body += [np.interp(track.t, m.imu_t, x) for x in (m.imu_roll_rate, m.imu_pitch_rate, m.imu_yaw_rate)]
    ux, uy = hinge_flow(fin, hull.mount, *body)
    plate = Plate(mpc.rho, mpc.fin_area, mpc.r_c, phi, cfg.plate_strips)
    c0, c90, cl, cr = plate_regressors(track.angle, track.rate, ux, uy, plate, hull.mounting_angle)
    return c0 + cfg.lift_ratio * cl, c90 + cfg.lift_ratio * cl, cr


def _slope(t: NDArray, u: NDArray) -> float:
    tc = t - t.mean()
    return float((tc * (u - u.mean())).sum() / (tc * tc).sum())


def windows(m: Measurements, mpc: MpcConfig, hull: Hull, cfg: IdentifyConfig,
            phi: float | None = None) -> tuple[list[Window], dict[str, int]]:
    """The usable windows and, for a refusal's message, how many each check left out
    (``phi``: the plate fit's line, default the configured model's)."""
    phi = math.atan2(mpc.c_d, mpc.c_l) if phi is None else phi
    if not m.fins or any(f.t.size < 3 for f in m.fins):
        raise ValueError("fin channels: no encoder samples (fin/<i>/state): identification needs "
                         "every fin's measured angle and rate")
    if m.dvl_t.size < cfg.min_dvl:
        raise ValueError(f"sensors/dvl: {m.dvl_t.size} valid DVL reports; identification needs the "
                         "forward speed (at least one window's worth)")
    regs = [(f.t, *thrust_regressors(f, mpc, hull), *_plate(i, f, m, mpc, hull, cfg, phi))
            for i, f in enumerate(m.fins)]
    t_lo = max(f.t[0] for f in m.fins)
    t_hi = min(f.t[-1] for f in m.fins)
    n = int((t_hi - t_lo) // cfg.window_s)
    out: list[Window] = []
    why = {"fins still": 0, "few DVL reports": 0, "tilted or turning": 0}
    tilt = math.radians(cfg.max_tilt)
    for k in range(n):
        t0 = t_lo + k * cfg.window_s
        t1 = t0 + cfg.window_s
        rates = [np.abs(f.rate[(f.t >= t0) & (f.t < t1)]) for f in m.fins]
        if min(r.size for r in rates) < 3 or np.mean([r.mean() for r in rates]) < cfg.min_rate:
            why["fins still"] += 1
            continue
        sel = (m.dvl_t >= t0) & (m.dvl_t < t1)
        if sel.sum() < cfg.min_dvl:
            why["few DVL reports"] += 1
            continue
        isel = (m.imu_t >= t0) & (m.imu_t < t1)
        if isel.any() and (np.abs(m.imu_roll[isel]).max() > tilt or np.abs(m.imu_pitch[isel]).max() > tilt
                           or abs(m.imu_yaw_rate[isel].mean()) > cfg.max_yaw_rate):
            why["tilted or turning"] += 1
            continue
        u = m.dvl_u[sel]
        accel = _slope(m.dvl_t[sel], u)
        drag = float(hull.drag(u).mean())
        a = b = 0.0
        plate = np.zeros(3)
        for t, ra, rb, *rp in regs:
            s = (t >= t0) & (t < t1)
            a += float(ra[s].mean())
            b += float(rb[s].mean())
            plate += [float(r[s].mean()) for r in rp]
        steady = drag > 0.0 and abs(hull.mass * accel) <= cfg.steady_share * drag
        out.append(Window(t0, t1, float(u.mean()), accel, drag, a, b, bool(steady),
                          plate=(float(plate[0]), float(plate[1]), float(plate[2]))))
    return out, why


def identify(recordings: Sequence[Measurements], mpc: MpcConfig, hull: Hull,
             cfg: IdentifyConfig | None = None) -> Identification:
    """Fit the fin coefficients to the windows of every recording (module docstring);
    ValueError naming why the recordings are refused."""
    cfg = cfg or IdentifyConfig()
    if cfg.fit == "plate":
        return _fit_plate(recordings, mpc, hull, cfg)
    return _fit(_usable(recordings, mpc, hull, cfg), mpc, hull, cfg)


def _usable(recordings: Sequence[Measurements], mpc: MpcConfig, hull: Hull, cfg: IdentifyConfig) -> list[Window]:
    """Every recording's windows; ValueError when none is usable or none is steady."""
    ws: list[Window] = []
    why: dict[str, int] = {}
    for m in recordings:
        w, left = windows(m, mpc, hull, cfg)
        ws += w
        for k, v in left.items():
            why[k] = why.get(k, 0) + v
    left_out = ", ".join(f"{v} {k}" for k, v in why.items() if v)
    if not ws:
        raise ValueError(f"no usable window of {cfg.window_s:g} s (left out: {left_out or 'none: too short'}); "
                         "identification needs the fins beating while the DVL reports, level and not turning")
    if not any(w.steady for w in ws):
        shares = [abs(hull.mass * w.accel) / w.drag if w.drag > 0.0 else math.inf for w in ws]
        raise ValueError(
            f"no steady segment: in each of the {len(ws)} usable windows of {cfg.window_s:g} s the hull "
            f"was still accelerating (M du/dt {100 * min(shares):.0f}-{100 * max(shares):.0f} % of the drag, "
            f"more than {100 * cfg.steady_share:g} %): record strokes held long enough for the speed to settle "
            f"(the identification manoeuvre holds each for {ManoeuvreConfig().step_s:g} s)")
    return ws


def _fit(ws: list[Window], mpc: MpcConfig, hull: Hull, cfg: IdentifyConfig) -> Identification:
    import scipy.optimize
    import scipy.stats

    a = np.array([w.a for w in ws])
    b = np.array([w.b for w in ws])
    y = np.array([w.drag + hull.mass * w.accel for w in ws])
    if cfg.fit == "coefficients":
        basis = np.column_stack([b, a])  # columns: C_D, C_L
        x0 = np.array([mpc.c_d, mpc.c_l])
    else:
        basis = (mpc.c_d * b + mpc.c_l * a)[:, None]
        x0 = np.array([1.0])
    p = basis.shape[1]
    if len(ws) <= p:
        raise ValueError(f"{len(ws)} usable windows for {p} coefficients: the recording is too short")
    gram = basis.T @ basis
    if cfg.fit != "scale" and np.linalg.cond(gram) > 1e8:
        raise ValueError("the recording does not tell the coefficients apart (every window pushes with the "
                         "same combination: strokes about one centre); run the identification manoeuvre, or "
                         "fit one scale of both (fit = 'scale')")
    res = scipy.optimize.least_squares(lambda x: basis @ x - y, x0, bounds=(0.0, np.inf), method="trf")
    r = res.fun
    dof = len(ws) - p
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.inv(res.jac.T @ res.jac)
    t975 = scipy.stats.t.ppf(0.975, dof)
    half = t975 * np.sqrt(np.diag(cov))
    c_d0 = c_d0_ci = math.nan
    if cfg.fit == "coefficients":
        c_d, c_l = float(res.x[0]), float(res.x[1])
        c_d_ci, c_l_ci = float(half[0]), float(half[1])
        scale = c_d / mpc.c_d if mpc.c_d > 0.0 else math.nan
        scale_ci = c_d_ci / mpc.c_d if mpc.c_d > 0.0 else math.nan
        thrust = c_l * a + c_d * b
    else:
        scale, scale_ci = float(res.x[0]), float(half[0])
        c_d, c_l = scale * mpc.c_d, scale * mpc.c_l
        c_d_ci, c_l_ci = scale_ci * mpc.c_d, scale_ci * mpc.c_l
        thrust = c_l * a + c_d * b
    fitted = tuple(
        Window(w.t0, w.t1, w.speed, w.accel, w.drag, w.a, w.b, w.steady, thrust=float(th),
               plate=w.plate, residual=float(th - yy))
        for w, th, yy in zip(ws, thrust, y)
    )
    return Identification(cfg.fit, c_d, c_l, c_d_ci, c_l_ci, scale, scale_ci, fitted,
                          float(np.sqrt(np.mean(r * r))), hull.mass, c_d0, c_d0_ci)


def _fit_plate(recordings: Sequence[Measurements], mpc: MpcConfig, hull: Hull,
               cfg: IdentifyConfig) -> Identification:
    """The plate fit (module docstring): (C_D, C_L, C_D0) by nonlinear least squares on the
    windows' force balance, the plate calibrated to (C_D, C_L) as the plant's is."""
    import scipy.optimize
    import scipy.stats

    ws = _usable(recordings, mpc, hull, cfg)  # the windows, with the checks' refusals
    if len(ws) <= 3:
        raise ValueError(f"{len(ws)} usable windows for 3 coefficients: the recording is too short")
    y = np.array([w.drag + hull.mass * w.accel for w in ws])

    def at(x: NDArray) -> tuple[list[Window], NDArray]:
        """The windows with the plate regressors of the line of (C_D, C_L), and the thrust."""
        c_d, c_l, c_d0 = (float(v) for v in x)
        rows = [w for m in recordings for w in windows(m, mpc, hull, cfg, math.atan2(c_d, c_l))[0]]
        coef = np.array([c_d0, c_d - c_d0, 2.0 * math.hypot(c_d, c_l) / 3.0])  # C_D0, C_D90, C_R
        return rows, np.array([w.plate for w in rows]) @ coef

    x0 = np.array([max(mpc.c_d, 0.1), max(mpc.c_l, 0.05), 0.05])  # from the configured model
    res = scipy.optimize.least_squares(lambda x: at(x)[1] - y, x0, bounds=(1e-9, np.inf), method="trf",
                                       x_scale=[x0[0], x0[1], 0.1])
    jtj = res.jac.T @ res.jac
    if np.linalg.cond(jtj) > 1e10:
        raise ValueError("the recording does not tell the plate's coefficients apart (strokes about one centre, "
                         "at one speed); run the identification manoeuvre")
    r = res.fun
    dof = len(ws) - 3
    half = scipy.stats.t.ppf(0.975, dof) * np.sqrt(np.diag(float(r @ r) / dof * np.linalg.inv(jtj)))
    c_d, c_l, c_d0 = (float(v) for v in res.x)
    rows, thrust = at(res.x)
    fitted = tuple(
        Window(w.t0, w.t1, w.speed, w.accel, w.drag, w.a, w.b, w.steady, thrust=float(th), plate=w.plate,
               residual=float(th - yy))
        for w, th, yy in zip(rows, thrust, y)
    )
    scale = c_d / mpc.c_d if mpc.c_d > 0.0 else math.nan
    scale_ci = float(half[0]) / mpc.c_d if mpc.c_d > 0.0 else math.nan
    return Identification("plate", c_d, c_l, float(half[0]), float(half[1]), scale, scale_ci, fitted,
                          float(np.sqrt(np.mean(r * r))), hull.mass, c_d0, float(half[2]))


@dataclass(frozen=True)
class HoverTrim:
    """The heave force that holds the robot at its depth (``BodyConfig.heave_trim``), from a
    hover: its mean, the 95 % half-width, the seconds of hover it saw."""

    heave_trim: float  # N, down > 0
    ci: float  # N
    seconds: float

    def toml_fragment(self, source: str) -> str:
        return (f"# the heave trim from {self.seconds:.0f} s of hover in {source}: "
                f"{self.heave_trim:.3f} +- {self.ci:.3f} N (95 %)\n[loop.body]\nheave_trim = {self.heave_trim:.4f}\n")


def hover_trim(t: ArrayLike, driving: ArrayLike, depth_error: ArrayLike, speed_ref: ArrayLike,
               heave: ArrayLike, *, band: float = 0.02, still: float = 0.02, min_s: float = 10.0,
               block_s: float = 1.0) -> HoverTrim:
    """The trim from the body layer's own record of a hover (``body/tracking`` and the heave
    applied, ``body/allocation``, at the same times ``t``).

    At a steady depth the hull's heave damping and added mass do nothing, so the heave force
    the fins were given is what holds the robot: its buoyancy, its trim, a steady vertical
    disturbance. Samples count while the fins are driven, the depth is within ``band`` of its
    reference and the speed reference below ``still`` (a hover: the fins beat for depth only).
    The mean over them is the trim; its interval is from the means of ``block_s`` blocks
    (neighbouring samples are not independent). ValueError when the record holds less than
    ``min_s`` of hover."""
    t = np.asarray(t, dtype=float)
    ok = (np.asarray(driving, dtype=bool) & (np.abs(np.asarray(depth_error, dtype=float)) <= band)
          & (np.abs(np.asarray(speed_ref, dtype=float)) <= still))
    z = np.asarray(heave, dtype=float)
    ok &= np.isfinite(z)
    if ok.sum() < 2:
        raise ValueError(f"trim: no hover in the record (driven, depth within {band:g} m of its reference, "
                         f"speed reference below {still:g} m/s)")
    dt = np.median(np.diff(t)) if t.size > 1 else 0.0
    seconds = float(ok.sum() * dt)
    if seconds < min_s:
        raise ValueError(f"trim: {seconds:.1f} s of hover in the record; it needs at least {min_s:g} s")
    blocks = np.floor((t[ok] - t[ok][0]) / block_s)
    means = np.array([z[ok][blocks == b].mean() for b in np.unique(blocks)])
    from scipy import stats  # here only: nothing of the run path loads scipy.stats

    half = float(stats.t.ppf(0.975, means.size - 1) * means.std(ddof=1) / np.sqrt(means.size)) if means.size > 1 else math.inf
    return HoverTrim(float(z[ok].mean()), half, seconds)
