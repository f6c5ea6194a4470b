"""The identification manoeuvre on a running robot: :class:`ManoeuvreRun`.

The pilot's command: it records a session while the fins step through the manoeuvre
(mode "identify"), then puts the previous mode back and stops the recording (the console's
own act: it happens whoever flies by then, and at once when the robot is disarmed before
the end). ``start`` / ``poll`` / ``finish`` drive it without blocking (the supervisor
polls its run after every chunk of the loop); :meth:`ManoeuvreRun.wait` blocks (the
command line). The recorded session is fitted with
``backend.identification.identify_sessions``.

The run reaches the console through a :class:`ManoeuvreHost`, the few operator commands
and readings it needs (the supervisor's, checked as any operator's), not the supervisor.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ucat_console.backend.access import LOCAL, Actor
from ucat_console.backend.loop.commands import CommandRefused


@dataclass(frozen=True)
class ManoeuvreHost:
    """What a manoeuvre run uses of the console: the operator's commands it gives (each
    checked as the operator's own), and the state it follows."""

    require_pilot: Callable[[Actor, str], None]
    armed: Callable[[], bool]
    mode: Callable[[], str]
    set_mode: Callable[[Actor, str], None]
    #: the session being recorded, "" when none
    recording: Callable[[], str]
    start_recording: Callable[[Actor, str], str]
    stop_recording: Callable[[Actor], list[Path]]
    add_marker: Callable[[Actor, str], Any]
    #: the loop's time (s)
    time: Callable[[], float]
    #: the manoeuvre's steps (s)
    duration: float


class ManoeuvreRun:
    """The identification manoeuvre, once (module docstring)."""

    #: seconds recorded after the manoeuvre's last step
    TAIL_S = 2.0

    def __init__(self, host: ManoeuvreHost, who: Actor) -> None:
        self.host = host
        self.who = who
        self.session = ""
        self.paths: list[Path] = []
        self._previous = ""
        self._t0 = math.nan
        self._finished = False
        self._finishing = threading.Lock()  # the supervisor's thread polls, a waiting caller too

    @property
    def duration(self) -> float:
        return self.host.duration + self.TAIL_S

    def start(self) -> str:
        """Start recording and the manoeuvre (pilot only, armed); returns the session id."""
        host = self.host
        host.require_pilot(self.who, "identification manoeuvre")
        if not host.armed():
            raise CommandRefused("identification manoeuvre: arm the motors first")
        if host.mode() == "identify":
            raise CommandRefused("identification manoeuvre: already running")
        self._previous = host.mode()
        self.session = host.recording() or host.start_recording(self.who, "identification manoeuvre")
        host.set_mode(self.who, "identify")
        host.add_marker(self.who, "identification manoeuvre starts")
        self._t0 = host.time()
        return self.session

    @property
    def progress(self) -> float:
        """Share of the manoeuvre done (0-1)."""
        if math.isnan(self._t0):
            return 0.0
        return min(1.0, max(0.0, (self.host.time() - self._t0) / self.duration))

    @property
    def finished(self) -> bool:
        return self._finished

    def poll(self) -> bool:
        """Finish when the manoeuvre is over (or the robot was disarmed); True once finished."""
        if self._finished:
            return True
        if self.progress >= 1.0 or not self.host.armed():
            self.finish()
            return True
        return False

    def finish(self) -> list[Path]:
        """The previous mode back, the recording stopped; the session's files (once,
        whichever thread comes first)."""
        with self._finishing:
            if self._finished:
                return self.paths
            try:
                host = self.host
                if host.mode() == "identify":
                    host.set_mode(LOCAL, self._previous or "mpc")
                if self.session and host.recording() == self.session:
                    self.paths = host.stop_recording(LOCAL)
            finally:  # finished from here on, with its files (a failure is not tried again)
                self._finished = True
            return self.paths

    def wait(self, poll_s: float = 0.2) -> list[Path]:
        """Block until the manoeuvre is over (a supervisor running in its own thread)."""
        while not self.poll():
            time.sleep(poll_s)
        return self.paths
