"""One closed-loop run on the simulated U-CAT, measured the way the paper measures it.

:func:`run_scenario` builds the plant (a variant of ``sim.variants``), the closed loop
(headless), runs ``settle_s`` seconds, then measures over ``window_s`` seconds from the
telemetry stream the loop publishes (the same channels a pool test records) and, for the
simulator's own view, from the plant's truth. It returns plain JSON-ready numbers (and an
optional decimated trace), so it can run in a worker process of a distributed executor.

Start: the plant starts level at the run's start depth, already surging at the start
velocity (default: the reference), with every fin at rest at ``fin_rig.START_FIN_ANGLE``,
the angle about which a symmetric stroke pair pushes straight forward under the
controller's model (the baseline's oscillation centre for a pure thrust demand). The runs measure
cruising, as the paper does after settling; ``start_velocity = 0`` starts them from rest
(E4R and E6). ``body`` is the body-frame layer (the paper's PIDs by default,
the shipped ``sim-tuned``'s in E4R's second setting) and ``plant`` the name of a plant
variant (``sim.variants.plant_config``). An MPC mode's fin planner may be another than the
loop's own (``mpc_planner``: E7's oracle, ``experiments.oracle``).

Energy per metre: the energy spent over the window divided by the distance the hull
travelled through the water in it (true surge integrated): the battery's (the drives'
electrical input by the plant's drive model, ``energy_per_metre_electrical``, the
experiments' primary figure), the plant's shaft energy (``energy_per_metre_true``) and the
encoder estimate's (``energy_per_metre``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np

from ucat_console.backend.fin_rig import START_FIN_ANGLE
from ucat_console.backend.loop.closed_loop import ClosedLoop, check_setpoints
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim.variants import DEFAULT_PLANT, plant_config
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.params import BaselineConfig, BodyConfig, MpcConfig
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream


@dataclass(frozen=True)
class Scenario:
    """One closed-loop run (times in simulated seconds)."""

    mode: str
    v_ref: float
    depth: float = 1.0
    yaw_rate: float = 0.0
    seed: int = 0
    plant: str = DEFAULT_PLANT
    settle_s: float = 30.0
    window_s: float = 60.0
    start_depth: float | None = None  # default: the depth setpoint
    start_velocity: float | None = None  # default: the velocity setpoint
    current: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    baseline: BaselineConfig = field(default_factory=BaselineConfig)
    trace_rate: float = 0.0  # Hz of the returned trace; 0: none
    tag: str = ""
    planner: str = ""  # "oracle": E7's oracle plans for the MPC modes (experiments.oracle)

    def loop_config(self) -> LoopConfig:
        return LoopConfig(mode=self.mode, planner_seed=self.seed, mpc=self.mpc, body=self.body,
                          baseline=self.baseline)

    def check(self) -> None:
        """Refuse setpoints outside the loop's envelope before anything runs."""
        sp = BodySetpoints(velocity=self.v_ref, depth=self.depth, yaw_rate=self.yaw_rate)
        check_setpoints(self.loop_config(), sp)
        plant_config(self.plant, self.seed, self.current)
        if self.planner not in ("", "oracle"):
            raise ValueError(f"planner: {self.planner!r} is not '' or 'oracle'")
        if self.settle_s < 0.0 or self.window_s <= 0.0:
            raise ValueError(f"window: settle {self.settle_s} s and window {self.window_s} s; need >= 0 and > 0")


class _Recorder:
    """Collects what the metrics need from the telemetry stream, from ``t0`` on."""

    def __init__(self, loop: ClosedLoop, t0: float, t1: float, trace_rate: float, st_opt: float,
                 st_band: tuple[float, float]) -> None:
        self.loop = loop
        self.t0, self.t1 = t0, t1
        self.dvl_v: list[float] = []
        self.depth_meas: list[float] = []
        self.gyro_r: list[float] = []
        self.plan_st: list[float] = []
        self.plan_force: list[float] = []
        self.plan_u: dict[int, list[tuple]] = {i: [] for i in range(4)}
        self.fin_angles: list[tuple[float, ...]] = []  # true, at each power sample in the window
        self.truth: list[tuple] = []
        self.energy: list[tuple[float, float]] = []  # (t, estimator energy)
        self.trace_rate = trace_rate
        self.trace: dict[str, list] = {k: [] for k in (
            "t", "depth", "velocity", "velocity_dvl", "yaw_rate", "x", "y", "yaw", "power", "st_mean", "st_plan")}
        self._next_trace = 0.0
        self._last_power = 0.0
        self._last_st_plan = math.nan
        self._last_dvl = math.nan

    def __call__(self, channel: str, m: Any) -> None:
        t = m.t
        if channel == ch.POWER:
            self._last_power = m.total
            if self.t0 - 1e-9 <= t <= self.t1 + 1e-9:
                self.energy.append((t, m.energy))
                tr = self.loop.truth()
                self.truth.append((t, tr.velocity[0], tr.depth, tr.velocity[5], sum(tr.fin_energy),
                                   sum(abs(s - 0.3) for s in tr.fin_strouhal) / 4.0, sum(tr.fin_battery_energy)))
                self.fin_angles.append(tr.fin_angles)
            if self.trace_rate > 0.0 and t + 1e-9 >= self._next_trace:
                self._next_trace += 1.0 / self.trace_rate
                tr = self.loop.truth()
                tc = self.trace
                tc["t"].append(t)
                tc["depth"].append(tr.depth)
                tc["velocity"].append(tr.velocity[0])
                tc["velocity_dvl"].append(self._last_dvl)
                tc["yaw_rate"].append(tr.velocity[5])
                tc["x"].append(tr.position[0])
                tc["y"].append(tr.position[1])
                tc["yaw"].append(tr.euler[2])
                tc["power"].append(m.total)
                tc["st_mean"].append(sum(tr.fin_strouhal) / 4.0)
                tc["st_plan"].append(self._last_st_plan)
            return
        if channel == ch.DVL:
            if m.valid:
                self._last_dvl = m.vx
                if self.t0 <= t <= self.t1:
                    self.dvl_v.append(m.vx)
            return
        if channel == ch.DEPTH:
            if self.t0 <= t <= self.t1:
                self.depth_meas.append(m.depth_m)
            return
        if channel == ch.IMU:
            if self.t0 <= t <= self.t1:
                self.gyro_r.append(m.gyro[2])
            return
        if channel.endswith("/plan"):
            self._last_st_plan = m.st
            if self.t0 <= t <= self.t1:
                self.plan_st.append(m.st)
                self.plan_force.append(m.cost_force)
                self.plan_u[m.fin].append(m.u)


def run_scenario(sc: Scenario, mpc_planner: Callable[[int], Any] | None = None) -> dict[str, Any]:
    """Run one scenario headless and return its metrics (module docstring); ``mpc_planner``
    makes each fin's planner of an MPC mode (by fin index; default: the loop's own), and
    must be given for ``planner="oracle"``."""
    sc.check()
    if sc.planner == "oracle" and mpc_planner is None:
        raise ValueError("planner: 'oracle' needs the oracle's planner (experiments.scenario.run_scenario)")
    cfg = sc.loop_config()
    plant_cfg = plant_config(sc.plant, sc.seed, sc.current)
    start_depth = sc.depth if sc.start_depth is None else sc.start_depth
    start_v = sc.v_ref if sc.start_velocity is None else sc.start_velocity
    io = SimRobotIO(plant_cfg, depth=start_depth, velocity=start_v)
    io.plant.reset(
        position_ned=(0.0, 0.0, start_depth), body_velocity=(start_v, 0.0, 0.0, 0.0, 0.0, 0.0),
        fin_angles=(START_FIN_ANGLE,) * 4, seed=sc.seed,
    )
    stream = TelemetryStream(validate=False)
    loop = ClosedLoop(cfg, io, stream, setpoints=BodySetpoints(sc.v_ref, sc.depth, sc.yaw_rate),
                      mpc_planner=mpc_planner)
    t0, t1 = sc.settle_s, sc.settle_s + sc.window_s
    rec = _Recorder(loop, t0, t1, sc.trace_rate, cfg.mpc.st_opt, (cfg.mpc.st_low, cfg.mpc.st_high))
    stream.subscribe(rec, [ch.POWER, ch.DVL, ch.DEPTH, ch.IMU] + [ch.fin_plan(i) for i in range(4)])
    loop.run_until(t1)
    loop.close()
    return summarise(sc, rec, loop)


def summarise(sc: Scenario, rec: _Recorder, loop: ClosedLoop) -> dict[str, Any]:
    mcfg = sc.mpc
    truth = np.asarray(rec.truth)
    energy = np.asarray(rec.energy)
    span = energy[-1, 0] - energy[0, 0]
    power_est = float((energy[-1, 1] - energy[0, 1]) / span)
    power_true = float((truth[-1, 4] - truth[0, 4]) / span)
    power_electrical = float((truth[-1, 6] - truth[0, 6]) / span)
    dvl = np.asarray(rec.dvl_v)
    st = np.asarray(rec.plan_st)
    u_true = truth[:, 1]
    distance = float(np.trapezoid(u_true, truth[:, 0]))
    out: dict[str, Any] = {
        "scenario": _scenario_dict(sc),
        "power_est": power_est,
        "power_true": power_true,
        "power_electrical": power_electrical,
        "energy_per_metre": power_est * span / distance if distance > 0.0 else math.nan,
        "energy_per_metre_true": power_true * span / distance if distance > 0.0 else math.nan,
        "energy_per_metre_electrical": power_electrical * span / distance if distance > 0.0 else math.nan,
        "velocity_mean": float(u_true.mean()),
        "velocity_mae": float(np.abs(dvl - sc.v_ref).mean()) if dvl.size else math.nan,
        "velocity_mae_true": float(np.abs(u_true - sc.v_ref).mean()),
        "velocity_err_p95": float(np.percentile(np.abs(dvl - sc.v_ref), 95)) if dvl.size else math.nan,
        "velocity_within_0025": float(np.mean(np.abs(dvl - sc.v_ref) <= 0.025)) if dvl.size else math.nan,
        "depth_mae": float(np.abs(truth[:, 2] - sc.depth).mean()),
        "depth_mae_meas": float(np.abs(np.asarray(rec.depth_meas) - sc.depth).mean()),
        "depth_final": float(truth[-1, 2]),
        "yaw_rate_mean": float(truth[:, 3].mean()),
        "yaw_rate_mae": float(np.abs(np.asarray(rec.gyro_r) - sc.yaw_rate).mean()),
        "st_mae": float(np.abs(st - mcfg.st_opt).mean()) if st.size else math.nan,
        "st_in_range": float(np.mean((st >= mcfg.st_low) & (st <= mcfg.st_high))) if st.size else math.nan,
        "st_plant_mae": float(truth[:, 5].mean()),
        "force_error": float(np.mean(rec.plan_force)) if rec.plan_force else math.nan,
        **_strokes(rec, span),
        "plans": len(rec.plan_st),
        "late_plans": loop.late_plans,
        "plan_overruns": loop.plan_overruns,
        "stroke_timeouts": loop.stroke_timeouts,
    }
    if sc.trace_rate > 0.0:
        out["trace"] = {k: [float(x) for x in v] for k, v in rec.trace.items()}
    return out


def _strokes(rec: _Recorder, span: float) -> dict[str, float]:
    """Mean stroke |d_k| (rad) and rate w_k (rad/s) of the window's plans, their mean
    opening |d_1 + d_2| (rad), and how far the fins wound up (mean net turn, rad/min)."""
    u = np.asarray([x for us in rec.plan_u.values() for x in us], dtype=float).reshape(-1, 4)
    ang = np.asarray(rec.fin_angles)
    out = {"stroke": math.nan, "rate": math.nan, "opening": math.nan,
           "winding": float(np.abs(ang[-1] - ang[0]).mean() * 60.0 / span) if len(ang) > 1 and span > 0 else math.nan}
    if u.size:
        out.update(stroke=float(np.abs(u[:, :2]).mean()), rate=float(u[:, 2:].mean()),
                   opening=float(np.abs(u[:, 0] + u[:, 1]).mean()))
    return out


def _scenario_dict(sc: Scenario) -> dict[str, Any]:
    d = asdict(sc)
    d["mpc"] = {k: d["mpc"][k] for k in ("formulation", "lam_f", "lam_st", "lam_a", "lam_d", "lam_c", "lam_e",
                                         "n_samples", "c_d", "c_l")}
    d["body"] = {"layer": sc.body.layer, "thrust_gain": sc.body.thrust_gain, "velocity": d["body"]["velocity"]}
    d["baseline"] = {"inverse_model": sc.baseline.inverse_model, "frequency": sc.baseline.frequency}
    d["current"] = list(sc.current)
    return d
