"""Counterfactual replay of recorded fin plans."""

from __future__ import annotations

import math
import time

import pytest
from session_helpers import record

from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.replay import (
    counterfactual,
    parse_weights,
    predicted_power,
    recorded_config,
    recorded_drive,
    replay_config,
)
from ucat_console.control import FinMpc, MpcConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import FinPlan

SEED = 1234
CFG = MpcConfig(n_samples=64, max_iter=10, lam_st=3.0, lam_f=2.0)


def recorded_plans() -> list[tuple[str, FinPlan]]:
    """Plans made by actually running the planner, as the supervisor records them."""
    items = []
    planners = {f: FinMpc(CFG, clock=time.perf_counter) for f in range(4)}
    u_prev = {f: (0.5, -0.5, 2.0, 2.0) for f in range(4)}
    theta = {f: 0.0 for f in range(4)}
    t = 0.0
    for cycle in range(5):
        for fin in range(4):
            target = (-0.2 * (1 + cycle % 3), 0.1 * (fin - 1.5))
            v = 0.1 + 0.05 * cycle
            plan = planners[fin].plan(target, v, theta[fin], u_prev[fin], seed=SEED)
            c = plan.cost
            items.append((C.fin_plan(fin), FinPlan(
                t=t, fin=fin, mode="mpc", target=target, v_body=v, theta0=theta[fin],
                u_prev=u_prev[fin], u=plan.u, commands=plan.commands, cost_total=c.total,
                cost_force=c.force, cost_strouhal=c.strouhal_penalty, cost_amplitude=c.amplitude,
                cost_smoothness=c.smoothness, st=c.st, mean_force=c.mean_force,
                solve_time=plan.solve_time_s, late=False,
            )))
            u_prev[fin] = plan.u
            theta[fin] = plan.commands[2]
            t += 0.1
    return items


@pytest.fixture(scope="module")
def plans():
    return recorded_plans()


@pytest.fixture
def session(sessions, plans):
    [path] = record(sessions, plans, config_toml="[loop.mpc]\n" + CFG.to_toml(),
                    weights=dict(zip(("lam_f", "lam_st", "lam_a", "lam_d"), CFG.weights)))
    return path


def test_recorded_configuration_is_read_back(session, sessions):
    with SessionReader(session, sessions) as r:
        assert recorded_config(r) == CFG


@pytest.mark.parametrize("loop", ["loop.", ""])  # this version's tables, an older recording's
def test_the_recorded_mpc_and_drive_are_read_from_the_loops_tables_or_an_older_recordings(sessions, loop):
    from ucat_console.control.params import ExecutorConfig

    drive = ExecutorConfig(acceleration=40.0)
    [path] = record(sessions, [], config_toml=f"[{loop}mpc]\n{CFG.to_toml()}\n[{loop}executor]\n{drive.to_toml()}")
    with SessionReader(path, sessions) as r:
        assert recorded_config(r) == CFG and recorded_drive(r) == drive


def test_a_bad_recorded_mpc_value_is_refused_naming_its_key(sessions):
    [path] = record(sessions, [], config_toml="[loop.mpc]\nlam_st = -1.0\n")
    with SessionReader(path, sessions) as r, pytest.raises(ValueError, match=r"recorded configuration: loop\.mpc\.lam_st"):
        recorded_config(r)


def test_replay_with_the_recorded_weights_reproduces_the_recorded_plans(session, sessions, plans):
    with SessionReader(session, sessions) as r:
        res = counterfactual(r, {}, seed=SEED)
    assert res.skipped == 0 and len(res.rows) == len(plans)
    for row, (_, msg) in zip(sorted(res.rows, key=lambda x: x.t), plans):
        assert row.t == msg.t and row.fin == msg.fin
        assert row.u == msg.u == row.recorded_u
        assert row.st == msg.st == row.recorded_st
        assert row.force_error == msg.cost_force
        assert row.cost == msg.cost_total
        assert row.power == row.recorded_power


def test_replay_with_other_weights_is_the_planner_with_those_weights(session, sessions, plans):
    with SessionReader(session, sessions) as r:
        res = counterfactual(r, parse_weights("lam_st=40, lam_f=0.5"), seed=SEED)
    assert (res.config.lam_st, res.config.lam_f, res.config.lam_a) == (40.0, 0.5, CFG.lam_a)
    planner = FinMpc(CFG.replace(lam_st=40.0, lam_f=0.5))
    rows = sorted(res.rows, key=lambda x: x.t)
    for row, (_, msg) in zip(rows, plans):
        direct = planner.plan(msg.target, msg.v_body, msg.theta0, msg.u_prev, seed=SEED)
        assert row.u == direct.u and row.st == direct.cost.st
        assert row.recorded_st == msg.st
    assert any(row.u != row.recorded_u for row in rows)
    summary = res.summary()
    assert [s["fin"] for s in summary] == ["0", "1", "2", "3", "all"]
    assert summary[-1]["plans"] == len(plans)
    assert summary[-1]["st"] == pytest.approx(sum(r.st for r in rows) / len(rows))


def test_predicted_power_hand_computed():
    # P_k = 0.5 * 1000 * 0.7 * 0.02 * (0.1 w_k)^3: 0.056 W at 2 rad/s, 0.448 W at 4 rad/s;
    # strokes last 0.5/2 = 0.25 s and 0.5/4 = 0.125 s
    expected = (0.056 * 0.25 + 0.448 * 0.125) / 0.375
    assert predicted_power((0.5, -0.5, 2.0, 4.0), MpcConfig()) == pytest.approx(expected)
    assert math.isnan(predicted_power((0.5, -0.5, 0.0, 4.0), MpcConfig()))


def test_weights_parse_and_refusals():
    assert parse_weights("lam_st=2.0,lam_f=1.5") == {"lam_st": 2.0, "lam_f": 1.5}
    assert parse_weights("") == {}
    with pytest.raises(ValueError, match="lam_x: unknown weight"):
        parse_weights("lam_x=1")
    with pytest.raises(ValueError, match="lam_st: 'abc' is not a number"):
        parse_weights("lam_st=abc")
    with pytest.raises(ValueError, match="lam_st: 'nan' is not finite"):
        parse_weights("lam_st=nan")
    with pytest.raises(ValueError, match="lam_f: given twice"):
        parse_weights("lam_f=1,lam_f=2")
    with pytest.raises(ValueError, match="not name=value"):
        parse_weights("lam_f")
    with pytest.raises(ValueError, match="lam_st"):
        replay_config(MpcConfig(), {"lam_st": 500.0})  # above the parameter's range


def test_a_long_session_with_wound_up_fin_angles_replays_without_refusals(sessions):
    """The fins wind up over whole turns in a long session; the live planner plans from the
    wrapped angle, and so does the replay: nothing is refused, every plan is reproduced."""
    from ucat_console.backend.loop.planners import MpcFinPlanner, PlanInputs

    live = {f: MpcFinPlanner(CFG, seed=f) for f in range(2)}
    items = []
    for k, theta0 in enumerate((-245.3, -120.0, 88.8, 40.1 * math.pi, -13.0)):
        for fin in range(2):
            x = PlanInputs(t=0.1 * k, fins=(fin,), target=(-0.3, 0.05), v_body=0.2, theta0=theta0,
                           u_prev=(0.5, -0.5, 2.0, 2.0))
            o = live[fin](x)
            items.append((C.fin_plan(fin), FinPlan(
                t=x.t, fin=fin, mode="mpc", target=x.target, v_body=x.v_body, theta0=theta0, u_prev=x.u_prev,
                u=o.u, commands=o.commands, cost_total=o.cost_total, cost_force=o.cost_force,
                cost_strouhal=o.cost_strouhal, cost_amplitude=o.cost_amplitude,
                cost_smoothness=o.cost_smoothness, st=o.st, mean_force=o.mean_force,
                solve_time=o.solve_time, late=False, seed=o.seed,
            )))
    assert any(abs(m.theta0) > 4 * math.pi for _, m in items)  # FinMpc alone refuses these
    [path] = record(sessions, items, config_toml="[loop.mpc]\n" + CFG.to_toml(),
                    weights=dict(zip(("lam_f", "lam_st", "lam_a", "lam_d"), CFG.weights)))
    with SessionReader(path, sessions) as r:
        res = counterfactual(r, {})
    assert res.skipped == 0 and len(res.rows) == len(items)
    assert [row.u for row in res.rows] == [m.u for _, m in items]


def test_refused_plans_are_summarised_in_one_log_line(sessions, caplog):
    bad = [(C.fin_plan(0), FinPlan(
        t=0.1 * i, fin=0, mode="mpc", target=(-0.3, 0.0), v_body=float("nan") if i % 2 else 0.2, theta0=0.0,
        u_prev=(0.5, -0.5, 2.0, 2.0), u=(0.5, -0.5, 2.0, 2.0), commands=(0.5, 0.5, 0.0, 2.0), cost_total=1.0,
        cost_force=0.1, cost_strouhal=0.1, cost_amplitude=0.1, cost_smoothness=0.0, st=0.3,
        mean_force=(0.0, 0.0), solve_time=1e-4, late=False)) for i in range(10)]
    [path] = record(sessions, bad)
    with SessionReader(path, sessions) as r, caplog.at_level("WARNING"):
        res = counterfactual(r, {})
    assert res.skipped == 5 and len(res.rows) == 5
    lines = [rec for rec in caplog.records if "not replayed" in rec.getMessage()]
    assert len(lines) == 1 and "5 of 10" in lines[0].getMessage()


def test_plans_timed_by_the_drive_replay_exactly_with_the_recorded_drive(sessions):
    """A session whose planners timed strokes by the drives (its recorded [loop.executor] has the
    drives' acceleration, as every session of this version does) replays with that timing."""
    from ucat_console.control.params import ExecutorConfig

    drive = ExecutorConfig(acceleration=40.0)
    cfg = CFG.replace(centre_rate=2.0)
    planner = FinMpc(cfg, drive=drive)
    items, u_prev, theta = [], (0.5, -0.5, 2.0, 2.0), 0.0
    for k in range(6):
        target = (-0.3, 0.2 * (k % 2))
        plan = planner.plan(target, 0.2, theta, u_prev, seed=SEED)
        c = plan.cost
        items.append((C.fin_plan(0), FinPlan(
            t=0.5 * k, fin=0, mode="mpc", target=target, v_body=0.2, theta0=theta, u_prev=u_prev, u=plan.u,
            commands=plan.commands, cost_total=c.total, cost_force=c.force, cost_strouhal=c.strouhal_penalty,
            cost_amplitude=c.amplitude, cost_smoothness=c.smoothness, st=c.st, mean_force=c.mean_force,
            solve_time=0.0, late=False)))
        u_prev, theta = plan.u, plan.commands[2]
    [path] = record(sessions, items, config_toml="[loop.mpc]\n" + cfg.to_toml() + "\n[loop.executor]\n" + drive.to_toml())
    with SessionReader(path, sessions) as r:
        res = counterfactual(r, {}, seed=SEED)
    assert [row.u for row in sorted(res.rows, key=lambda x: x.t)] == [m.u for _, m in items]


def test_the_summary_lists_the_fins_in_order_whatever_order_their_plans_came_in():
    from ucat_console.backend.sessions.replay import ReplayResult, ReplayRow

    u = (0.5, -0.5, 2.0, 2.0)
    rows = tuple(ReplayRow(0.1 * k, fin, "mpc", u, 0.3, 0.1, 1.0, 0.5, u, 0.3, 0.1, 1.0, 0.5)
                 for k, fin in enumerate((0, 3, 1, 2, 3)))
    summary = ReplayResult(MpcConfig(), rows, 0).summary()
    assert [s["fin"] for s in summary] == ["0", "1", "2", "3", "all"]
    assert [s["plans"] for s in summary] == [1, 1, 1, 2, 5]
