"""Recording sessions: on demand, and automatically from arming until a tail after
disarming. :class:`SessionRecording` owns whether the present recording was started by
arming (and so stops by itself) or by the operator.

The tail covers a fault's clearing: an automatic recording stops ``tail`` s after the later
of the disarm and the moment the last fault (an active failsafe, a drive fault not reported
cleared) was seen, so a fault's clearing is in the file; at most ``tail_max`` s after the
disarm, so a fault that never clears does not record for ever."""

from __future__ import annotations

import logging
import math
import threading
from pathlib import Path
from typing import Callable

from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.backend.loop.commands import CommandRefused

log = logging.getLogger(__name__)

#: the longest notes of a recording (characters)
MAX_NOTES = 2000


class SessionRecording:
    """``config_toml()``, ``weights()`` and ``config_name`` (the name the configuration was
    loaded by) give what a new recording stores; ``tail`` is how
    long an automatic recording runs on after disarming and after the last fault cleared,
    ``tail_max`` how long at most after disarming; ``on_arm``: record on arming."""

    def __init__(self, recorder: Recorder, *, config_toml: Callable[[], str], weights: Callable[[], dict],
                 on_arm: bool, tail: float, notify: Callable[[], None], tail_max: float = math.inf,
                 config_name: str = "") -> None:
        self.recorder = recorder
        self._config_toml = config_toml
        self.config_name = config_name
        self._weights = weights
        self.on_arm = on_arm
        self.tail = tail
        self.tail_max = tail_max
        self._notify = notify
        self._auto = False
        self._disarmed_at: float | None = None
        self._fault_seen: float | None = None  # the last check at which a fault was active

    @property
    def recording(self) -> bool:
        return self.recorder.recording

    @property
    def session_id(self) -> str:
        return self.recorder.session_id if self.recorder.recording else ""

    @property
    def failed(self) -> str:
        """Why the recording stopped on its own ("" when it did not; until it is started
        again or stopped)."""
        return self.recorder.failed

    def _start(self, label: str = "", notes: str = "") -> str:
        return self.recorder.start(label=label, notes=notes, config_toml=self._config_toml(),
                                   weights=self._weights(), config_name=self.config_name)

    def start(self, notes: object = "") -> str:
        """The operator's recording; CommandRefused when one runs or the notes are bad."""
        if not isinstance(notes, str) or len(notes) > MAX_NOTES:
            raise CommandRefused(f"notes: expected text of at most {MAX_NOTES} characters")
        if self.recorder.recording:
            raise CommandRefused(f"record: already recording session {self.recorder.session_id}")
        sid = self._start(notes=notes)
        self._auto = False
        return sid

    def stop(self) -> list[Path]:
        """Stop recording, or acknowledge a failed recording."""
        if not self.recorder.recording and not self.recorder.failed:
            raise CommandRefused("record: not recording")
        paths = self.recorder.stop()
        self._auto = False
        return paths

    def armed(self) -> None:
        """Arming: start recording (first, so the file holds the moment of arming). Raises
        what the recorder raised; the caller decides that arming goes on."""
        self._disarmed_at = None
        self._fault_seen = None
        if self.on_arm and not self.recorder.recording:
            self._start(label="armed", notes="started on arming")
            self._auto = True

    def disarmed(self, now: float) -> None:
        self._disarmed_at = now

    def check(self, now: float, armed: bool, faulted: bool = False) -> None:
        """Stop an automatic recording ``tail`` s after disarming and after the last fault
        cleared (``faulted``: one is active now), at most ``tail_max`` s after disarming
        (between loop chunks)."""
        if faulted:
            self._fault_seen = now
        disarmed = self._disarmed_at
        if not self._auto or armed or disarmed is None or not self.recorder.recording:
            return
        quiet_since = disarmed if self._fault_seen is None else max(disarmed, self._fault_seen)
        if (not faulted and now - quiet_since >= self.tail) or now - disarmed >= self.tail_max:
            self._auto = False
            threading.Thread(target=self._stop_quietly, name="recorder-stop", daemon=True).start()

    def _stop_quietly(self) -> None:
        try:
            self.recorder.stop()
        except Exception:
            log.exception("stopping the recording failed")
        self._notify()
