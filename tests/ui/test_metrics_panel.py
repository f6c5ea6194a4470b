"""The efficiency figures' panel: numbers coloured in or out of the corridor, fin swatches in
the plot colours, a reset on another session, and (in headless Chromium) the live page at
1280x800 with the figures and the power chart in view."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[1] / "backend" / "sessions"))
from synthetic_run import BATTERY, run_items  # noqa: E402

from ucat_console.backend.review.metrics import MetricsConfig  # noqa: E402
from ucat_console.robot.look import FIN_COLOURS, hex_colour  # noqa: E402
from ucat_console.telemetry.stream import TelemetryStream  # noqa: E402
from ucat_console.ui.metrics_panel import IN_COLOUR, OUT_COLOUR, MetricsPanel  # noqa: E402


class _Gui:
    def add_html(self, content: str, order: float | None = None) -> types.SimpleNamespace:
        return types.SimpleNamespace(content=content)


def _panel() -> tuple[MetricsPanel, TelemetryStream]:
    stream = TelemetryStream()
    panel = MetricsPanel(_Gui(), MetricsConfig(window=10.0))
    panel.subscribe(stream)
    return panel, stream


def test_the_panel_shows_each_fins_strokes_coloured_and_the_robots_figures():
    panel, stream = _panel()
    assert "no telemetry yet" in panel.html.content
    for channel, m in run_items():
        stream.publish(channel, m)
    panel.refresh()
    html = panel.html.content
    for fin in range(4):
        # the latest two strokes: 0.30 (inside 0.25..0.35) then 0.40 (outside)
        for stroke, (where, colour, value) in enumerate((("in", IN_COLOUR, "0.30"), ("out", OUT_COLOUR, "0.40"))):
            assert re.search(rf'class="ucat-st {where}" data-fin="{fin}" data-stroke="{stroke}"'
                             rf'[^>]*background:{colour}[^>]*>{value}<', html)
        assert f"background:{hex_colour(FIN_COLOURS[fin])}" in html
    # no electrical readings: the estimate's figures, and the battery's row says why
    assert _source_row(html, "mechanical", used=True) == ["▸ mechanical (shaft estimate)", "4.00", "20.0", "0.91"]
    assert _source_row(html, "electrical", used=False) == ["electrical (battery)", "no readings"]
    assert "depth 0.050 m" in html
    panel.reset()
    assert "no telemetry yet" in panel.html.content


def _source_row(html: str, source: str, used: bool) -> list[str]:
    """The texts of the cells of the robot's row of ``source`` (asserting whether it is the one used)."""
    m = re.search(rf'<tr class="ucat-source( ucat-used)?" data-source="{source}"[^>]*>(.*?)</tr>', html)
    assert m is not None and bool(m.group(1)) == used, html
    return [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", m.group(2))]


def test_the_battery_power_is_shown_first_with_the_estimate_below_it():
    panel, stream = _panel()
    for channel, m in run_items(battery_from=0.0):
        stream.publish(channel, m)
    panel.refresh()
    html = panel.html.content
    # the drives' 12 W at 0.2 m/s: 60 J/m, 60 / 22 J/(kg m); the estimate's 4 W below
    assert _source_row(html, "electrical", used=True) == ["▸ electrical (battery)", "12.00", "60.0", "2.73"]
    assert _source_row(html, "mechanical", used=False) == ["mechanical (shaft estimate)", "4.00", "20.0", "0.91"]
    powers = re.findall(r'class="ucat-fin-power">([^<]*)<', html)
    assert powers == [f"{p:.2f}" for p in BATTERY]


def test_the_effects_list_shows_before_and_after_and_what_is_still_pending():
    from ucat_console.backend.review.effects import Effect
    from ucat_console.ui.markdown import esc
    from ucat_console.ui.metrics_panel import effects_markdown

    done = Effect(10.0, "tuning", "client 1: mpc.lam_st 5 -> 2", {}, 20.0, {"power": 4.0, "energy_per_metre": 20.0,
                  "speed_mae": 0.02, "st_in": 50.0}, {"power": 3.0, "energy_per_metre": 15.0, "speed_mae": None,
                                                      "st_in": 80.0}, "electrical", "electrical (battery)")
    pending = Effect(30.0, "mode", "controller mpc -> baseline", {}, 40.0, {"power": 3.0})
    md = effects_markdown([pending, done], now=34.0)
    assert esc("electrical (battery): 4.00 → 3.00 W") in md and "20.0 → 15.0 J/m" in md
    assert "50 → 80 % St in corridor" in md
    assert "0.020 → – m/s" in md
    assert "3.00 → … W" in md and "fills in 6 s" in md
    assert md.index("controller mpc") < md.index("lam")  # newest first


def test_a_seek_back_starts_the_figures_afresh():
    panel, stream = _panel()
    for channel, m in run_items():
        stream.publish(channel, m)
    panel.refresh()
    assert _source_row(panel.html.content, "mechanical", used=True)[1] == "4.00"
    # the review seeks back to 2 s and plays a run of twice the power from there
    for channel, m in run_items(scale=2.0):
        if m.t >= 2.0:
            stream.publish(channel, m)
    panel.refresh()
    assert _source_row(panel.html.content, "mechanical", used=True)[1] == "8.00"


def _st_tiles(html: str) -> list[tuple[str, str]]:
    """Each St tile's (class, text)."""
    return re.findall(r'<span class="ucat-st ([^"]*)"[^>]*>([^<]*)<', html)


def test_no_st_value_is_shown_while_the_robot_is_still_or_disarmed():
    from ucat_console.telemetry import channels as C
    from ucat_console.telemetry.messages import Status

    # slower than the plots' 0.02 m/s: the strokes' St is the planner's speed floor's, no measurement
    panel, stream = _panel()
    for channel, m in run_items(speed=0.01):
        stream.publish(channel, m)
    panel.refresh()
    assert _st_tiles(panel.html.content) == [("none", "–")] * 4
    # swimming, then disarmed: the last strokes' values go, a greyed dash each
    panel, stream = _panel()
    items = run_items()
    for channel, m in items:
        stream.publish(channel, m)
    panel.refresh()
    assert len([c for c, _ in _st_tiles(panel.html.content) if c in ("in", "out")]) == 8
    t = items[-1][1].t
    stream.publish(C.STATUS, Status(t, False, "mpc", "", (), 0, "sim"))
    panel.refresh()
    assert _st_tiles(panel.html.content) == [("none", "–")] * 4
    assert "the robot is disarmed" in panel.html.content
