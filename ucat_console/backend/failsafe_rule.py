"""One failsafe's rule: what it does when its cause has lasted ``timeout`` s (hold, surface,
disarm or warn) and what it does when the cause lasts on. The failsafes' configuration
(:mod:`~ucat_console.backend.failsafe_config`) holds one for each failsafe; a registered
sensor (:mod:`~ucat_console.backend.sensors`) names its own default.
"""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.typedconf import Config, param

#: the console's own failsafes, in display order: each a field of ``FailsafeConfig`` (a
#: registered sensor's failsafe takes another name, ``backend.sensors``)
FIXED_FAILSAFES = ("pilot_gone", "imu", "dvl", "depth", "motor", "planner_late", "tracking", "recording",
                   "loop_watchdog", "depth_limit", "altitude", "battery_low", "battery_critical", "estimate")
#: what a failsafe does when it triggers
FAILSAFE_ACTIONS = ("hold", "surface", "disarm", "warn")
#: how strongly each action acts: an escalation acts more strongly than the action before it
ACTION_STRENGTH = {"warn": 0, "hold": 1, "surface": 2, "disarm": 3}
#: what a failsafe may do when its cause lasts on (``none``: nothing more)
ESCALATIONS = ("none", "hold", "surface", "disarm")


ESCALATE_DOC = ("what the failsafe does when its cause lasts escalate_after s after it triggered: "
                 "none (nothing more), hold, surface or disarm")
_ESCALATE_AFTER_DOC = "how long the failsafe acts before it escalates"


@dataclass(frozen=True)
class FailsafeRule(Config):
    """What one failsafe does, after how long its cause triggers it, and what it does when the
    cause lasts on (``escalate``, ``escalate_after`` s after it triggered)."""

    action: str = param(
        "hold", choices=FAILSAFE_ACTIONS,
        doc="hold: stop and hold the present depth; surface: stop and rise to 0 m; "
        "disarm: motors off; warn: show and record only",
    )
    timeout: float = param(2.0, lo=0.0, hi=3600.0, unit="s", doc="how long the cause lasts before it triggers")
    escalate: str = param("none", choices=ESCALATIONS, doc=ESCALATE_DOC)
    escalate_after: float = param(30.0, lo=0.0, hi=3600.0, unit="s", doc=_ESCALATE_AFTER_DOC)

    def _check(self) -> None:
        if self.escalate != "none" and ACTION_STRENGTH[self.escalate] < ACTION_STRENGTH[self.action]:
            stronger = [a for a in ESCALATIONS[1:] if ACTION_STRENGTH[a] >= ACTION_STRENGTH[self.action]]
            raise ValueError(f"escalate: {self.escalate!r} would act less strongly than action "
                             f"{self.action!r}; allowed: none, {', '.join(stronger)}")

    @property
    def escalates(self) -> bool:
        """Whether the escalation acts more strongly than the action (otherwise it is none)."""
        return self.escalate != "none" and ACTION_STRENGTH[self.escalate] > ACTION_STRENGTH[self.action]
