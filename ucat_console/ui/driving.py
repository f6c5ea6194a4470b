"""Manual driving from a page: keys step the setpoints, a gamepad sets them continuously.

Keys (viser commands with hotkeys, so they are listed in the command palette, Ctrl+K, and
ignored while the cursor is in a text box): **W / S** forward velocity up / down by
``console.drive_velocity_step``, **Q / E** yaw rate left / right by
``console.drive_yaw_step``, **R / F** depth up / down by ``console.drive_depth_step``,
**Space** stops (velocity and yaw rate 0, depth kept), **Esc** disarms. Every step is
clamped to the loop's envelope (``loop.max_velocity``, ``max_yaw_rate``, ``max_depth``)
and journalled like a typed setpoint. A held key repeats; when the page loses focus the
browser stops sending it.

The gamepad (the page's script, :mod:`ucat_console.ui.page_script`) sends stick fractions
in [-1, 1] to a hidden input of the page: the velocity and yaw rate are those fractions of
the envelope, the depth moves at the fraction of ``console.drive_depth_rate``. These
setpoints are not journalled one by one (the stick sends several a second); the start and
end of gamepad driving are. Only the pilot's page drives; the page guard drops a viewer's
keys and stick before they reach here.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Protocol

from ucat_console.backend.supervisor import ConsoleState
from ucat_console.control.allocation import BodySetpoints
from ucat_console.ui.page_script import parse_drive

#: key -> (what, direction); the labels are the key map the page shows
KEYS: dict[str, tuple[str, float, str]] = {
    "W": ("velocity", +1.0, "faster"),
    "S": ("velocity", -1.0, "slower / back"),
    "Q": ("yaw_rate", -1.0, "turn left"),
    "E": ("yaw_rate", +1.0, "turn right"),
    "R": ("depth", -1.0, "up"),
    "F": ("depth", +1.0, "down"),
}
KEY_MAP = ("Keys: **W/S** velocity · **Q/E** turn · **R/F** up/down · **Space** stop · "
           "**Esc** DISARM · **M** marker (not while typing in a box)")


def clamp(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


class DrivingHost(Protocol):
    """What manual driving uses of the supervisor: its configuration, its snapshot (the
    envelope), the setpoints in force, and two commands."""

    cfg: Any  # the AppConfig the console started with

    @property
    def setpoints(self) -> BodySetpoints: ...
    def state(self) -> ConsoleState: ...
    def set_setpoints(self, who: Any, velocity: object = None, depth: object = None,
                      yaw_rate: object = None, quiet: bool = False) -> None: ...
    def note_gamepad(self, who: Any, driving: bool) -> None: ...


class Driving:
    """One page's manual driving (module docstring); ``act(fn)`` runs a command for the page
    (refusals shown there)."""

    def __init__(self, sup: DrivingHost, client: int, act: Callable[[Callable[[], Any]], Any]) -> None:
        self.sup = sup
        self.client = client
        self.act = act
        self._envelope = sup.state().limits.envelope()
        self._pad_last = 0.0
        self._pad_active = False

    def envelope(self) -> dict[str, tuple[float, float]]:
        return dict(self._envelope)

    def step(self, key: str) -> None:
        """One key press."""
        what, sign, _ = KEYS[key]
        c = self.sup.cfg.console
        size = {"velocity": c.drive_velocity_step, "yaw_rate": c.drive_yaw_step, "depth": c.drive_depth_step}[what]
        lo, hi = self.envelope()[what]
        value = round(clamp(getattr(self.sup.setpoints, what) + sign * size, lo, hi), 4)
        self.sup.set_setpoints(self.client, **{what: value})

    def stop(self) -> None:
        self.sup.set_setpoints(self.client, velocity=0.0, yaw_rate=0.0)

    def gamepad(self, text: object) -> None:
        """One gamepad message (JSON from the page's script)."""
        v, r, dz, stop = parse_drive(text)
        env = self.envelope()
        now = time.monotonic()
        dt = min(now - self._pad_last, 0.5) if self._pad_last else 0.0
        self._pad_last = now
        depth = self.sup.setpoints.depth
        if dz:
            lo, hi = env["depth"]
            depth = round(clamp(depth + dz * self.sup.cfg.console.drive_depth_rate * dt, lo, hi), 4)
        moving = bool(v or r or dz) and not stop
        if moving != self._pad_active:
            self.sup.note_gamepad(self.client, moving)
        self._pad_active = moving
        self.sup.set_setpoints(self.client, velocity=round(v * env["velocity"][1], 4),
                               yaw_rate=round(r * env["yaw_rate"][1], 4), depth=depth,
                               quiet=moving)
