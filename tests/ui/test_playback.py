"""The review panel: playback reproduces the live plots; the controls from code; markers
beside the file; counterfactual replay from the panel; a session split into parts reviewed
as one.

A short simulated run (headless, simulated clock) is recorded once per module by the
supervisor's recorder while a plot feeder takes the live stream; a second one, recorded in
parts of one second, is reviewed across its part boundaries.
"""

from __future__ import annotations

import hashlib
import math
import statistics
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import viser
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.config import AppConfig
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.markdown import esc
from ucat_console.ui.playback import PlaybackPanel, StreamSampler
from ucat_console.ui.plots import CHANNELS as PLOT_CHANNELS
from ucat_console.ui.plots import COLUMNS, PlotFeeder

PLOT_RATE = 10.0
CAPACITY = 1000
MARK_AT = 2.0  # s of simulated time when the operator's marker is added


@dataclass
class Run:
    directory: Path
    path: Path
    live: np.ndarray  # the live plot rows
    plans: list  # the live FinPlans, in order
    weights: dict[str, float]

    @property
    def session_id(self) -> str:
        return files.parse_part_name(self.path)[0]


def live_sampler() -> StreamSampler:
    return StreamSampler(PlotFeeder(CAPACITY), 1.0 / PLOT_RATE)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    d = tmp_path_factory.mktemp("sessions")
    sup = Console(AppConfig(), d).sup
    try:
        sup.set_setpoints(LOCAL, velocity=0.2)
        sampler = live_sampler()
        plans: list = []
        sup.stream.subscribe(sampler.on_message, PLOT_CHANNELS)
        sup.stream.subscribe(lambda c, m: plans.append(m), [ch.fin_plan(i) for i in range(ch.N_FINS)])
        sup.start_recording(LOCAL, "review test run")
        sup.arm(LOCAL)
        sup.step(MARK_AT)
        sup.add_marker(LOCAL, "half way")
        sup.step(2.0)
        [path] = sup.stop_recording(LOCAL)
        sampler.flush()
        t = sup.tuning()["mpc"]
        weights = {"lam_f": t.lam_f, "lam_st": t.lam_st, "lam_a": t.lam_a, "lam_d": t.lam_d}
    finally:
        sup.stop()
    live = sampler.feeder.buffer.last(CAPACITY)
    assert len(live) > 20 and plans
    return Run(d, path, live, plans, weights)


@pytest.fixture
def panel(server: viser.ViserServer, run: Run):
    p = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=run.directory,
                      plot_rate=PLOT_RATE, max_history=60.0, history=lambda: 60.0)
    yield p
    p.stop()
    for f in run.directory.glob("*.markers.json"):  # the module's session stays unmarked
        f.unlink()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_playback_reproduces_the_live_plot_values(run: Run) -> None:
    """Every plot series, row by row, equal to what the live stream gave (NaN where live had NaN)."""
    from ucat_console.backend.sessions.player import Player

    sampler = live_sampler()
    stream = TelemetryStream()
    stream.subscribe(sampler.on_message, PLOT_CHANNELS)
    with SessionReader(run.path, run.directory) as reader:
        player = Player(reader, stream, speed=5.0)
        while not player.at_end:
            player.advance(0.05)  # the playing thread's steps, run here
        player.close()
    sampler.flush()
    played = sampler.feeder.buffer.last(CAPACITY)
    assert played.shape == run.live.shape
    for j, name in enumerate(COLUMNS):
        np.testing.assert_array_equal(played[:, j], run.live[:, j], err_msg=name)
    # the series are not empty: body state, plans and both powers were all plotted
    for name in ("depth", "velocity", "st0", "p_total", "e_total", "e_mean", "e_energy_per_metre"):
        assert np.isfinite(run.live[:, COLUMNS.index(name)]).sum() > 5, name


def test_the_browser_lists_the_session_with_its_notes(panel: PlaybackPanel, run: Run) -> None:
    assert panel.choice.options == (run.session_id,)  # sessions, not their files
    assert panel.choice.value == run.session_id
    assert f"| {run.session_id} | 1 |" in panel.browser.content  # the table shows the part
    assert "review test run" in panel.browser.content
    assert panel.repair_button.disabled  # nothing truncated
    assert panel.play_button.disabled  # nothing open yet
    assert panel.act(panel.play) is False and "no session open" in panel.messages[-1]


def test_controls_open_seek_speed_step_event_marker(panel: PlaybackPanel, run: Run) -> None:
    before = digest(run.path)
    assert panel.act(lambda: panel.open(run.path.name))
    p = panel.player
    assert p is not None and not p.playing and not panel.play_button.disabled
    with SessionReader(run.path, run.directory) as r:
        start, end = r.start, r.end
        body_times = [m.t for _, m in r.messages([ch.BODY_STATE])]
    assert panel.timeline.max == pytest.approx(end - start)

    # seek: the position, and the review plots rebuilt up to it
    assert panel.act(lambda: panel.seek(1.0))
    assert p.position == pytest.approx(start + 1.0)
    rows = panel.feeder.buffer.last(CAPACITY)
    assert rows[-1, 0] == pytest.approx(max(t for t in body_times if t <= start + 1.0 + 1e-9))
    assert rows[0, 0] <= start + 0.1 + 1e-9  # the history window before the position

    # speed bounds: refused with a message, nothing changed
    assert panel.act(lambda: panel.set_speed(2.0)) and p.speed == 2.0
    for bad in (0.05, 6.0):
        assert panel.act(lambda: panel.set_speed(bad)) is False
        assert "out of range" in panel.messages[-1] and "Refused" in panel.message.content
        assert p.speed == 2.0 and panel.speed.value == 2.0

    # frame step: the next / previous body state
    k = max(i for i, t in enumerate(body_times) if t <= p.position + 1e-9)
    assert panel.act(lambda: panel.step(1))
    assert p.position == pytest.approx(body_times[k + 1])
    assert panel.act(lambda: panel.step(-1))
    assert p.position == pytest.approx(body_times[k])

    # next event: the operator's marker recorded at MARK_AT is among the events after t = 1
    panel.seek(1.0)
    seen = []
    while (what := panel.next_event()) is not None:
        seen.append(what)
    assert any(getattr(e, "code", "") == "marker" and "half way" in e.message for e in seen)
    assert p.position >= start + 1.0

    # a review marker: saved in the sidecar, the MCAP untouched
    panel.seek(3.0)
    m = panel.add_marker("fin 2 looks late")
    sidecar = run.directory / f"{p.reader.session_id}.markers.json"
    assert sidecar.is_file() and "fin 2 looks late" in sidecar.read_text()
    assert m.t == pytest.approx(start + 3.0)
    assert digest(run.path) == before
    panel.seek(2.5)
    assert panel.next_event() == m  # review markers are jump targets too

    panel.close_session()
    assert panel.player is None and panel.play_button.disabled


def test_playing_moves_the_position_and_pauses(panel: PlaybackPanel, run: Run) -> None:
    panel.open(run.path.name)
    p = panel.player
    assert p is not None
    panel.set_speed(5.0)
    panel.play()
    # wait for the player's thread (no timing asserted: only that it moves and stops)
    wait_for(lambda: p.position > p.start + 0.5, what="the player moving on")
    panel.pause()
    pos = p.position
    assert pos > p.start + 0.5 and not p.playing
    assert panel.tick_errors == 0  # the review scene and plots were pushed without error
    panel._sync_inputs()
    assert panel.timeline.value == pytest.approx(pos - p.start)


def test_counterfactual_with_the_recorded_weights_reproduces_the_recorded_st(
    panel: PlaybackPanel, run: Run
) -> None:
    panel.open(run.path.name)
    text = ",".join(f"{k}={v!r}" for k, v in run.weights.items())
    panel.weights.value = text
    assert panel.act(lambda: panel.run_counterfactual(panel.weights.value))
    res = panel.wait_replay()  # it runs in a child process
    assert res is not None and res.skipped == 0
    assert len(res.rows) == len(run.plans)
    for row, plan in zip(sorted(res.rows, key=lambda r: (r.t, r.fin)), sorted(run.plans, key=lambda m: (m.t, m.fin))):
        assert row.fin == plan.fin
        assert row.recorded_st == plan.st
        # each live plan recorded its seed: the replay reproduces it to the last bit
        assert plan.seed >= 0
        assert row.u == plan.u
        assert row.st == plan.st
    # the table's overall row: the mean of the live plans' St, recorded and replayed alike
    mean_st = statistics.fmean(m.st for m in run.plans)
    all_row = next(line for line in panel.replay_table.content.splitlines() if line.startswith("| all |"))
    cells = [c.strip() for c in all_row.strip("|").split("|")]
    assert int(cells[1]) == len(run.plans)
    assert float(cells[2]) == pytest.approx(mean_st, abs=5e-4)
    assert float(cells[3]) == pytest.approx(mean_st, abs=5e-4)


def test_counterfactual_bad_weights_are_refused(panel: PlaybackPanel, run: Run) -> None:
    panel.open(run.path.name)
    assert panel.act(lambda: panel.run_counterfactual("lam_x=2")) is False
    assert "lam_x" in panel.messages[-1]
    assert panel.act(lambda: panel.run_counterfactual("lam_st=nan")) is False
    assert panel.act(lambda: panel.run_counterfactual("lam_st=-1")) is False  # out of range: at once
    assert "lam_st" in panel.messages[-1]
    assert panel.job is None and panel.last_replay is None


def test_a_counterfactual_replay_shows_progress_runs_one_at_a_time_and_cancels(
        panel: PlaybackPanel, run: Run) -> None:
    panel.open(run.path.name)
    job = panel.run_counterfactual("lam_st=2.0")
    assert panel.replay_progress.visible and panel.cancel_button.visible
    server2 = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)  # another page
    other = PlaybackPanel(server2.gui, server2.scene, AppConfig().plant.geometry, directory=run.directory,
                          replay_slot=panel.replay_slot)
    try:
        other.open(run.path.name)
        assert other.act(lambda: other.run_counterfactual("lam_st=3.0")) is False  # one at a time
        assert "running" in other.messages[-1]
    finally:
        other.stop()
        server2.stop()
    assert panel.act(panel.cancel_counterfactual)
    assert job.done and job.cancelled and job.result is None
    assert not panel.replay_progress.visible and "cancelled" in panel.replay_table.content
    # the slot is free again, and a replay runs to its end
    panel.run_counterfactual("lam_st=2.0")
    res = panel.wait_replay()
    assert res is not None and len(res.rows) == len(run.plans)
    assert not panel.replay_progress.visible and "| all |" in panel.replay_table.content


def test_the_pilots_replay_cancels_another_pages_running_one(panel: PlaybackPanel, run: Run) -> None:
    panel.open(run.path.name)
    job = panel.run_counterfactual("lam_st=2.0")  # a viewer's page (no priority)
    server2 = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    pilot = PlaybackPanel(server2.gui, server2.scene, AppConfig().plant.geometry, directory=run.directory,
                          replay_slot=panel.replay_slot, may_replay=lambda: True)
    try:
        pilot.open(run.path.name)
        mine = pilot.run_counterfactual("lam_st=3.0")
        assert job.done and job.cancelled and job.result is None
        panel._tick_job()  # the viewer's panel shows why
        assert "cancelled: the pilot's page started one" in panel.replay_table.content
        assert panel.replay_slot.job is mine and not mine.cancelled
        mine.cancel()
    finally:
        pilot.stop()
        server2.stop()


def test_a_page_may_not_start_a_replay_when_the_console_says_no(run: Run) -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)

    def refuse() -> None:
        raise ValueError("counterfactual replay: while the robot is armed only the pilot may start one")

    p = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=run.directory, may_replay=refuse)
    try:
        p.open(run.path.name)
        assert p.act(lambda: p.run_counterfactual("lam_st=2.0")) is False
        assert "only the pilot" in p.messages[-1] and p.job is None
    finally:
        p.stop()
        server.stop()


def test_a_truncated_file_is_listed_and_repaired_from_the_panel(
    server: viser.ViserServer, run: Run, tmp_path: Path
) -> None:
    d = tmp_path / "sessions"
    d.mkdir()
    data = run.path.read_bytes()
    cut = d / run.path.name
    cut.write_bytes(data[: len(data) * 2 // 3])  # a killed recorder: no summary
    p = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=d, plot_rate=PLOT_RATE)
    try:
        assert "truncated" in p.browser.content and not p.repair_button.disabled
        assert p.act(lambda: p.open(cut.name)) is False  # it does not open before the repair
        assert p.act(lambda: p.repair(cut.name))
        assert "repaired" in p.messages[-1] and esc("truncated (repair)") not in p.browser.content
        assert esc(f"the original of {cut.name}, kept by its repair") in p.browser.content
        assert p.act(lambda: p.open(cut.name))
        assert p.player is not None and p.player.end > p.player.start
        assert p.act(lambda: p.open("../escape.mcap")) is False
    finally:
        p.stop()


def test_the_console_mounts_the_review_tab(run: Run, tmp_path: Path) -> None:
    from ucat_console.ui.app import ConsoleApp

    sup = Console(AppConfig(), run.directory).sup
    app = ConsoleApp(sup, port=0)
    review = app.build_review(app.server.gui, app.server.scene)  # what each page gets
    try:
        assert review.directory == run.directory.resolve()
        assert run.session_id in review.choice.options
        assert review.act(lambda: review.open(run.path.name))
        assert not math.isnan(review.feeder.latest[0])
    finally:
        review.stop()
        app.stop()
        sup.stop()


# ------------------------------------------------------------------ a session in parts
@dataclass
class SplitRun:
    directory: Path
    paths: list[Path]  # the part files, in order

    @property
    def session_id(self) -> str:
        return files.parse_part_name(self.paths[0])[0]

    def records(self, channels=None) -> list:
        """(channel, message, stream time) of every part read alone, in part order."""
        out = []
        for p in self.paths:
            with SessionReader(p, self.directory) as r:
                out += [(x.channel, x.message, r.from_ns(x.log_time_ns)) for x in r.records(channels)]
        return out

    def spans(self) -> list[tuple[float, float]]:
        out = []
        for p in self.paths:
            with SessionReader(p, self.directory) as r:
                out.append((r.start, r.end))
        return out


@pytest.fixture(scope="module")
def split_run(tmp_path_factory: pytest.TempPathFactory) -> SplitRun:
    d = tmp_path_factory.mktemp("split_sessions")
    cfg = AppConfig().replace(recorder=RecorderConfig(split_duration=1.0))
    sup = Console(cfg, d).sup
    try:
        sup.set_setpoints(LOCAL, velocity=0.2)
        sup.start_recording(LOCAL, "split review run")
        sup.arm(LOCAL)
        sup.step(1.5)
        sup.add_marker(LOCAL, "in a later part")
        sup.step(2.0)
        paths = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    assert len(paths) >= 3
    return SplitRun(d, paths)


@pytest.fixture
def split_panel(server: viser.ViserServer, split_run: SplitRun):
    p = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=split_run.directory,
                      plot_rate=PLOT_RATE, max_history=60.0, history=lambda: 60.0)
    yield p
    p.stop()
    for f in split_run.directory.glob("*.markers.json"):
        f.unlink()


class Sink:
    def __init__(self, stream: TelemetryStream) -> None:
        self.got: list = []
        stream.subscribe(lambda c, m: self.got.append((c, m)))

    def take(self) -> list:
        out, self.got = self.got, []
        return out


def test_a_split_session_is_listed_by_part_and_opened_whole(split_panel: PlaybackPanel,
                                                             split_run: SplitRun) -> None:
    panel, sid = split_panel, split_run.session_id
    assert panel.choice.options == (sid,)
    rows = [line for line in panel.browser.content.splitlines() if line.startswith(f"| {sid} |")]
    assert [int(r.split("|")[2]) for r in rows] == list(range(1, len(split_run.paths) + 1))
    assert panel.act(lambda: panel.open(panel.choice.value))
    r = panel.reader
    assert r is not None and r.paths == tuple(split_run.paths)
    spans = split_run.spans()
    first, last = spans[0][0], spans[-1][1]
    assert panel.timeline.max == pytest.approx(last - first)
    assert f"opened {sid}: {len(split_run.paths)} parts" in panel.messages[-1]
    assert f"part 1 of {len(split_run.paths)}" in panel.status.content
    # a part file's name opens the whole session too (as `run --playback FILE` does)
    assert panel.act(lambda: panel.open(split_run.paths[1].name))
    assert panel.reader is not None and panel.reader.paths == tuple(split_run.paths)


def test_playing_crosses_the_part_boundaries(split_panel: PlaybackPanel, split_run: SplitRun) -> None:
    panel = split_panel
    panel.open(split_run.session_id)
    p = panel.player
    assert p is not None
    every = split_run.records()
    spans = split_run.spans()
    start = spans[0][0]
    sink = Sink(panel.stream)
    for k in range(1, len(spans)):
        boundary = spans[k][0]
        # driven step by step: exactly the messages in between, once, in order
        panel.seek(boundary - 0.3 - start)
        sink.take()
        from_t = p.position
        while p.position < boundary + 0.3:
            p.advance(0.05)
        between = [(c, m, t) for c, m, t in every if from_t + 1e-9 < t <= p.position + 1e-9]
        assert between[0][2] < boundary <= between[-1][2]  # from part k into part k + 1
        assert sink.take() == [(c, m) for c, m, _ in between]
        panel._sync_inputs()
        assert f"part {k + 1} of {len(spans)}" in panel.status.content
    # played by the player's thread across the first boundary
    panel.seek(spans[1][0] - 0.25 - start)
    sink.take()
    from_t = p.position
    panel.set_speed(2.0)
    panel.play()
    wait_for(lambda: p.position > spans[1][0] + 0.25, what="the player past the second span")
    panel.pause()
    assert p.position > spans[1][0] + 0.25
    got = sink.take()
    assert got == [(c, m) for c, m, t in every if from_t + 1e-9 < t <= p.position + 1e-9]
    assert panel.tick_errors == 0


def test_seek_step_events_plots_and_replay_across_parts(split_panel: PlaybackPanel,
                                                       split_run: SplitRun) -> None:
    panel = split_panel
    panel.open(split_run.session_id)
    p = panel.player
    assert p is not None
    spans = split_run.spans()
    start = spans[0][0]
    bodies = [t for c, _, t in split_run.records([ch.BODY_STATE])]
    # frame steps over the boundary between parts 1 and 2
    before = max(t for t in bodies if t < spans[1][0])
    after = min(t for t in bodies if t >= spans[1][0])
    panel.seek(before - start)
    assert p.position == pytest.approx(before)
    assert panel.step(1) and p.position == pytest.approx(after)
    assert panel.step(-1) and p.position == pytest.approx(before)
    # a seek into the last part: the plots rebuilt from every part before it
    panel.seek(spans[-1][0] + 0.05 - start)
    rows = panel.feeder.buffer.last(CAPACITY)
    assert rows[-1, 0] == pytest.approx(max(t for t in bodies if t <= spans[-1][0] + 0.05 + 1e-9))
    assert rows[0, 0] < spans[1][0]  # the history window reaches back into part 1
    # every recorded event, of every part, is a jump target
    events = [m for c, m, _ in split_run.records([ch.EVENTS])]
    assert any(e.code == "marker" and e.message == "in a later part" for e in events)
    assert any(t >= spans[1][0] for c, _, t in split_run.records([ch.EVENTS]))
    panel.seek(-1.0)
    first = p.position
    seen = []
    while (what := panel.next_event()) is not None:
        seen.append(what)
    assert seen == [e for e in events if e.t > first + 1e-9]
    # counterfactual replay: every fin plan of every part
    plans = [m for c, m, _ in split_run.records([ch.fin_plan(i) for i in range(ch.N_FINS)])]
    assert plans
    panel.run_counterfactual("lam_st=2.0")
    res = panel.wait_replay()
    assert res is not None
    assert len(res.rows) + res.skipped == len(plans)
    assert sorted(r.t for r in res.rows) == sorted(m.t for m in plans)


def test_a_truncated_part_is_repaired_from_the_session_chooser(
    server: viser.ViserServer, split_run: SplitRun, tmp_path: Path
) -> None:
    d = tmp_path / "sessions"
    d.mkdir()
    for path in split_run.paths:
        (d / path.name).write_bytes(path.read_bytes())
    cut = d / split_run.paths[1].name
    data = cut.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    p = PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=d, plot_rate=PLOT_RATE)
    try:
        assert not p.repair_button.disabled and "truncated" in p.browser.content
        assert p.act(lambda: p.open(p.choice.value)) is False
        assert cut.name in p.messages[-1] and "repair" in p.messages[-1]
        assert p.act(lambda: p.repair(p.choice.value))
        assert f"repaired {cut.name}" in p.messages[-1]
        assert p.repair_button.disabled and esc("truncated (repair)") not in p.browser.content
        assert p.act(lambda: p.open(p.choice.value))
        assert p.reader is not None and len(p.reader.parts) == len(split_run.paths)
        # the other parts were left alone
        for path in split_run.paths:
            if path.name != cut.name:
                assert digest(d / path.name) == digest(path)
    finally:
        p.stop()


def test_review_markers_are_limited_in_size_and_rate(panel: PlaybackPanel, run: Run, monkeypatch) -> None:
    from ucat_console.backend.review.session import MARKER_INTERVAL

    t = [1000.0]
    monkeypatch.setattr(panel.session, "_clock", lambda: t[0])
    panel.open(run.path.name)
    assert panel.act(lambda: panel.add_marker("x" * 2049)) is False
    assert "2048 bytes" in panel.messages[-1]
    assert panel.act(lambda: panel.add_marker("first"))
    assert panel.act(lambda: panel.add_marker("too soon")) is False
    assert "at most one every" in panel.messages[-1]
    t[0] += MARKER_INTERVAL
    assert panel.act(lambda: panel.add_marker("second"))
    notes = [m.note for m in panel.player.markers.markers]
    assert "first" in notes and "second" in notes and "too soon" not in notes


def test_the_timeline_has_a_tick_at_each_warning_and_error(panel: PlaybackPanel, run: Run) -> None:
    panel.open(run.path.name)
    with SessionReader(run.path, run.directory) as r:
        serious = sorted({round(e.t - r.start, 2) for e in r.events() if e.level in ("warning", "error", "fatal")})
    assert serious  # arming is a warning
    assert [m.value for m in panel.timeline._marks] == pytest.approx(serious)
