"""The fin model identified from what the robot measures: C_D and C_L (or one scale of both).

Data: each fin's encoder angle and rate (``FinState``), the DVL's forward speed, the IMU's
attitude and yaw rate; and from the configuration the hull's surge damping (``X_u``,
``X_uu``), its mass and added mass (``m - X_udot``) and the fins' mounting angle.

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

scipy.optimize is imported inside :func:`identify` only (the console's run path does not
load it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.inflow_model import Plate, stream_regressors
from ucat_console.control.params import ManoeuvreConfig, MpcConfig
from ucat_console.typedconf import Config, param

FITS = ("coefficients", "scale", "inflow")


@dataclass(frozen=True)
class IdentifyConfig(Config):
    """How a recording is cut into windows and which windows count."""

    fit: str = param("coefficients", choices=FITS,
                     doc="fit C_D and C_L, one scale of both, or C_D, C_L and the stream's profile drag C_D0 (inflow)")
    window_s: float = param(5.0, lo=0.5, hi=120.0, unit="s", doc="length of a force-balance window")
    steady_share: float = param(
        0.1, lo=0.0, hi=1.0, lo_open=True, doc="a window is steady when M du/dt is at most this share of the drag"
    )
    min_rate: float = param(0.3, lo=0.0, hi=50.0, unit="rad/s", doc="fins beat: mean |rate| at least this")
    max_tilt: float = param(10.0, lo=0.0, hi=90.0, lo_open=True, unit="deg", doc="largest roll or pitch")
    max_yaw_rate: float = param(0.1, lo=0.0, hi=10.0, lo_open=True, unit="rad/s", doc="largest mean |yaw rate|")
    min_dvl: int = param(8, lo=3, hi=10_000, doc="valid DVL reports a window needs")
    plate_cl_max: float = param(1.2, lo=0.0, hi=5.0, doc="inflow: the plate's largest lift C_Lmax (held)")
    plate_cd90: float = param(2.0, lo=0.0, hi=5.0, doc="inflow: the plate's drag across the flow C_D90 (held)")
    plate_strips: int = param(8, lo=1, hi=64, doc="inflow: blade-element strips")


@dataclass(frozen=True)
class Hull:
    """The hull in surge, from the configuration (Fossen's signs: damping < 0)."""

    mass: float  # m - X_udot, kg
    x_u: float  # N s/m
    x_uu: float  # N s2/m2
    mounting_angle: float  # rad, the fin plane's horizontal axis from the body x axis

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
    """What the fit reads: fin tracks, DVL forward speed, IMU attitude and yaw rate."""

    fins: tuple[FinTrack, ...]
    dvl_t: NDArray[np.float64]
    dvl_u: NDArray[np.float64]  # valid reports only, m/s
    imu_t: NDArray[np.float64]
    imu_roll: NDArray[np.float64]  # rad
    imu_pitch: NDArray[np.float64]
    imu_yaw_rate: NDArray[np.float64]  # rad/s


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
    c0: float = 0.0  # inflow: mean stream-thrust regressor of C_D0
    held: float = 0.0  # inflow: mean stream thrust of the held C_D90 and C_Lmax (N)
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
    c_d0: float = math.nan  # fit "inflow": the stream's profile drag C_D0
    c_d0_ci: float = math.nan

    @property
    def steady_windows(self) -> int:
        return sum(w.steady for w in self.windows)

    def toml_fragment(self, sources: str = "") -> str:
        """The ``[mpc]`` table to load (``--config``), with the fit in comments."""
        lines = ["# fin coefficients identified by `ucat-console identify`"
                 + (f" from {sources}" if sources else ""),
                 f"# fit {self.fit}: {len(self.windows)} windows ({self.steady_windows} steady), "
                 f"rms residual {self.rms_residual:.4f} N; 95 % intervals:",
                 f"# c_d {self.c_d:.4f} +- {self.c_d_ci:.4f}, c_l {self.c_l:.4f} +- {self.c_l_ci:.4f}"]
        if self.fit == "inflow":
            lines.append(f"# inflow: profile drag c_d0 {self.c_d0:.4f} +- {self.c_d0_ci:.4f} (the plate's "
                         "C_D90 and C_Lmax held)")
        lines += ["[mpc]", f"c_d = {self.c_d:.6g}", f"c_l = {self.c_l:.6g}", ""]
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


def _stream(track: FinTrack, m: Measurements, mpc: MpcConfig, hull: Hull,
            cfg: IdentifyConfig) -> tuple[NDArray, NDArray]:
    """(c_0, held) per sample for the inflow fit (zeros for the others): the stream's thrust
    regressor of C_D0 and the stream thrust of the held C_D90 and C_Lmax, at the DVL speed."""
    if cfg.fit != "inflow":
        z = np.zeros(track.t.size)
        return z, z
    speed = np.interp(track.t, m.dvl_t, m.dvl_u)
    plate = Plate(mpc.rho, mpc.fin_area, mpc.r_c, mpc.c_d, mpc.c_l, cfg.plate_strips)
    c0, c90, cl = stream_regressors(track.angle, track.rate, speed, plate, hull.mounting_angle)
    return c0, cfg.plate_cd90 * c90 + cfg.plate_cl_max * cl


def _slope(t: NDArray, u: NDArray) -> float:
    tc = t - t.mean()
    return float((tc * (u - u.mean())).sum() / (tc * tc).sum())


def windows(m: Measurements, mpc: MpcConfig, hull: Hull, cfg: IdentifyConfig) -> tuple[list[Window], dict[str, int]]:
    """The usable windows and, for a refusal's message, how many each check left out."""
    if not m.fins or any(f.t.size < 3 for f in m.fins):
        raise ValueError("fin channels: no encoder samples (fin/<i>/state): identification needs "
                         "every fin's measured angle and rate")
    if m.dvl_t.size < cfg.min_dvl:
        raise ValueError(f"sensors/dvl: {m.dvl_t.size} valid DVL reports; identification needs the "
                         "forward speed (at least one window's worth)")
    regs = [(f.t, *thrust_regressors(f, mpc, hull), *_stream(f, m, mpc, hull, cfg)) for f in m.fins]
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
        a = b = c0 = held = 0.0
        for t, ra, rb, r0, rh in regs:
            s = (t >= t0) & (t < t1)
            a += float(ra[s].mean())
            b += float(rb[s].mean())
            c0 += float(r0[s].mean())
            held += float(rh[s].mean())
        steady = drag > 0.0 and abs(hull.mass * accel) <= cfg.steady_share * drag
        out.append(Window(t0, t1, float(u.mean()), accel, drag, a, b, bool(steady), c0=c0, held=held))
    return out, why


def identify(recordings: Sequence[Measurements], mpc: MpcConfig, hull: Hull,
             cfg: IdentifyConfig | None = None) -> Identification:
    """Fit the fin coefficients to the windows of every recording (module docstring);
    ValueError naming why the recordings are refused."""
    import scipy.optimize
    import scipy.stats

    cfg = cfg or IdentifyConfig()
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
    steady = [w for w in ws if w.steady]
    if not steady:
        shares = [abs(hull.mass * w.accel) / w.drag if w.drag > 0.0 else math.inf for w in ws]
        raise ValueError(
            f"no steady segment: in each of the {len(ws)} usable windows of {cfg.window_s:g} s the hull "
            f"was still accelerating (M du/dt {100 * min(shares):.0f}-{100 * max(shares):.0f} % of the drag, "
            f"more than {100 * cfg.steady_share:g} %): record strokes held long enough for the speed to settle "
            f"(the identification manoeuvre holds each for {ManoeuvreConfig().step_s:g} s)")
    a = np.array([w.a for w in ws])
    b = np.array([w.b for w in ws])
    y = np.array([w.drag + hull.mass * w.accel - w.held for w in ws])
    if cfg.fit == "coefficients":
        basis = np.column_stack([b, a])  # columns: C_D, C_L
        x0 = np.array([mpc.c_d, mpc.c_l])
    elif cfg.fit == "inflow":
        basis = np.column_stack([b, a, [w.c0 for w in ws]])  # columns: C_D, C_L, C_D0
        x0 = np.array([mpc.c_d, mpc.c_l, 0.05])
    else:
        basis = (mpc.c_d * b + mpc.c_l * a)[:, None]
        x0 = np.array([1.0])
    p = basis.shape[1]
    if len(ws) <= p:
        raise ValueError(f"{len(ws)} usable windows for {p} coefficients: the recording is too short")
    gram = basis.T @ basis
    if cfg.fit != "scale" and np.linalg.cond(gram) > 1e8:
        raise ValueError("the recording does not tell C_L from C_D (every window pushes with the same "
                         "combination of the two: strokes about one centre); run the identification "
                         "manoeuvre, or fit one scale of both (fit = 'scale')")
    res = scipy.optimize.least_squares(lambda x: basis @ x - y, x0, bounds=(0.0, np.inf), method="trf")
    r = res.fun
    dof = len(ws) - p
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.inv(res.jac.T @ res.jac)
    half = scipy.stats.t.ppf(0.975, dof) * np.sqrt(np.diag(cov))
    c_d0 = c_d0_ci = math.nan
    if cfg.fit == "inflow":
        c_d0, c_d0_ci = float(res.x[2]), float(half[2])
    if cfg.fit != "scale":
        c_d, c_l = float(res.x[0]), float(res.x[1])
        c_d_ci, c_l_ci = float(half[0]), float(half[1])
        scale = c_d / mpc.c_d if mpc.c_d > 0.0 else math.nan
        scale_ci = c_d_ci / mpc.c_d if mpc.c_d > 0.0 else math.nan
    else:
        scale, scale_ci = float(res.x[0]), float(half[0])
        c_d, c_l = scale * mpc.c_d, scale * mpc.c_l
        c_d_ci, c_l_ci = scale_ci * mpc.c_d, scale_ci * mpc.c_l
    stream = 0.0 if math.isnan(c_d0) else c_d0
    fitted = tuple(
        Window(w.t0, w.t1, w.speed, w.accel, w.drag, w.a, w.b, w.steady,
               thrust=c_l * w.a + c_d * w.b + stream * w.c0 + w.held,
               residual=c_l * w.a + c_d * w.b + stream * w.c0 - yy, c0=w.c0, held=w.held)
        for w, yy in zip(ws, y)
    )
    return Identification(cfg.fit, c_d, c_l, c_d_ci, c_l_ci, scale, scale_ci, fitted,
                          float(np.sqrt(np.mean(r * r))), hull.mass, c_d0, c_d0_ci)


@dataclass(frozen=True)
class HoverTrim:
    """The heave force that holds the robot at its depth (``BodyConfig.heave_trim``), from a
    hover: its mean, the 95 % half-width, the seconds of hover it saw."""

    heave_trim: float  # N, down > 0
    ci: float  # N
    seconds: float

    def toml_fragment(self, source: str) -> str:
        return (f"# the heave trim from {self.seconds:.0f} s of hover in {source}: "
                f"{self.heave_trim:.3f} +- {self.ci:.3f} N (95 %)\n[body]\nheave_trim = {self.heave_trim:.4f}\n")


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
