"""Seeking efficiency (docs/seek.md): the configuration, the search's bounds, the run on the
console (journal entries, a candidate off its tracking bands rejected and the best put back,
a disarm or a failsafe stopping it at once, keep / revert, a drift seeking again) and the
headless command on the simulated robot."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any, Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import Console, console_config, wait_for

from ucat_console.backend.access import LOCAL, AccessDenied
from ucat_console.backend.review.metrics import ELECTRICAL, FIGURES, Estimate, TableRow
from ucat_console.backend.seek.config import SeekConfig, SeekParam
from ucat_console.backend.seek.search import Dimension, Search
from ucat_console.backend.supervisor import CommandRefused
from ucat_console.backend.supervisor import seek_run
from ucat_console.cli import main
from ucat_console.config import AppConfig

pytest.importorskip("optuna")


# ---------------------------------------------------------------- configuration and search
def test_the_configuration_reads_its_params_tables_and_names_a_bad_key(tmp_path: Path) -> None:
    f = tmp_path / "c.toml"
    f.write_text('[seek]\nwindow_s = 20.0\n[[seek.params]]\nname = "mpc.st_opt"\nlo = 0.25\nhi = 0.4\n'
                 '[[seek.params]]\nname = "baseline.frequency"\nlo = 1.0\nhi = 3.0\n')
    cfg = AppConfig.from_toml(f)
    assert cfg.seek.window_s == 20.0
    assert cfg.seek.params == (SeekParam("mpc.st_opt", 0.25, 0.4), SeekParam("baseline.frequency", 1.0, 3.0))
    again = tmp_path / "again.toml"
    again.write_text(cfg.to_toml())
    assert AppConfig.from_toml(again).seek == cfg.seek
    f.write_text('[[seek.params]]\nname = "mpc.st_opt"\nlo = 0.4\nhi = 0.25\n')
    with pytest.raises(ValueError, match=r"seek.params\[0\].lo/hi: need lo < hi"):
        AppConfig.from_toml(f)
    f.write_text('[[seek.params]]\nname = "mpc.st_opt"\nlow = 0.1\n')
    with pytest.raises(ValueError, match=r"seek.params\[0\].low: unknown key"):
        AppConfig.from_toml(f)
    with pytest.raises(ValueError, match="mpc.lam_f: not one of the seeker's parameters"):
        SeekConfig().only(("mpc.lam_f",))
    with pytest.raises(ValueError, match="mpc.st_opt given more than once"):
        SeekConfig(params=(SeekParam(), SeekParam()))


@settings(max_examples=15, deadline=None)
@given(lo=st.floats(-50.0, 50.0), width=st.floats(1e-3, 100.0), seed=st.integers(0, 2**31 - 1),
       integer=st.booleans(), results=st.lists(st.one_of(st.none(), st.floats(0.0, 1e3)), min_size=12, max_size=12))
def test_every_suggestion_is_inside_its_bounds(lo: float, width: float, seed: int, integer: bool,
                                               results: list[float | None]) -> None:
    hi = lo + width + (2.0 if integer else 0.0)
    dims = (Dimension("a.x", lo, hi, integer), Dimension("b.y", 0.2, 0.45))
    search = Search(dims, seed, startup=3)
    for r in results:  # past the random start: the model's suggestions too, after failures
        trial, values = search.ask()
        assert set(values) == {"a.x", "b.y"}
        assert all(d.lo <= values[d.name] <= d.hi for d in dims)
        assert isinstance(values["a.x"], int) == integer
        search.tell(trial, r)


def test_the_same_seed_suggests_the_same() -> None:
    dims = (Dimension("mpc.st_opt", 0.2, 0.45),)
    a, b = Search(dims, 7), Search(dims, 7)
    assert [a.ask()[1] for _ in range(4)] == [b.ask()[1] for _ in range(4)]


# ---------------------------------------------------------------- on the console
SEEK = SeekConfig(params=(SeekParam("mpc.st_opt", 0.2, 0.45),), settle_s=0.5, window_s=1.0,
                  max_candidates=6, confirm=0, seed=1, startup=2, drift_check=False)


def seek_console(make_console: Callable[..., Console], **seek: Any) -> Console:
    cfg = console_config(base="sim-tuned")
    c = make_console(cfg.replace(seek=SEEK.replace(**seek)))
    c.sup.set_setpoints(LOCAL, velocity=0.2, depth=0.5)
    c.sup.arm(LOCAL)
    c.sup.step(1.0)
    return c


def fake_rows(monkeypatch: pytest.MonkeyPatch, sup: Any, energy: Callable[[float, float], float],
              off_track: Callable[[float], bool] = lambda v: False) -> None:
    """The windows' figures made from the value of mpc.st_opt in force when the window ends
    (energy per metre ``energy(st_opt, t1)`` +- 1; a speed error of 0.5 m/s where
    ``off_track``): what each candidate is judged on, the console around it unchanged."""

    def row(data: Any, t0: float, t1: float, cfg: Any, label: str = "", **kw: Any) -> TableRow:
        v = sup.param_value("mpc.st_opt")
        e = energy(v, t1)
        figures = {k: Estimate(math.nan, math.nan, math.nan) for k in FIGURES}
        figures.update(energy_per_metre=Estimate(e, e - 1.0, e + 1.0), speed=Estimate(0.2, 0.19, 0.21),
                       speed_mae=Estimate(0.5 if off_track(v) else 0.01, 0.0, 0.0),
                       depth_mae=Estimate(0.01, 0.0, 0.0), heading_mae=Estimate(0.01, 0.0, 0.0))
        return TableRow(label, t0, t1, 10, figures, source=ELECTRICAL, source_label="electrical (battery)")

    monkeypatch.setattr(seek_run, "table_row", row)


def run_until(sup: Any, done: Callable[[], bool], limit: float = 60.0) -> None:
    t_end = sup.loop.time + limit
    while not done() and sup.loop.time < t_end:
        sup.step(0.25)
    assert done()


def test_each_candidate_is_journalled_and_one_off_its_tracking_band_is_rejected_and_the_best_put_back(
        make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    c = seek_console(make_console)
    sup = c.sup
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * v, off_track=lambda v: v < 0.28)  # the lowest values: off track
    with pytest.raises(AccessDenied):
        sup.start_seek(7, ("mpc.st_opt",))  # a viewer
    with pytest.raises(CommandRefused, match="mpc.lam_f: not one of the seeker's parameters"):
        sup.start_seek(LOCAL, ("mpc.lam_f",))
    run = sup.start_seek(LOCAL, ("mpc.st_opt",))
    with pytest.raises(CommandRefused, match="a manoeuvre or a seek is running"):
        sup.start_seek(LOCAL)
    rejected_then: dict[int, float] = {}  # candidates measured at a rejection -> the value in force after it

    def watch() -> bool:
        if run.phase == "recover":
            rejected_then.setdefault(len(run.candidates), sup.param_value("mpc.st_opt"))
        return run.finished

    run_until(sup, watch)
    assert run.reason == "completed" and len(run.candidates) == SEEK.max_candidates
    cands = run.candidates
    assert cands[0].values == (("mpc.st_opt", 0.3),) and cands[0].accepted
    for cand in cands:
        (v,) = [x for _, x in cand.values]
        assert 0.2 <= v <= 0.45
        assert cand.accepted == (v >= 0.28)
    rejected = [cand for cand in cands if not cand.accepted]
    assert rejected, "the seed's candidates include one off its tracking band"
    assert all(cand.verdict.startswith("rejected: speed error 0.5 m/s") for cand in rejected)
    # after a rejection the best so far is back in force before the next candidate
    assert rejected_then
    for n, in_force in rejected_then.items():
        best_before = min((x for cand in cands[:n] if cand.accepted for _, x in cand.values))
        assert in_force == pytest.approx(best_before)
    accepted = [cand for cand in cands if cand.accepted]
    assert run.best is min(accepted, key=lambda cand: cand.energy.value)
    assert sup.param_value("mpc.st_opt") == dict(run.best.values)["mpc.st_opt"]  # the best kept
    journal = [e for e in sup.journal() if e.key.startswith("seek #")]
    assert [e.key for e in journal] == [f"seek #{k}" for k in range(len(cands))]
    assert all(("J/m" in e.new) and (("accepted" in e.new) == cands[k].accepted) for k, e in enumerate(journal))
    changes = [e for e in sup.journal() if e.key == "mpc.st_opt"]
    assert len(changes) >= len(cands) - 1  # each candidate's change through the tuning, journalled
    events = [e for e in c.events if e.source == "seek" and e.code == "candidate"]
    assert [e.data["accepted"] for e in events] == [cand.accepted for cand in cands]
    view = sup.state().seek
    assert view is not None and view.finished and view.candidates == len(cands)
    assert view.best == run.best.values and view.best_energy[0] == run.best.energy.value


def test_the_search_best_are_measured_again_and_the_least_second_measure_is_the_best(
        make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    """A first measure that was lucky (the least of the search by far) does not win when its
    second measure is what its values give: the least second measure does."""
    c = seek_console(make_console, confirm=3)
    sup = c.sup
    measured: dict[float, int] = {}
    lucky: list[float] = []  # the value whose first measure is low by chance

    def energy(v: float, t: float) -> float:
        n = measured[v] = measured.get(v, 0) + 1
        if not lucky and v != 0.3:
            lucky.append(v)
        return 1.0 if (n == 1 and lucky and v == lucky[0]) else 10.0 + 100.0 * abs(v - 0.35)

    fake_rows(monkeypatch, sup, energy)
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: run.finished)
    first = [cand for cand in run.candidates if cand.confirms is None]
    again = [cand for cand in run.candidates if cand.confirms is not None]
    assert len(first) == SEEK.max_candidates and len(again) == 3
    ranked = sorted(first, key=lambda cand: cand.energy.value)
    assert [cand.confirms for cand in again] == [cand.index for cand in ranked[:3]]
    assert ranked[0].values == ((("mpc.st_opt", lucky[0]),)) and ranked[0].energy.value == 1.0
    assert all(cand.values == first[cand.confirms].values for cand in again)
    assert run.best in again and run.best.energy.value == min(cand.energy.value for cand in again)
    assert run.best.values != ranked[0].values  # the lucky one, measured again, lost
    assert sup.param_value("mpc.st_opt") == dict(run.best.values)["mpc.st_opt"]
    events = [e for e in c.events if e.source == "seek" and e.code == "candidate"]
    assert [e.data["confirms"] for e in events] == [cand.confirms for cand in run.candidates]
    assert f"#{again[0].confirms} again" in events[len(first)].message


def test_when_no_second_measure_is_accepted_the_first_measures_best_stands(
        make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    c = seek_console(make_console, confirm=2)
    sup = c.sup
    done: list[bool] = []  # the search's candidates all measured: every window after is off track

    def energy(v: float, t: float) -> float:
        return 100.0 * abs(v - 0.35)

    fake_rows(monkeypatch, sup, energy, off_track=lambda v: bool(done))
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: len(run.candidates) >= SEEK.max_candidates)
    best = run.best
    done.append(True)
    run_until(sup, lambda: run.finished)
    again = [cand for cand in run.candidates if cand.confirms is not None]
    assert len(again) == 2 and not any(cand.accepted for cand in again)
    assert run.best is best and sup.param_value("mpc.st_opt") == dict(best.values)["mpc.st_opt"]


@pytest.mark.parametrize("on_stop", ["revert", "best"])
def test_a_disarm_stops_it_at_once_and_leaves_what_on_stop_says(make_console: Callable[..., Console],
                                                                 monkeypatch: pytest.MonkeyPatch,
                                                                 on_stop: str) -> None:
    c = seek_console(make_console, on_stop=on_stop)
    sup = c.sup
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * abs(v - 0.35))
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: len(run.candidates) >= 3)
    sup.disarm(LOCAL)
    assert run.finished and run.reason == "the robot is disarmed"  # no chunk needed
    expected = 0.3 if on_stop == "revert" else dict(run.best.values)["mpc.st_opt"]
    assert sup.param_value("mpc.st_opt") == pytest.approx(expected)
    n = len(run.candidates)
    sup.step(3.0)
    assert len(run.candidates) == n  # nothing more happens


def test_a_failsafe_stops_it_at_once(make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    c = seek_console(make_console)
    sup = c.sup
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * abs(v - 0.35))
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: len(run.candidates) >= 2)
    sup.inject_leak(LOCAL, True)  # the detector is read by its own thread, in wall time

    def leak_active() -> bool:
        sup.step(0.05)
        return "leak" in sup.state().failsafes

    wait_for(leak_active, what="the leak failsafe")
    assert run.finished and run.reason.startswith("failsafe leak")  # in the pass that saw it
    assert sup.param_value("mpc.st_opt") == pytest.approx(0.3)  # on_stop revert: the values it found


def test_the_pilot_stops_it_keeping_the_best_or_reverting(make_console: Callable[..., Console],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    c = seek_console(make_console)
    sup = c.sup
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * abs(v - 0.35))
    for keep in (True, False):
        run = sup.start_seek(LOCAL)
        run_until(sup, lambda: len(run.candidates) >= 3)
        with pytest.raises(AccessDenied):
            sup.stop_seek(7, keep)
        start = run.start_values["mpc.st_opt"]
        sup.stop_seek(LOCAL, keep)
        assert run.finished and run.reason == "stopped by console"
        assert sup.param_value("mpc.st_opt") == (dict(run.best.values)["mpc.st_opt"] if keep else start)
    with pytest.raises(CommandRefused, match="none is running"):
        sup.stop_seek(LOCAL, True)


def test_a_drift_outside_the_best_interval_seeks_again(make_console: Callable[..., Console],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    c = seek_console(make_console, drift_check=True, max_candidates=3, max_seeks=2)
    sup = c.sup
    changed: list[float] = []  # the loop time from which the robot needs 20 J/m more

    def energy(v: float, t: float) -> float:
        return 100.0 * abs(v - 0.35) + (20.0 if changed and t > changed[0] else 0.0)

    fake_rows(monkeypatch, sup, energy)
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: run.phase == "watch")
    assert run.searches == 1 and not run.finished and run.time_left() == 0.0
    sup.step(2.0)  # a window or more of the best, inside its interval: no drift
    assert run.searches == 1
    best = run.best.values
    changed.append(sup.loop.time)
    run_until(sup, lambda: run.searches == 2)
    (drift,) = [e for e in c.events if e.source == "seek" and e.code == "drift"]
    assert "seeking again" in drift.message
    run_until(sup, lambda: run.phase == "watch" or run.finished)
    second = [cand for cand in run.candidates if cand.search == 1]
    assert len(second) == 3 and second[0].values == best  # the second search starts from the best


# ---------------------------------------------------------------- the command line
def test_a_headless_seek_on_the_simulated_robot_finds_a_best_with_its_interval(tmp_path: Path, capsys) -> None:
    out_json = tmp_path / "seek.json"
    code = main(["seek", "--config", "sim-tuned", "--velocity", "0.2", "--depth", "1", "--params", "mpc.st_opt",
                 "--candidates", "4", "--confirm", "1", "--seed", "2", "--settle", "3", "--window", "10", "--fast",
                 "--json", str(out_json), "--sessions-dir", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0, out
    lines = re.findall(r"seek #(\d) \(mpc.st_opt ([0-9.]+)\): ([0-9.]+) J/m \[([0-9.]+), ([0-9.]+)\]", out)
    assert [int(k) for k, *_ in lines] == [0, 1, 2, 3]
    assert re.search(r"best: #\d mpc.st_opt [0-9.]+: energy per metre [0-9.]+ J/m \[[0-9.]+, [0-9.]+\]", out)
    data = json.loads(out_json.read_text())
    assert data["reason"] == "completed" and len(data["candidates"]) == 4 + 1
    assert all(0.2 <= cand["values"]["mpc.st_opt"] <= 0.45 for cand in data["candidates"])
    *first, again = data["candidates"]
    energy = {c["index"]: c["figures"]["energy_per_metre"]["value"] for c in first if c["accepted"]}
    assert again["confirms"] == min(energy, key=energy.get) and again["accepted"]  # the search's best, again
    assert again["values"] == first[again["confirms"]]["values"]
    best = data["best"]
    assert best is not None and best["index"] == again["index"]  # the only second measure
    e = best["energy_per_metre"]
    assert e["lo"] <= e["value"] <= e["hi"]
    start = data["candidates"][0]
    assert start["values"] == data["start"] and start["accepted"]
    assert energy[again["confirms"]] <= start["figures"]["energy_per_metre"]["hi"]
    assert "mpc.lam_f: not one of the seeker's parameters" not in out
    assert main(["seek", "--params", "mpc.lam_f", "--fast"]) == 2
    assert "mpc.lam_f: not one of the seeker's parameters" in capsys.readouterr().err


def test_bounds_outside_a_parameters_own_range_or_a_candidate_its_block_refuses_never_reach_the_loop(
        make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    params = (SeekParam("mpc.st_opt", 0.001, 0.3), SeekParam("mpc.formulation", 0.0, 1.0),
              SeekParam("mpc.st_low", 0.2, 0.6))
    c = seek_console(make_console, params=params, max_candidates=8, startup=8)
    sup = c.sup
    with pytest.raises(CommandRefused, match=r"mpc.st_opt: the bounds \[0.001, 0.3\] leave the parameter's own "
                                             r"range \[0.01, 2.0\]"):
        sup.start_seek(LOCAL, ("mpc.st_opt",))
    with pytest.raises(CommandRefused, match="mpc.formulation is not a number"):
        sup.start_seek(LOCAL, ("mpc.formulation",))
    assert sup.seek_run is None
    fake_rows(monkeypatch, sup, lambda v, t: 50.0)
    high = sup.param_value("mpc.st_high")
    in_force: list[float] = []
    run = sup.start_seek(LOCAL, ("mpc.st_low",))
    run_until(sup, lambda: in_force.append(sup.param_value("mpc.st_low")) or run.finished, limit=120.0)
    refused = [cand for cand in run.candidates if cand.verdict.startswith("refused")]
    assert refused and all(dict(cand.values)["mpc.st_low"] >= high for cand in refused)
    assert "st_low/st_high: need st_low < st_high" in refused[0].verdict
    assert max(in_force) < high  # the MPC's own check kept every refused one out of the loop
    assert all(cand.accepted for cand in run.candidates if dict(cand.values)["mpc.st_low"] < high)


def test_it_stops_when_its_pilot_is_gone(make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    c = make_console(console_config(base="sim-tuned").replace(seek=SEEK))
    sup = c.sup
    sup.client_connected(1)
    assert sup.take_control(1, sup.access.token)
    sup.arm(1)
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * abs(v - 0.35))
    run = sup.start_seek(1)
    run_until(sup, lambda: len(run.candidates) >= 2)
    sup.client_disconnected(1)
    sup.step(0.2)
    assert run.finished and run.reason in ("its pilot is no longer the pilot", "failsafe pilot_gone")
    assert sup.param_value("mpc.st_opt") == pytest.approx(0.3)


def test_a_candidate_under_which_the_robot_loses_its_track_is_rejected_before_the_failsafe(
        make_console: Callable[..., Console], monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    c = seek_console(make_console, max_candidates=8, settle_s=2.0, window_s=4.0, abort_s=1.0)
    sup = c.sup
    fake_rows(monkeypatch, sup, lambda v, t: 100.0 * v)
    lost: dict[str, float] = {}  # since when the robot is off its track under the present value

    def off_track(now: float) -> tuple[float, str]:  # the lowest values cannot hold the speed
        if sup.param_value("mpc.st_opt") >= 0.28:
            lost.clear()
            return 0.0, ""
        since = lost.setdefault("since", now)
        return now - since, "speed -0.06 m/s"

    sup.seek_host = dataclasses.replace(sup.seek_host, off_track=off_track)
    run = sup.start_seek(LOCAL)
    run_until(sup, lambda: run.finished, limit=120.0)
    assert run.reason == "completed" and len(run.candidates) == 8
    low = [cand for cand in run.candidates if dict(cand.values)["mpc.st_opt"] < 0.28]
    assert low, "the search tried no value that loses the track"
    for cand in low:
        assert cand.verdict.startswith("rejected: lost its track (speed -0.06 m/s off its expected response")
        assert cand.energy is None
    ends = {ev.data["index"]: ev.data["t1"] - ev.data["t0"] for ev in c.events if ev.source == "seek" and ev.code == "candidate"}
    for cand in low:  # ended a second into it, not after its settle and window
        assert ends[cand.index] < 2.0 + 4.0 - 1.0
    assert dict(run.best.values)["mpc.st_opt"] >= 0.28
    assert "tracking" not in sup.state().failsafes
    assert sup.param_value("mpc.st_opt") == dict(run.best.values)["mpc.st_opt"]


def test_an_abort_time_not_shorter_than_the_tracking_failsafes_is_refused(
        make_console: Callable[..., Console]) -> None:
    c = seek_console(make_console, abort_s=10.0)  # the tracking failsafe's timeout: 10 s
    with pytest.raises(CommandRefused, match=r"seek.abort_s \(10 s\) must be shorter than the tracking failsafe"):
        c.sup.start_seek(LOCAL)
