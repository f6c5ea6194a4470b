"""A closed-loop run on the simulated robot, recorded as numbers, for the trajectory
equivalence test (``test_trajectory_fixture.py``).

``python tests/backend/loop/trajectory.py`` writes ``fixtures/trajectory_<mode>.npz`` from
the code as it stands. The fixtures kept in the repository hold the loop to the trajectory
of the code before a change that must not move it: they were written before the loop's
per-sample path was compiled (the kernels, then the whole per-sample core), which left the
trajectory as it was, and written again when the MPC's refinement changed (its line search
and the refinement of the best samples only), which changes the plans by design: then the
baseline scenario's first six seconds, before it switches to the MPC, stayed the same to
1e-12. They were written again when the designed body layer became the default (its loops,
references and allocation; each stroke's profile velocity timed to its planned duration;
the baseline's fin-model inverse; the MPC's drive timing and centred cycles in
the shipped ``sim-tuned``), which changes every trajectory by design, and adds the
channels ``body/allocation`` and ``fin/N/cycle``. They were written again when the IMU's
acceleration went from standard gravities to m/s^2: every other channel stayed the same to
rtol 1e-9, and the IMU's acceleration is the former one times 9.80665 to rtol 1e-9. They
were written again when the designed layer's velocity loop began to close on the low-passed
DVL speed (``BodyConfig.speed_filter``), which changes every trajectory by design: with
the low-pass set to 0 the run gave the former fixtures to rtol 1e-9. They were written again
when the simulated fins became the energy-conserving plate (``backend/sim/plate.py``, with
``sim-tuned``'s thrust gain identified on it), which changes every trajectory by design: the
plant's forces changed, not the controller. They were written again when the designed heading
loop's bandwidth rose to 0.5 rad/s and the depth loop's integral zero to 3/8 of its
bandwidth (``control.body_design``), which changes every trajectory by design. They were
written again when the designed layer began to feed the fins' shortfall forward (each running
cycle's target against its plan's force, corrected by the fin's last executed cycle) and
stopped making yaw with fins pushing against the travel, which changes the MPC scenarios'
trajectories by design (the baseline scenario's stayed the same to rtol 1e-9); and again when,
before a speed is measured, the layer stopped making up surge and let the fins push either
way for yaw, which moves the MPC scenarios' first steps by design. They were written again
when the MPC's centred cycle became the one of least cost among the solver's and a grid's
(``MpcConfig.centre_grid``), which changes the MPC's plans by design: with ``centre_grid = 0``
the run gave the former fixtures to rtol 1e-9, and the baseline scenario's first six seconds,
before it switches to the MPC, stayed the same. They were written again when the body layer
was fitted to the baseline's planners (its loops scheduled on the fins' cycle periods under
the baseline only, ``Mode.schedules_body``; its allocation limited to the beat's peak force,
``Mode.fin_force``), which changes the baseline's part of every scenario by design: the
``mpc`` scenario stayed the same to rtol 1e-9, and so did the ``mpc_sync`` scenario's first
six seconds, before it switches to the baseline. They were written again when the designed
heading loop's bandwidth rose from 1 / (2.3 tau) to 1 / (1.7 tau) (``HEADING_FACTOR``,
``control.body_design``), which changes the heading loop's gains and so every trajectory by
design. They were written again when the baseline's fins began to beat in phase (each cycle
shortened by a share of its fin's lag behind the others' beats, ``BaselineConfig.phase_gain``;
the plans carry the lag, ``FinPlan.lag``), which changes the baseline's part of every scenario by
design: the ``mpc`` scenario stayed the same to rtol 1e-9 but for the plans' new column, and so
did the ``mpc_sync`` scenario's first six seconds, before it switches to the baseline. The
``mpc`` scenario's was written again when the shipped ``sim-tuned`` limited the MPC's cycles to
1 s (``MpcConfig.max_cycle``, 1.5 s before), which changes its plans by design with no change of
code; the other two scenarios stayed the same to rtol 1e-9. They were written again when the
MPC's fins across the hull from each other began to end their cycles together
(``MpcConfig.align``, 0.2 in the shipped ``sim-tuned``; the plans carry the duration asked,
``FinPlan.align``), which changes the MPC's plans by design: the ``baseline`` scenario's first
six seconds, before it switches to the MPC, stayed the same to rtol 1e-9 but for the plans'
new column.

Each scenario starts the simulated U-CAT at 1 m depth surging at 0.2 m/s with the
configuration of the shipped ``sim-tuned``, runs one mode with a velocity, depth and yaw
rate setpoint, switches mode half way (bumpless hand-over), and records every message of
every channel (numbers only: each message flattened into one row per channel).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from ucat_console import shipped
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.commands import SetMode
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.config import AppConfig
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import TelemetryStream
from ucat_console.telemetry.messages import FinPlan

TUNED = shipped.config_path("sim-tuned")
FIXTURES = Path(__file__).resolve().parent / "fixtures"

#: (first mode, mode after the switch)
SCENARIOS = {"mpc": "mpc_sync", "mpc_sync": "baseline", "baseline": "mpc"}
SWITCH_AT = 6.0
DURATION = 12.0


def _numbers(value: object, out: list[float]) -> None:
    if dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            _numbers(getattr(value, f.name), out)
    elif isinstance(value, (tuple, list)):
        for v in value:
            _numbers(v, out)
    elif isinstance(value, bool):
        out.append(float(value))
    elif isinstance(value, (int, float)):
        out.append(float(value))
    elif value is None:
        out.append(math.nan)
    # text (mode names, messages) is left out


def run(mode: str) -> dict[str, np.ndarray]:
    """Every channel's messages of the scenario starting in ``mode``, one row each."""
    app = AppConfig.from_toml(TUNED)
    rows: dict[str, list[list[float]]] = {}

    def record(channel: str, message: object) -> None:
        if channel == "events":
            return  # their data carries wall-clock solve times
        if isinstance(message, FinPlan):
            message = dataclasses.replace(message, solve_time=0.0)  # wall-clock time
        row: list[float] = []
        _numbers(message, row)
        rows.setdefault(channel, []).append(row)

    stream = TelemetryStream()
    stream.subscribe(record)
    io = SimRobotIO(depth=1.0, velocity=0.2)
    loop = ClosedLoop(app.loop.replace(mode=mode), io, stream,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.2, yaw_rate=0.05))
    loop.run_until(SWITCH_AT)
    loop.submit(SetMode(SCENARIOS[mode]))
    loop.run_until(DURATION)
    truth = io.truth()
    loop.close()
    out = {ch.replace("/", "."): np.array(r, dtype=float) for ch, r in rows.items()}
    t_row: list[float] = []
    _numbers(truth, t_row)
    out["truth"] = np.array(t_row)
    out["counters"] = np.array([loop.plans_made, loop.late_plans, loop.stroke_timeouts], dtype=float)
    return out


if __name__ == "__main__":
    FIXTURES.mkdir(exist_ok=True)
    for m in (sys.argv[1:] or list(SCENARIOS)):
        np.savez_compressed(FIXTURES / f"trajectory_{m}.npz", **run(m))
        print("wrote", FIXTURES / f"trajectory_{m}.npz")
