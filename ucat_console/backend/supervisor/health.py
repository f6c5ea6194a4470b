"""What the terminal's health line shows."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Health:
    t: float
    mode: str
    armed: bool
    lag: float  # s the loop is behind the wall clock now
    lag_max: float
    late_plans: int
    plan_overruns: int
    failsafes: tuple[str, ...]
    clients: int
    pilot: str
    recording: str
    fault: str
    recording_failed: str = ""  # why the recording stopped on its own
    stalls: int = 0  # the loop skipped ahead after falling more than console.max_lag behind

    def line(self) -> str:
        fs = ",".join(self.failsafes) or "none"
        parts = [
            f"t={self.t:7.1f}s", f"mode={self.mode}", "ARMED" if self.armed else "disarmed",
            f"lag={self.lag * 1e3:.0f}ms(max {self.lag_max * 1e3:.0f})",
            f"late_plans={self.late_plans}", f"overruns={self.plan_overruns}", f"stalls={self.stalls}",
            f"failsafes={fs}", f"clients={self.clients}", f"pilot={self.pilot or 'none'}",
            f"rec={'FAILED' if self.recording_failed else (self.recording or 'off')}",
        ]
        if self.fault:
            parts.append(f"FAULT={self.fault}")
        return " ".join(parts)
