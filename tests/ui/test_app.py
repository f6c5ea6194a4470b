"""The console app without a browser: a viser server on port 0, page callbacks run from code.

A ControlPanel built on the server's GUI stands in for one page; ``panel.act`` runs a
command exactly as the page's callback does (refusals shown, inputs reverted).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from support import Console, wait_for

from ucat_console.backend.supervisor import CommandRefused
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.devices.config import DevicesConfig, SimStartConfig
from ucat_console.config import AppConfig, load_config
from ucat_console.telemetry import channels as ch
from ucat_console.ui.app import ConsoleApp, is_loopback
from ucat_console.ui.identify_inputs import NO_SESSION
from ucat_console.ui.panels import DRAFT_MARK, ControlPanel, esc
from ucat_console.ui.tuning_inputs import param_specs, step_for

TOKEN = "pool-side-token"


@pytest.fixture
def app(tmp_path: Path):
    sup = Console(AppConfig(access=AccessConfig(token=TOKEN)), tmp_path).sup
    a = ConsoleApp(sup, port=0)
    yield a
    a.stop()
    sup.stop()


def page(app: ConsoleApp, cid: int, pilot: bool) -> ControlPanel:
    """A stand-in page ``cid`` (no browser): the console takes it as connected, so its page
    jobs run."""
    stand_ins = app.__dict__.setdefault("_stand_ins", set())
    if not stand_ins:
        real = app.page_present
        app.page_present = lambda c: c in stand_ins or real(c)  # type: ignore[method-assign]
    stand_ins.add(cid)
    app.sup.client_connected(cid)
    if pilot:
        assert app.sup.take_control(cid, TOKEN)
    return ControlPanel(app, cid, app.server.gui)


def test_server_binds_loopback_on_a_real_port(app: ConsoleApp) -> None:
    assert app.host == "127.0.0.1"
    assert app.port > 0 and app.url == f"http://127.0.0.1:{app.port}"
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.10")


def test_a_viewers_controls_are_disabled_and_refused_server_side(app: ConsoleApp) -> None:
    viewer = page(app, 7, pilot=False)
    assert viewer.arm.disabled and viewer.disarm.disabled and viewer.mode.disabled
    assert all(h.disabled for h in viewer.params.values())
    assert not viewer.take.disabled  # but it may ask for control
    # a page that sends anyway (the controls are disabled only in its browser)
    assert viewer.act(viewer._request_arm) is False
    assert "read-only" in viewer.messages[-1]
    assert not app.sup.armed
    viewer.mode.value = "baseline"
    assert viewer.act(lambda: app.sup.set_mode(viewer.cid, viewer.mode.value)) is False
    assert app.sup.mode == "mpc" and viewer.mode.value == "mpc"  # reverted on the page


def test_out_of_range_tuning_is_refused_shown_and_reverted(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    assert not pilot.arm.disabled and not pilot.params["mpc.lam_st"].disabled
    pilot.params["mpc.lam_st"].value = 500.0
    assert pilot.act(pilot._apply_tuning, tuning=True) is False
    assert "out of range" in pilot.messages[-1]
    assert "Refused" in pilot.tuning_message.content
    assert pilot.params["mpc.lam_st"].value == 5.0
    assert app.sup.tuning()["mpc"].lam_st == 5.0
    pilot.params["mpc.n_samples"].value = 250.5
    assert pilot.act(pilot._apply_tuning, tuning=True) is False
    assert "integer" in pilot.messages[-1]
    assert app.sup.tuning()["mpc"].n_samples == 500


def test_applied_tuning_shows_on_every_page(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    viewer = page(app, 4, pilot=False)
    pilot.params["mpc.lam_st"].value = 2.5
    pilot.params["pid.depth.kd"].value = 0.01
    assert pilot.act(pilot._apply_tuning, tuning=True) is True
    assert app.sup.tuning()["mpc"].lam_st == 2.5
    assert app.sup.tuning()["pid.depth"].kd == 0.01
    viewer.refresh()
    assert viewer.params["mpc.lam_st"].value == 2.5
    assert viewer.params["pid.depth.kd"].value == 0.01


def test_a_pilots_draft_is_not_overwritten_by_unrelated_refreshes(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    pilot.params["mpc.lam_a"].value = 4.0  # typed, not applied yet
    app.sup.set_mode(3, "baseline")
    pilot.refresh()
    assert pilot.params["mpc.lam_a"].value == 4.0
    assert pilot.mode.value == "baseline"


def test_an_edited_input_says_it_is_not_applied_until_it_is(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    lam, vel = pilot.params["mpc.lam_a"], pilot.sp_inputs["velocity"]
    label_lam, label_vel = lam.label, vel.label
    lam.value, vel.value = 4.0, 0.3  # typed, not applied
    pilot.refresh()
    assert lam.label == label_lam + DRAFT_MARK and vel.label == label_vel + DRAFT_MARK
    assert app.sup.setpoints.velocity == 0.0  # what the arm dialog would show: not the box
    assert pilot.act(pilot._apply_setpoints) is True
    pilot.refresh()
    assert vel.label == label_vel and lam.label == label_lam + DRAFT_MARK  # the tuning still a draft
    lam.value = app.sup.param_value("mpc.lam_a")  # typed back to the value in force
    pilot.refresh()
    assert lam.label == label_lam


def test_the_feedback_line_follows_a_revert_of_what_it_applied(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    before = app.sup.param_value("mpc.lam_st")
    pilot.params["mpc.lam_st"].value = 2.5
    assert pilot.act(pilot._apply_tuning, tuning=True) is True
    shown = pilot.tuning_message.content
    assert pilot.messages[-1] == "applied: mpc.lam_st = 2.5" and "2.5" in shown
    pilot.refresh()
    assert pilot.tuning_message.content == shown  # still in force: it stays
    app.sup.undo_tuning(3)  # undone (by the pilot, another of its pages, or a revert)
    pilot.refresh()
    assert pilot.messages[-1] == f"now in force: mpc.lam_st = {before:g}"
    assert "now in force" in pilot.tuning_message.content and "2.5" not in pilot.tuning_message.content
    assert pilot.params["mpc.lam_st"].value == before


def test_arming_from_the_page_takes_a_confirmation(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    assert pilot.act(pilot._request_arm) is True
    assert not app.sup.armed  # only the modal's confirm arms
    app.sup.confirm_arm(3, pilot._arm_nonce)
    assert app.sup.armed
    pilot.refresh()
    assert pilot.arm.disabled and not pilot.disarm.disabled
    assert pilot.act(lambda: app.sup.disarm(3)) is True
    assert not app.sup.armed


def test_plot_history_is_the_pilots_and_bounded(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    viewer = page(app, 4, pilot=False)
    assert viewer.act(lambda: app.set_history(4, 60.0)) is False
    assert pilot.act(lambda: app.set_history(3, 1e6)) is False
    assert pilot.act(lambda: app.set_history(3, 60.0)) is True
    assert app.history == 60.0


def test_tuning_inputs_come_from_the_field_metadata() -> None:
    from ucat_console.backend.supervisor.tuning import tuning_blocks

    specs = param_specs(tuning_blocks(AppConfig()))
    lam_st = next(s for s in specs["mpc"] if s.key == "mpc.lam_st")
    assert "[0.0, 100.0]" in lam_st.label and "Strouhal" in lam_st.hint
    n = next(s for s in specs["mpc"] if s.key == "mpc.n_samples")
    assert n.is_int and n.step == 10.0
    assert step_for(0.3, False) == pytest.approx(0.01)
    assert {s.key for s in specs["pid.yaw_rate"]} == {f"pid.yaw_rate.{k}" for k in ("kp", "ki", "kd", "limit")}


def test_page_text_is_escaped() -> None:
    assert "<" not in esc("<script>alert(1)</script>")
    assert esc("**bold**") == "\\*\\*bold\\*\\*"
    assert esc("it's 'quoted'") == "it's 'quoted'"  # quotes stay quotes (the page shows &#x27; as is)


def test_rig_fault_inputs_only_where_the_robot_is_the_simulated_rig(app: ConsoleApp) -> None:
    p = page(app, 3, pilot=True)
    assert p.faults is None and p.reset_drives is None and p.zero_depth is None  # no devices
    with pytest.raises(CommandRefused, match="no motor drives"):
        app.sup.reset_drive_faults(3)
    with pytest.raises(CommandRefused, match="no pressure sensor"):
        app.sup.zero_depth(3)


def test_the_pilot_injects_rig_faults_from_the_page_and_bad_entries_are_refused(tmp_path: Path) -> None:
    cfg = load_config("sim-devices").replace(access=AccessConfig(token=TOKEN))
    sup = Console(cfg, tmp_path, clock=None).sup
    a = ConsoleApp(sup, port=0)
    sup.start()
    try:
        pilot, viewer = page(a, 3, pilot=True), page(a, 4, pilot=False)
        assert pilot.faults is not None and viewer.faults is not None
        assert not pilot.faults.inject.disabled and viewer.faults.inject.disabled
        f = pilot.faults

        # the fault list follows the device
        f.device.value = "pressure"
        f.show_faults_of_device()
        assert set(f.fault.options) == {"silence", "corrupt", "invalid", "implausible", "slow"} and f.fault.value == "silence"
        f.device.value = "epos2"
        f.show_faults_of_device()
        assert "emcy" in f.fault.options and f.fault.value == "silence"  # still a fault of the drive
        f.fault.value = "emcy"

        f.code.value = "overcurrent"
        assert pilot.act(pilot._inject_fault) is False
        assert "EMCY code" in pilot.messages[-1] and "0x2310" in pilot.messages[-1]
        f.fin.value = 7  # past the input's bound, as a page that sends anyway
        f.code.value = "0x2310"
        assert pilot.act(pilot._inject_fault) is False
        assert "fin" in pilot.messages[-1]
        assert viewer.act(viewer._inject_fault) is False
        assert "read-only" in viewer.messages[-1]

        f.fin.value = 2
        assert pilot.act(pilot._inject_fault) is True
        assert "emcy injected" in pilot.messages[-1]
        node = cfg.devices.epos2.node_ids[2]
        wait_for(lambda: sup.rig.nodes[node].state == "fault", what="the drive in fault")
        assert pilot.act(pilot._clear_faults) is True
        wait_for(lambda: "motor" in sup.safety.active(), what="the motor failsafe")
        assert sup.rig.nodes[node].state == "fault"  # clearing the emulator does not reset a drive

        # the drive's fault is reset from the page, by the pilot only, and it stays off
        assert not pilot.reset_drives.disabled and viewer.reset_drives.disabled
        assert viewer.act(viewer._reset_drive_faults) is False
        assert sup.rig.nodes[node].state == "fault"
        assert pilot.act(pilot._reset_drive_faults) is True
        assert "drive faults reset" in pilot.messages[-1]
        assert sup.rig.nodes[node].state == "switch_on_disabled"
        wait_for(lambda: "motor" not in sup.safety.active(), what="the motor failsafe clearing")

        # depth zeroing: the pressure the robot is at becomes depth 0
        depths: list = []
        sup.stream.subscribe(lambda c, m: depths.append(m.depth_m), [ch.DEPTH])
        wait_for(lambda: depths, what="depth readings")
        assert depths[-1] > 0.2  # the rig's robot starts below the surface
        assert viewer.act(viewer._zero_depth) is False
        assert pilot.act(pilot._zero_depth) is True
        assert "depth zeroed" in pilot.messages[-1]
        n = len(depths)
        wait_for(lambda: len(depths) > n + 5, what="depth readings after the zeroing")
        assert abs(depths[-1]) < 0.05
    finally:
        a.stop()
        sup.stop()


def test_the_arm_dialog_shows_the_setpoints_and_offers_to_zero_them(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    app.sup.set_setpoints(3, velocity=0.2, yaw_rate=0.1)
    made = []
    real_button = pilot.gui.add_button
    pilot.gui.add_button = lambda label, **kw: made.append((label, real_button(label, **kw))) or made[-1][1]
    real_md = pilot.gui.add_markdown
    texts = []
    pilot.gui.add_markdown = lambda text, **kw: texts.append(text) or real_md(text, **kw)
    assert pilot.act(pilot._request_arm)
    assert any("velocity 0.2 m/s" in t and "yaw rate 0.1 rad/s" in t for t in texts)
    zero = dict(made)["Zero velocity and yaw rate, then arm"]
    assert zero.visible
    app.sup.set_setpoints(3, velocity=0.0, yaw_rate=0.0)
    assert pilot.act(pilot._request_arm)  # nothing to zero: the offer is not shown
    assert not [b for label, b in made if label.startswith("Zero")][-1].visible


def test_the_gamepad_drives_within_the_envelope_and_stops(app: ConsoleApp) -> None:
    from ucat_console.ui.driving import Driving

    sup = app.sup
    page(app, 3, pilot=True)
    d = Driving(sup, 3, lambda fn: fn())
    lc = sup.cfg.loop
    d.gamepad('{"v": 1.0, "r": -0.5, "dz": 0}')
    assert sup.setpoints.velocity == pytest.approx(lc.max_velocity)
    assert sup.setpoints.yaw_rate == pytest.approx(-0.5 * lc.max_yaw_rate)
    assert sup.journal()[-1].key == "gamepad"  # driving started (the setpoints are not journalled one by one)
    d.gamepad('{"v": 0, "r": 0, "dz": 0, "stop": 1}')
    assert sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0
    for bad in ('{"v": 2, "r": 0, "dz": 0}', '{"v": "x", "r": 0, "dz": 0}', "not json", '{"v": 0}'):
        with pytest.raises(ValueError, match="gamepad"):
            d.gamepad(bad)
    viewer = Driving(sup, 4, lambda fn: fn())
    sup.client_connected(4)
    with pytest.raises(Exception, match="read-only"):
        viewer.gamepad('{"v": 1, "r": 0, "dz": 0}')
    assert sup.setpoints.velocity == 0.0


def test_keys_step_the_setpoints_and_clamp_to_the_envelope(app: ConsoleApp) -> None:
    from ucat_console.ui.driving import Driving

    sup = app.sup
    page(app, 3, pilot=True)
    d = Driving(sup, 3, lambda fn: fn())
    for _ in range(100):
        d.step("W")
    assert sup.setpoints.velocity == pytest.approx(sup.cfg.loop.max_velocity)
    depth = sup.setpoints.depth
    d.step("F")
    assert sup.setpoints.depth == pytest.approx(depth + sup.cfg.console.drive_depth_step)
    d.stop()
    assert sup.setpoints.velocity == 0.0 and sup.setpoints.yaw_rate == 0.0


def test_the_events_list_shows_the_chosen_severities(app: ConsoleApp) -> None:
    from ucat_console.telemetry.events import Event

    pilot = page(app, 3, pilot=True)
    for level in ("info", "warning", "error"):
        app._on_message(ch.EVENTS, Event(1.0, "test", f"{level}_code", f"a {level}", level))
    pilot.severity.value = "errors"
    pilot.show_events(force=True)
    assert "error\\_code" in pilot.events.content and "warning\\_code" not in pilot.events.content
    pilot.severity.value = "all"
    pilot.show_events(force=True)
    assert "info\\_code" in pilot.events.content


def test_the_events_list_is_rebuilt_when_an_event_comes_or_the_filter_changes(app: ConsoleApp, monkeypatch) -> None:
    """The 4-Hz refresh of a page's events list builds it only when there is something new
    to show: a new event, or another choice of severity."""
    from ucat_console.telemetry.events import Event
    from ucat_console.ui import panels as panels_module

    pilot = page(app, 3, pilot=True)
    built = []
    real = panels_module.events_markdown
    monkeypatch.setattr(panels_module, "events_markdown", lambda events: built.append(len(events)) or real(events))
    app._on_message(ch.EVENTS, Event(1.0, "test", "first_code", "one", "warning"))
    pilot.show_events()
    pilot.show_events()
    assert built == [1] and "first\\_code" in pilot.events.content
    app._on_message(ch.EVENTS, Event(2.0, "test", "second_code", "two", "error"))
    pilot.show_events()
    assert built == [1, 2] and "second\\_code" in pilot.events.content
    pilot.severity.value = "errors"
    pilot.show_events()
    assert built == [1, 2, 1] and "first\\_code" not in pilot.events.content
    pilot.show_events()
    assert built == [1, 2, 1]


def test_the_formulation_is_switched_from_the_tuning_tab(app: ConsoleApp) -> None:
    pilot = page(app, 3, pilot=True)
    box = pilot.params["mpc.formulation"]
    assert set(box.options) == {"paper", "closed_stroke"} and box.value == "paper"
    box.value = "closed_stroke"
    assert pilot.act(pilot._apply_tuning, tuning=True)
    assert app.sup.tuning()["mpc"].formulation == "closed_stroke"
    assert "mpc.formulation = closed_stroke" in pilot.messages[-1]


def test_recording_buttons_follow_the_recording_and_setpoints_show_rounded(app: ConsoleApp) -> None:
    pilot = page(app, 1, pilot=True)
    pilot.refresh()
    assert not pilot.rec_start.disabled and pilot.rec_stop.disabled
    app.sup.start_recording(1)
    pilot.refresh()
    assert pilot.rec_start.disabled and not pilot.rec_stop.disabled  # no second start while recording
    app.sup.stop_recording(1)
    # a depth held by a failsafe is the measured one; the box shows it to 4 places at most
    app.sup.set_setpoints(1, depth=1.0110210123)
    pilot.refresh()
    assert pilot.sp_inputs["depth"].value == 1.011


def test_the_pilot_identifies_the_fin_model_from_the_session_tab(tmp_path: Path) -> None:
    cfg = AppConfig(access=AccessConfig(token=TOKEN), devices=DevicesConfig(start=SimStartConfig(depth=3.0)))
    sup = Console(cfg, tmp_path).sup
    a = ConsoleApp(sup, port=0)
    try:
        viewer = page(a, 2, pilot=False)
        pilot = page(a, 1, pilot=True)
        ident = pilot.identify
        assert pilot.act(ident.start) is False and "arm" in pilot.messages[-1]  # armed first
        sup.arm(1)
        sup.step(1.0)
        assert viewer.act(viewer.identify.start) is False and "read-only" in viewer.messages[-1]
        assert pilot.act(ident.start) and sup.mode == "identify" and sup.recorder.recording
        pilot.refresh()
        assert ident.progress.visible and ident.stop.visible
        sup.step(sup.manoeuvre.duration + 0.5)
        assert sup.manoeuvre.finished and sup.mode == "mpc" and not sup.recorder.recording
        pilot.refresh()  # the sessions are listed by the console's page jobs
        wait_for(lambda: ident.session.value == sup.manoeuvre.session,
                 what="the manoeuvre's recording chosen")
        assert viewer.act(viewer.identify.start_fit) is False  # the pilot's
        assert pilot.act(ident.start_fit)
        ident._fitting.join(120.0)
        pilot.refresh()
        r = ident.report.result
        assert r.c_d > 0.0 and r.steady_windows >= 3
        assert "C_D" in ident.result.content and ident.use.visible
        assert pilot.act(ident.use_fit)
        sup.step(0.2)
        assert sup.loop.mpc_config.c_d == pytest.approx(r.c_d, rel=1e-5)
        assert sup.loop.mpc_config.c_l == pytest.approx(r.c_l, rel=1e-5)
        assert {e.key for e in sup.journal()[-2:]} == {"mpc.c_d", "mpc.c_l"}
    finally:
        a.stop()
        sup.stop()


def test_a_recording_the_fit_refuses_is_shown_with_the_reason(app: ConsoleApp) -> None:
    pilot = page(app, 1, pilot=True)
    app.sup.start_recording(1)
    app.sup.step(0.5)  # disarmed: no steady window where the fins beat
    app.sup.stop_recording(1)
    pilot.refresh(force=True)
    wait_for(lambda: pilot.identify.session.value != NO_SESSION, what="the recording listed")
    assert pilot.act(pilot.identify.start_fit)
    pilot.identify._fitting.join(60.0)
    pilot.refresh()
    assert "Fit refused" in pilot.identify.result.content and not pilot.identify.use.visible
