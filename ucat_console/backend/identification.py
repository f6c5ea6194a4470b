"""Identification from recordings.

* :func:`identify_sessions` reads recorded sessions (the fins' encoder angles and rates,
  the DVL, the IMU), takes the hull's surge damping, mass and added mass and the fins'
  mounting angle from the configuration (given, else the one the first session recorded,
  else the defaults) and fits the controller's fin coefficients
  (:mod:`ucat_console.control.identification`). It returns an :class:`IdentifyReport`
  with the coefficients, their 95 % intervals, the windows' residuals and the TOML
  fragment to load; :func:`residual_plots` draws the residuals (matplotlib, the
  ``experiments`` extra).

The identification manoeuvre that records such a session on a running robot is the
supervisor's (``backend.supervisor.manoeuvre``).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.reader import SessionSource, open_session
from ucat_console.config import AppConfig
from ucat_console.control.estimation import tilt_from_accel
from ucat_console.control.identification import (
    FinTrack,
    HoverTrim,
    Hull,
    Identification,
    IdentifyConfig,
    Measurements,
    hover_trim,
    identify,
)
from ucat_console.control.plate_model import FinMount
from ucat_console.robot.readings import ImuReading
from ucat_console.robot.rotations import euler_from_quaternion
from ucat_console.telemetry import channels as ch


def hull_of(cfg: AppConfig) -> Hull:
    """The hull in surge and the fin mounting from a configuration's plant description."""
    v, f = cfg.plant.vehicle, cfg.plant.fins
    return Hull(mass=v.mass - v.x_udot, x_u=v.x_u, x_uu=v.x_uu,
                mount=FinMount(math.radians(f.mounting_angle_deg), f.arm_roll, f.arm_pitch, f.arm_yaw))


def recorded_app_config(source: SessionSource, name: str) -> AppConfig | None:
    """The configuration a session recorded, or None if it recorded none."""
    text = source.config_toml
    if not text.strip():
        return None
    try:
        return AppConfig.from_dict(tomllib.loads(text))
    except (tomllib.TOMLDecodeError, ValueError) as e:
        raise ValueError(f"{name}: recorded configuration: {e}") from None


def measurements(source: SessionSource, name: str) -> Measurements:
    """What the fit reads from one session; ValueError naming a missing channel."""
    present = {c for c, n in source.message_counts().items() if n > 0}
    fins = [ch.fin_state(i) for i in range(ch.N_FINS)]
    missing = [c for c in fins if c not in present]
    if missing:
        raise ValueError(f"{name}: no fin channels {', '.join(missing)}: identification needs every "
                         "fin's encoder angle and rate")
    for c in (ch.DVL, ch.IMU):
        if c not in present:
            raise ValueError(f"{name}: no {c} channel: identification needs the DVL speed and the IMU")
    data: dict[str, list] = {c: [] for c in fins + [ch.DVL, ch.IMU]}
    for c, m in source.messages(data):
        data[c].append(m)
    tracks = tuple(FinTrack(np.array([m.t for m in ms]), np.array([m.angle for m in ms]),
                            np.array([m.rate for m in ms])) for ms in (data[c] for c in fins))
    dvl = [m for m in data[ch.DVL] if m.valid and math.isfinite(m.vx) and math.isfinite(m.vy) and math.isfinite(m.vz)]
    imu = data[ch.IMU]
    att = np.array([_roll_pitch(m) for m in imu]).reshape(-1, 2)
    return Measurements(
        fins=tracks, dvl_t=np.array([m.t for m in dvl]), dvl_u=np.array([m.vx for m in dvl]),
        dvl_v=np.array([m.vy for m in dvl]), dvl_w=np.array([m.vz for m in dvl]),
        imu_t=np.array([m.t for m in imu]), imu_roll=att[:, 0], imu_pitch=att[:, 1],
        imu_roll_rate=np.array([m.gyro[0] for m in imu]), imu_pitch_rate=np.array([m.gyro[1] for m in imu]),
        imu_yaw_rate=np.array([m.gyro[2] for m in imu]),
    )


def _roll_pitch(m: ImuReading) -> tuple[float, float]:
    """Roll and pitch (rad) the IMU reports; from the direction of gravity in its
    accelerometer when it streams no orientation (the hull accelerates at a few
    hundredths of g at most)."""
    if m.euler is not None:
        return m.euler[0], m.euler[1]
    if m.quaternion is not None:
        r, pch, _ = euler_from_quaternion(m.quaternion)
        return r, pch
    return tilt_from_accel(m.accel)


@dataclass(frozen=True)
class IdentifyReport:
    """An identification: the fit, the sessions it read, and the TOML fragment to load."""

    result: Identification
    sessions: tuple[str, ...]
    config_source: str  # where the hull and the starting model came from
    toml: str


def identify_sessions(sessions: Sequence[str | Path], directory: str | Path | None = None,
                      config: AppConfig | None = None, cfg: IdentifyConfig | None = None, *,
                      confined: bool = True, budget: MemoryBudget | None = None) -> IdentifyReport:
    """Fit the fin coefficients to the recorded sessions (module docstring; ``confined`` and
    ``budget``: as :func:`open_session`)."""
    if not sessions:
        raise ValueError("identify: name at least one session")
    recs: list[Measurements] = []
    names: list[str] = []
    app = config
    source_of_config = "the given configuration" if config is not None else ""
    for s in sessions:
        src = open_session(s, directory, confined=confined, budget=budget)
        try:
            name = str(s)
            if app is None:
                app = recorded_app_config(src, name)
                if app is not None:
                    source_of_config = f"the configuration recorded in {name}"
            recs.append(measurements(src, name))
            names.append(name)
        finally:
            src.close()
    if app is None:
        app, source_of_config = AppConfig(), "the defaults"
    result = identify(recs, app.loop.mpc, hull_of(app), cfg)
    toml = result.toml_fragment(", ".join(names))
    return IdentifyReport(result, tuple(names), source_of_config, toml)


def trim_sessions(sessions: Sequence[str | Path], directory: str | Path | None = None, *,
                  confined: bool = True, budget: MemoryBudget | None = None) -> tuple[HoverTrim, str]:
    """The heave trim from the hovers recorded in ``sessions`` (``control.identification.
    hover_trim``) and the TOML fragment to load; ValueError naming a session without the
    body layer's channels. ``confined`` and ``budget``: as :func:`open_session`."""
    if not sessions:
        raise ValueError("identify --trim: name at least one session")
    cols: dict[str, list[float]] = {k: [] for k in ("t", "driving", "depth_error", "speed_ref", "heave")}
    names = []
    for s in sessions:
        src = open_session(s, directory, confined=confined, budget=budget)
        try:
            name = str(s)
            present = {c for c, n in src.message_counts().items() if n > 0}
            for c in (ch.BODY_TRACKING, ch.BODY_ALLOCATION):
                if c not in present:
                    raise ValueError(f"{name}: no {c} channel: the trim needs the body layer's tracking and "
                                     "allocation (recorded by this version)")
            heave: dict[float, float] = {}
            tracking = []
            for c, m in src.messages([ch.BODY_TRACKING, ch.BODY_ALLOCATION]):
                if c == ch.BODY_ALLOCATION:
                    heave[m.t] = m.heave_applied
                else:
                    tracking.append(m)
            for m in tracking:
                if m.t in heave:
                    cols["t"].append(m.t)
                    cols["driving"].append(m.driving)
                    cols["depth_error"].append(m.depth_error)
                    cols["speed_ref"].append(m.speed_ref)
                    cols["heave"].append(heave[m.t])
            names.append(name)
        finally:
            src.close()
    trim = hover_trim(**{k: np.asarray(v) for k, v in cols.items()})
    return trim, trim.toml_fragment(", ".join(names))


def residual_plots(result: Identification, path: Path) -> Path:
    """The fit's residuals: model thrust against drag + M du/dt, and residual over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w = result.windows
    y = np.array([x.drag + result.mass * x.accel for x in w])
    thrust = np.array([x.thrust for x in w])
    steady = np.array([x.steady for x in w])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for mask, label, mk in ((steady, "steady", "o"), (~steady, "accelerating", "x")):
        ax1.plot(y[mask], thrust[mask], mk, label=label)
        ax2.plot([x.t0 for x, m in zip(w, mask) if m], [x.residual for x, m in zip(w, mask) if m], mk, label=label)
    lim = [0.0, max(float(y.max()), float(thrust.max()), 1e-3) * 1.05]
    ax1.plot(lim, lim, "k-", lw=0.8)
    ax1.set_xlabel("hull drag + M du/dt (N)")
    ax1.set_ylabel("model thrust (N)")
    ax1.set_title(f"C_D {result.c_d:.3f} +- {result.c_d_ci:.3f}, C_L {result.c_l:.3f} +- {result.c_l_ci:.3f}",
                  fontsize=9)
    ax1.legend(fontsize=8)
    ax2.axhline(0.0, color="k", lw=0.8)
    ax2.set_xlabel("window start (s)")
    ax2.set_ylabel("residual (N)")
    ax2.set_title(f"rms {result.rms_residual:.4f} N", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
