"""The console's own script in the page: the fixed status bar, DISARM, the link-loss banner,
the theme switch and the gamepad.

viser draws its panels; what must stay on screen whatever the operator scrolls to, and
what must still work when the server is gone, is drawn here in plain DOM (no innerHTML:
every text the server sends is set as text). The server installs the script once per page
(:data:`INSTALL`, run by viser's RunJavascript message; installing again is a no-op) and
then sends the bar's state a few times a second (:func:`update_source`). Two things the
page does on its own:

* **Link loss**: when no state has arrived for :data:`LINK_LOST_AFTER` s (checked every
  0.25 s, so within 1.75 s), a full-width banner says the link is lost and what the robot
  does meanwhile (the configured pilot-gone failsafe, as last told by the server), and the
  bar shows its last state greyed with a question mark (nothing in it is live), the page's
  panels greyed and their buttons and boxes disabled; all go with the next state. A state
  from another run of the console (its ``console.id``) puts up a line saying it restarted.
* **Link slow**: the server says when this page's link is too slow for the telemetry
  (:mod:`ucat_console.ui.link`); the bar then shows "LINK SLOW: updates thinned" in amber.
* **The pilot's token, for reconnects**: the token this page took control with is kept in
  the tab's ``sessionStorage`` (:data:`TOKEN_KEY`; never in the URL, never logged) while the
  page is the pilot. When the page comes back on a new connection (a lost link, the console
  restarted, the tab reloaded; the loading page of a console still starting is passed over)
  and nobody flies, it presents the token again, once, through
  its own token box and *Take control*: the server checks it as any token (the guard's and
  the access rules' guess budget and lock-outs). The page forgets it when another page flies
  by then, when control leaves it while connected (released, handed over), and when the
  token sent again has not made it the pilot within :data:`RESEND_GIVE_UP` s.
* **Number boxes**: viser sends nothing for a number box left empty or holding text that is
  no number; on leaving such a box the page puts back the number it held.
* **DISARM** (the bar's button, and the Esc key through the console's command) and the
  gamepad send their messages through the page's own viser connection
  (``sendMessage`` of viser's client in the page,
  :data:`ucat_console.ui.viser_compat.PAGE_CLIENT`, checked by the browser tests) to inputs of this page that the server registered; the page guard
  checks them like any other message.

The gamepad (where the browser exposes one, polled 10 times a second while this page is
the pilot's): left stick forward/back is the velocity, left stick left/right the yaw rate,
right stick up/down the depth rate, each with a dead zone; button 1 (B / circle) disarms.
Losing the gamepad or the page's focus sends zeros once (no runaway stick).
"""

from __future__ import annotations

import json
from typing import Any

from ucat_console.ui.viser_compat import PAGE_CLIENT

#: seconds without a state from the server before the link-loss banner shows
LINK_LOST_AFTER = 1.5
#: the gamepad's dead zone (fraction of full stick)
DEAD_ZONE = 0.15
#: the theme key in the browser's storage
THEME_KEY = "ucat-theme"
#: the key of the pilot's token in the page's sessionStorage (this tab only, never the URL)
TOKEN_KEY = "ucat-pilot-token"
#: a token sent again after a reconnect that has not made the page the pilot after this
#: long (s) is forgotten (a new token after a restart, or another page took control first)
RESEND_GIVE_UP = 10.0

INSTALL = r"""
(() => {
  if (window.__ucat) return;
  const LOST_MS = %(lost_ms)d, DEAD = %(dead)f, TOKEN_KEY = "%(token_key)s", RESEND_GIVE_UP_MS = %(give_up_ms)d;
  const u = window.__ucat = {state: null, last: 0, lost: false, pad: {sent: null, at: 0, active: false, polls: 0}};
  const css = document.createElement("style");
  css.textContent = `
    #ucat-bar { position: fixed; top: 0; left: 0; right: 0; height: 46px; z-index: 2147483000;
      display: flex; align-items: center; gap: 10px; padding: 0 10px; box-sizing: border-box;
      font: 14px/1.2 system-ui, sans-serif; background: #1f2328; color: #e6e6e6;
      border-bottom: 1px solid #444; overflow: hidden; white-space: nowrap; }
    #ucat-bar.light { background: #f3f4f6; color: #111; border-bottom-color: #bbb; }
    #ucat-bar .armed { font-weight: 800; font-size: 18px; padding: 4px 12px; border-radius: 4px;
      letter-spacing: 0.04em; }
    #ucat-bar .armed.on { background: #d7263d; color: #fff; }
    #ucat-bar .armed.off { background: #2f6f3e; color: #fff; }
    #ucat-bar > * { flex-shrink: 0; }
    #ucat-bar .item { opacity: 0.95; }
    #ucat-bar #ucat-info, #ucat-bar #ucat-battery { min-width: 0; overflow: hidden; text-overflow: ellipsis; }
    #ucat-bar #ucat-battery { flex-shrink: 50; }  /* where the bar is short: the battery's text first, */
    #ucat-bar #ucat-info { flex-shrink: 5; }  /* then the mode and pilot (in the tabs too); never the lights */
    #ucat-bar .armed.stale { background: #6b7280; }
    #ucat-bar .rec { color: #ff5c5c; font-weight: 700; }
    #ucat-bar .rec-failed { color: #fff; background: #b91c1c; padding: 2px 8px; border-radius: 3px; cursor: help; }
    #ucat-bar .review { color: #fff; background: #6d28d9; padding: 2px 8px; border-radius: 3px; font-weight: 700; }
    #ucat-bar .viewer { color: #111; background: #cbd5e1; padding: 2px 8px; border-radius: 3px; font-weight: 700;
      cursor: help; }
    #ucat-bar .fs { color: #fff; background: #b45309; padding: 2px 8px; border-radius: 3px; font-weight: 700; }
    #ucat-bar #ucat-link.slow { color: #111; background: #f59e0b; padding: 2px 8px; border-radius: 3px;
      font-weight: 700; }
    #ucat-bar .light-dot { display: inline-flex; align-items: center; gap: 4px; margin-right: 6px; cursor: help; }
    #ucat-bar .dot { width: 11px; height: 11px; border-radius: 50%%; display: inline-block; }
    #ucat-bar .dot.ok { background: #22c55e; } #ucat-bar .dot.warn { background: #f59e0b; }
    #ucat-bar .dot.bad { background: #ef4444; } #ucat-bar .dot.off { background: #6b7280; }
    #ucat-bar .grow { flex: 1 1 auto; }
    #ucat-disarm { font: 800 18px system-ui, sans-serif; color: #fff; background: #d7263d; border: 0;
      border-radius: 5px; padding: 6px 22px; cursor: pointer; letter-spacing: 0.05em; }
    #ucat-disarm:disabled { background: #6b7280; cursor: not-allowed; opacity: 0.7; }
    #ucat-theme { font: 14px system-ui, sans-serif; background: transparent; color: inherit;
      border: 1px solid #777; border-radius: 4px; padding: 4px 8px; cursor: pointer; }
    #ucat-banner { position: fixed; top: 46px; left: 0; right: 0; z-index: 2147483001; display: none;
      padding: 14px 18px; font: 700 20px/1.3 system-ui, sans-serif; color: #fff; background: #b91c1c;
      text-align: center; box-shadow: 0 4px 12px rgba(0,0,0,.4); }
    #ucat-banner small { display: block; font-weight: 500; font-size: 15px; margin-top: 4px; }
    #ucat-bar.lost .dot { background: #6b7280 !important; }
    #ucat-bar.lost .rec, #ucat-bar.lost .review, #ucat-bar.lost .fs { color: #d1d5db !important;
      background: #4b5563 !important; }
    body.ucat-lost #root { filter: grayscale(1) opacity(0.6); }
    #ucat-notice { position: fixed; top: 46px; left: 0; right: 0; z-index: 2147483001; display: none;
      padding: 8px 18px; font: 600 15px/1.3 system-ui, sans-serif; color: #111; background: #f59e0b;
      text-align: center; }
    body.ucat-has-bar #root { position: fixed !important; top: 46px !important; left: 0; right: 0;
      bottom: 0; height: auto !important; }
  `;
  document.head.appendChild(css);
  const el = (tag, cls, text) => { const e = document.createElement(tag); if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text; return e; };
  const bar = el("div"); bar.id = "ucat-bar";
  const armed = el("span", "armed off", "DISARMED"); armed.id = "ucat-armed";
  const viewer = el("span", "viewer", "VIEWER"); viewer.id = "ucat-viewer"; viewer.style.display = "none";
  viewer.title = "this page only watches: the pilot's controls are greyed; enter the pilot token under Pilot "
    + "to take control";
  const info = el("span", "item"); info.id = "ucat-info";
  const link = el("span", "item", "link ok"); link.id = "ucat-link";
  const rec = el("span", "rec"); rec.id = "ucat-rec";
  const review = el("span", "review"); review.id = "ucat-review"; review.style.display = "none";
  const fs = el("span", "fs"); fs.id = "ucat-failsafes"; fs.style.display = "none";
  const lights = el("span", "item"); lights.id = "ucat-lights";
  const battery = el("span", "item"); battery.id = "ucat-battery";
  const grow = el("span", "grow");
  const theme = el("button", "", "theme"); theme.id = "ucat-theme"; theme.title = "dark / light (this browser)";
  const disarm = el("button", "", "DISARM"); disarm.id = "ucat-disarm"; disarm.disabled = true;
  disarm.title = "no state from the console yet";
  bar.append(armed, viewer, info, link, rec, review, fs, lights, battery, grow, theme, disarm);
  const banner = el("div"); banner.id = "ucat-banner";
  const notice = el("div"); notice.id = "ucat-notice";
  const install = () => { if (!document.body) return setTimeout(install, 50);
    document.body.append(bar, banner, notice); document.body.classList.add("ucat-has-bar"); };
  install();
  const send = (uuid, value) => {
    const m = %(viser_client)s;
    if (!uuid || !m || !m.sendMessage) return false;
    m.sendMessage({type: "GuiUpdateMessage", uuid: uuid, updates: {value: value}});
    return true;
  };
  u.send = send;
  disarm.addEventListener("click", () => { const s = u.state; if (s && !disarm.disabled) send(s.disarm_uuid, true); });
  theme.addEventListener("click", () => { const s = u.state; if (s) send(s.theme_uuid, true); });
  // the mode, and beside an MPC mode its cost formulation
  const modeText = (s) => `mode ${s.mode}` + (s.formulation ? ` · ${s.formulation}` : "");
  const showBanner = (on) => {
    if (on === u.lost) return;
    u.lost = on;
    banner.style.display = on ? "block" : "none";
    // nothing on the page is live or can act while the link is lost: greyed, its controls off
    bar.classList.toggle("lost", on); document.body.classList.toggle("ucat-lost", on);
    if (on) {
      u.offed = [...document.querySelectorAll("#root button:not([disabled]), #root input:not([disabled])")];
      for (const b of u.offed) b.disabled = true;
    } else {
      for (const b of u.offed || []) if (b.isConnected) b.disabled = false;
      u.offed = [];
    }
    if (on) {
      banner.textContent = "";
      banner.append(document.createTextNode("LINK LOST: this page no longer reaches the console"));
      const s = u.state;
      banner.append(el("small", "", s ? s.link_policy : "the robot's failsafes act on their own"));
      // the bar shows what was last known, as such: nothing here is live any more
      if (s) {
        armed.textContent = (s.armed ? "ARMED" : "DISARMED") + "?";
        armed.className = "armed stale";
        armed.title = "last known state: the link is lost";
        info.textContent = `${modeText(s)}  ·  pilot: ${s.pilot}  ·  LINK LOST`;
        link.textContent = ""; link.className = "item";
      }
      disarm.disabled = true;
    }
  };
  u.render = (s) => {
    if (u.state && s.console && u.state.console && s.console.id !== u.state.console.id) {
      // the page came back to another run of the console: it says so (for a while)
      notice.textContent = `The console restarted (at ${s.console.started}) while this page was away: ` +
        "what it shows now is the new run's; take control again to pilot.";
      notice.style.display = "block"; clearTimeout(u.noticeTimer);
      u.noticeTimer = setTimeout(() => { notice.style.display = "none"; }, 20000);
    }
    u.state = s; u.last = Date.now(); showBanner(false);
    armed.textContent = s.armed ? "ARMED" : "DISARMED";
    armed.className = "armed " + (s.armed ? "on" : "off");
    armed.title = "";
    info.textContent = `${modeText(s)}  ·  pilot: ${s.pilot}  ·`;
    link.textContent = s.link_slow ? "LINK SLOW: updates thinned" : "link ok";
    link.className = "item" + (s.link_slow ? " slow" : "");
    link.title = s.link_slow ? "this page reads slower than the console sends: it gets the newest poses "
      + "and plots, not every one; heartbeats and this bar go first" : "";
    rec.textContent = s.recording_failed ? "● REC FAILED" : (s.recording ? "● REC" : "");
    rec.className = "rec" + (s.recording_failed ? " rec-failed" : "");
    rec.title = s.recording_failed || (s.recording ? `recording ${s.recording}` : "");
    review.style.display = s.review ? "inline" : "none";
    review.textContent = s.review ? `REVIEW ${s.review}` : "";
    review.title = s.review ? "this page plays a recording: the 3-D view and the Review plots show it, "
      + "not the live robot" : "";
    fs.style.display = s.failsafes.length ? "inline" : "none";
    fs.textContent = s.failsafes.length ? "FAILSAFE " + s.failsafes.join(", ") : "";
    lights.textContent = "";
    for (const l of s.lights) {
      const w = el("span", "light-dot"); w.title = l.why; w.dataset.name = l.name; w.dataset.state = l.state;
      w.append(el("span", "dot " + l.state), document.createTextNode(l.name));
      lights.append(w);
    }
    battery.textContent = s.battery;
    u.token(s);
    disarm.disabled = !(s.armed && s.you_pilot);
    viewer.style.display = s.you_pilot ? "none" : "inline";
    disarm.title = s.you_pilot ? "motors off now (key: Esc)"
      : "only the pilot can disarm: enter the pilot token under Pilot to take control";
    bar.classList.toggle("light", !s.dark);
    theme.textContent = s.dark ? "☀ light" : "☾ dark";
  };
  setInterval(() => { if (u.state && Date.now() - u.last > LOST_MS) showBanner(true); }, 250);
  // ------------------------------------------------------------ the pilot's token, for reconnects
  // viser's client assigns its sendMessage at each (re)connection: every message the page
  // sends passes through watch(), and each assignment is a new connection.
  const kept = {
    get: () => { try { return sessionStorage.getItem(TOKEN_KEY); } catch (e) { return null; } },
    set: (t) => { try { sessionStorage.setItem(TOKEN_KEY, t); } catch (e) {} },
    drop: () => { try { sessionStorage.removeItem(TOKEN_KEY); } catch (e) {} },
  };
  u.connection = 0;
  const watch = (msg) => {
    const s = u.state;
    if (!msg || msg.type !== "GuiUpdateMessage" || !msg.updates) return;
    if (!s) {  // typed before the bar's first state came (a slow link): judged when it comes
      u.early = (u.early || []).concat([msg]).slice(-20);
      return;
    }
    if (msg.uuid === s.token_uuid) u.typed = msg.updates.value;
    else if (msg.uuid === s.take_uuid && typeof u.typed === "string" && u.typed) u.offered = u.typed;
  };
  const client = %(viser_client)s;
  if (client && !client.__ucatWatched) {
    let wrapped = null;
    const wrap = (f) => (typeof f === "function" ? (msg) => { watch(msg); return f(msg); } : f);
    wrapped = wrap(client.sendMessage);
    Object.defineProperty(client, "sendMessage", {configurable: true, get: () => wrapped,
      set: (f) => { wrapped = wrap(f); u.connection += 1; }});
    client.__ucatWatched = true;
  }
  u.token = (s) => {
    // the loading page's state (the console still starting: no token box, nobody can fly):
    // the token is judged against the console's first state
    if (!s.token_uuid) return;
    if (u.early) { const early = u.early; u.early = null; early.forEach(watch); }
    const token = kept.get();
    if (u.tokenConnection !== u.connection) {  // the first state on a new connection (or a reload)
      u.tokenConnection = u.connection; u.wasPilot = false; u.resent = 0;
      if (token && !s.you_pilot) {
        // back after a lost link or a restart: when nobody flies, the token again, checked as
        // any; when another page flies, this one is a viewer now and forgets it
        if (s.pilot === "none" && send(s.token_uuid, token) && send(s.take_uuid, true)) u.resent = Date.now();
        else kept.drop();
        return;
      }
    }
    if (s.you_pilot) {
      u.wasPilot = true;
      if (u.offered) { kept.set(u.offered); u.offered = null; }
    } else if (u.wasPilot) {  // control left this page while it stayed connected: released or handed over
      kept.drop(); u.wasPilot = false;
    } else if (token && u.resent && Date.now() - u.resent > RESEND_GIVE_UP_MS) {
      kept.drop();  // not taken (a new token, or another page was first): presented once, not again
    }
  };
  // ------------------------------------------------------------ number boxes
  // viser sends nothing for a number box left empty or holding no number ("abc"), so the box
  // would stay blank while the value in force is another: on leaving it, the box gets back
  // the number it held (and sends it, the value in force, through its own input).
  const numberBox = (e) => e && e.tagName === "INPUT" && e.closest && e.closest(".mantine-NumberInput-root");
  const setNative = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set;
  document.addEventListener("focusin", (ev) => { const e = ev.target;
    if (numberBox(e)) e.dataset.ucatBefore = e.value; }, true);
  document.addEventListener("focusout", (ev) => { const e = ev.target;
    if (!numberBox(e) || e.dataset.ucatBefore === undefined) return;
    const text = e.value.trim();
    if (text === "" || text === "-" || !isFinite(Number(text.replace(/,/g, "")))) {
      setNative.call(e, e.dataset.ucatBefore);
      e.dispatchEvent(new Event("input", {bubbles: true}));
    }
  }, true);
  // ------------------------------------------------------------ gamepad
  const axis = (v) => (Math.abs(v) < DEAD ? 0 : (v - Math.sign(v) * DEAD) / (1 - DEAD));
  const padSend = (cmd) => {
    const s = u.state; if (!s) return;
    const key = JSON.stringify(cmd);
    const now = Date.now();
    const moving = cmd.v !== 0 || cmd.r !== 0 || cmd.dz !== 0;
    if (key === u.pad.sent && !(moving && now - u.pad.at > 500)) return;
    if (send(s.drive_uuid, key)) { u.pad.sent = key; u.pad.at = now; }
  };
  const stopPad = () => { if (u.pad.active) { padSend({v: 0, r: 0, dz: 0, stop: 1}); u.pad.active = false; } };
  window.addEventListener("blur", stopPad);
  window.addEventListener("gamepaddisconnected", stopPad);
  setInterval(() => {
    const s = u.state;
    u.pad.polls += 1;
    if (!s || !s.you_pilot || !navigator.getGamepads || !document.hasFocus()) { stopPad(); return; }
    const pad = Array.from(navigator.getGamepads()).find((p) => p && p.connected);
    if (!pad) { stopPad(); return; }
    if (pad.buttons[1] && pad.buttons[1].pressed && s.armed) { send(s.disarm_uuid, true); }
    const cmd = {v: -axis(pad.axes[1] || 0), r: axis(pad.axes[0] || 0), dz: axis(pad.axes[3] || 0)};
    cmd.v = Math.round(cmd.v * 100) / 100; cmd.r = Math.round(cmd.r * 100) / 100;
    cmd.dz = Math.round(cmd.dz * 100) / 100;
    if (cmd.v !== 0 || cmd.r !== 0 || cmd.dz !== 0) u.pad.active = true;
    if (u.pad.active) padSend(cmd);
  }, 100);
})();
""" % {"lost_ms": int(LINK_LOST_AFTER * 1000), "dead": DEAD_ZONE, "viser_client": PAGE_CLIENT,
       "token_key": TOKEN_KEY, "give_up_ms": int(RESEND_GIVE_UP * 1000)}


def update_source(state: dict[str, Any]) -> str:
    """The script that shows ``state`` in the bar (JSON is a JavaScript literal)."""
    return f"window.__ucat && window.__ucat.render({json.dumps(state, allow_nan=False)});"


def parse_drive(text: object) -> tuple[float, float, float, bool]:
    """``(velocity, yaw_rate, depth_rate, stop)`` fractions in [-1, 1] from the gamepad's
    message, or ValueError naming what is wrong."""
    if not isinstance(text, str) or len(text) > 200:
        raise ValueError("gamepad: expected a short JSON object")
    try:
        d = json.loads(text)
    except ValueError:
        raise ValueError("gamepad: not JSON") from None
    if not isinstance(d, dict) or not {"v", "r", "dz"} <= set(d) or set(d) - {"v", "r", "dz", "stop"}:
        raise ValueError("gamepad: expected the keys v, r, dz")
    out = []
    for k in ("v", "r", "dz"):
        x = d[k]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not -1.0 <= x <= 1.0:
            raise ValueError(f"gamepad: {k} must be a number in [-1, 1], got {x!r}")
        out.append(float(x))
    return out[0], out[1], out[2], bool(d.get("stop"))
