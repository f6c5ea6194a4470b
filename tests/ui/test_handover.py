"""Control changing hands between raw websocket pages on a console running the simulated
robot in real time: a request for control waiting when the pilot's link drops never takes
control, the pilot-gone failsafe holds, the token takes control back and DISARMs; a request
the pilot leaves unanswered lapses on both pages.
"""

from __future__ import annotations

from typing import Callable

from support import TOKEN, Console, console_config, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.bench.raw_page import RawPage

PILOT_GONE = 1.0
SETTINGS = {"scene_rate": 10.0, "plot_rate": 2.0, "heartbeat_period": 0.1}


def served(make_console: Callable[..., Console], handover_timeout: float = 20.0) -> Console:
    cfg = console_config(TOKEN, PILOT_GONE, **SETTINGS)
    return make_console(cfg.replace(access=cfg.access.replace(handover_timeout=handover_timeout)), serve=True)


def texts(page: RawPage) -> str:
    """Every markdown text the page shows (its role line, its last message)."""
    return "\n".join(str(el.get("_markdown", "")) for el in list(page.elements.values()))


def pilot_page(console: Console) -> tuple[RawPage, int]:
    page = console.page()
    cid = console.cid_of(page)
    page.take_control(TOKEN)
    wait_for(lambda: console.sup.access.pilot == cid, what="the page taking control")
    return page, cid


def test_a_waiting_page_never_takes_control_when_the_pilots_link_drops(
        make_console: Callable[..., Console]) -> None:
    console = served(make_console)
    sup = console.sup
    a, a_id = pilot_page(console)
    sup.arm(LOCAL)
    sup.set_setpoints(LOCAL, velocity=0.2)
    b = console.page()
    b_id = console.cid_of(b)
    b.take_control(TOKEN)  # asks, then sits idle
    wait_for(lambda: sup.access.pending == b_id, what="b asking a for control")
    wait_for(lambda: "lapses after 20 s" in texts(b), what="b told it waits for the pilot's hand-over")
    n = len(console.events)
    a.answer_heartbeats = False  # the pilot's link drops
    a.stop_reading()
    fired = wait_for(lambda: console.event("failsafe", "pilot_gone", n), timeout=PILOT_GONE + 20.0,
                     what="the pilot_gone failsafe")
    assert fired.data["action"] == "hold"
    assert console.event("access", "request_lapsed", n).data["client"] == b_id
    assert sup.access.pilot is None and sup.armed
    assert sup.setpoints.velocity == 0.0
    wait_for(lambda: "Waiting" not in texts(b), what="b's page showing its request lapsed")
    # the operator comes back with the token on a new page: control at once, and DISARM
    c = console.page()
    c_id = console.cid_of(c)
    c.take_control(TOKEN)
    wait_for(lambda: sup.access.pilot == c_id, what="the token taking control back")
    wait_for(lambda: c.bar.get("you_pilot"), what="c's page showing it flies")
    c.update(c.bar["disarm_uuid"], value=True)
    wait_for(lambda: not sup.armed, what="c's DISARM")
    assert console.event("supervisor", "disarmed", n).data["who"] == str(c_id)
    for p in (a, b, c):
        p.close()


def test_a_request_the_pilot_leaves_unanswered_lapses_on_both_pages(make_console: Callable[..., Console]) -> None:
    console = served(make_console, handover_timeout=1.0)
    sup = console.sup
    a, a_id = pilot_page(console)
    b = console.page()
    b_id = console.cid_of(b)
    n = len(console.events)
    b.take_control(TOKEN)
    wait_for(lambda: f"Client {b_id} asks for control" in texts(a), what="the pilot's page showing the request")
    lapsed = wait_for(lambda: console.event("access", "request_lapsed", n), what="the request lapsing")
    assert lapsed.data["client"] == b_id
    wait_for(lambda: "asks for control" not in texts(a), what="the pilot's page showing the request gone")
    wait_for(lambda: "Waiting" not in texts(b), what="the asking page showing its request gone")
    assert sup.access.pilot == a_id and sup.access.pending is None
    a.close()
    b.close()
