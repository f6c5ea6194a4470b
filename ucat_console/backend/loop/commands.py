"""What the supervisor and the page ask of the closed loop, from any thread.

:class:`LoopCommands` holds what the loop is commanded to do (mode, setpoints, the MPC and
baseline configurations, the PID gains): each request is checked at once, in the caller's
thread (a bad one raises ValueError naming what is wrong, and nothing changes), recorded as
commanded (what the supervisor and the page read back), and queued; the loop's thread
applies the queue at its next event (:meth:`LoopCommands.drain`), through the narrow
:class:`CommandTarget` the loop gives it.
"""

from __future__ import annotations

import queue
import threading
from typing import Any, Callable, Protocol

from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.loop.modes import mode
from ucat_console.control.allocation import BodySetpoints
from ucat_console.control.mpc import check_config
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains

PID_LOOPS = ("velocity", "depth", "yaw_rate")


def check_setpoints(cfg: LoopConfig, sp: BodySetpoints) -> BodySetpoints:
    """``sp`` if it lies inside the envelope of ``cfg``, else ValueError naming the value."""
    return sp.within(cfg.max_velocity, cfg.max_depth, cfg.max_yaw_rate)


class CommandTarget(Protocol):
    """What the loop's thread does with each command (at loop time ``t``)."""

    def apply_setpoints(self, sp: BodySetpoints, t: float) -> None: ...
    def apply_mode(self, mode: str, t: float, who: str) -> None: ...
    def apply_block(self, block: str, cfg: Any, t: float, who: str) -> None: ...
    def apply_gains(self, loop: str, gains: PidGains, t: float, who: str) -> None: ...
    def apply_restart(self, t: float) -> None: ...


class LoopCommands:
    """The loop's commanded state and its queue of commands (module docstring)."""

    def __init__(self, cfg: LoopConfig, setpoints: BodySetpoints, target: CommandTarget) -> None:
        self._cfg = cfg
        self._target = target
        self._lock = threading.Lock()
        self._commanded: dict[str, Any] = {
            "mode": cfg.mode, "setpoints": self.check_setpoints(setpoints), "mpc": cfg.mpc, "baseline": cfg.baseline,
            **{f"pid.{loop}": getattr(cfg.body, loop) for loop in PID_LOOPS},
        }
        self._queue: queue.SimpleQueue[Callable[[float], None]] = queue.SimpleQueue()

    # ------------------------------------------------------------------ what is commanded
    @property
    def mode(self) -> str:
        return self._commanded["mode"]

    @property
    def setpoints(self) -> BodySetpoints:
        return self._commanded["setpoints"]

    @property
    def mpc_config(self) -> MpcConfig:
        return self._commanded["mpc"]

    @property
    def baseline_config(self) -> BaselineConfig:
        return self._commanded["baseline"]

    def pid_gains(self, loop: str) -> PidGains:
        """The gains of the body-frame PID ``loop`` ("velocity", "depth" or "yaw_rate")."""
        return self._commanded[f"pid.{_pid_loop(loop)}"]

    # ------------------------------------------------------------------ requests
    def check_setpoints(self, sp: BodySetpoints) -> BodySetpoints:
        """``sp`` if it lies inside the configured envelope, else ValueError naming the value."""
        return check_setpoints(self._cfg, sp)

    def set_setpoints(self, velocity: float | None = None, depth: float | None = None,
                      yaw_rate: float | None = None) -> BodySetpoints:
        """New setpoints (unchanged where None), checked against the envelope now; the
        setpoints commanded before (they are in force from the next event)."""
        with self._lock:
            cur = self._commanded["setpoints"]
            sp = self.check_setpoints(BodySetpoints(
                velocity=cur.velocity if velocity is None else velocity,
                depth=cur.depth if depth is None else depth,
                yaw_rate=cur.yaw_rate if yaw_rate is None else yaw_rate,
            ))
            self._commanded["setpoints"] = sp
            self._queue.put(lambda t: self._target.apply_setpoints(sp, t))
        return cur

    def set_mode(self, name: str, who: str = "") -> str:
        """Switch the fin controller while swimming (bumpless; an Event with code "mode"
        naming ``who``); the mode commanded before."""
        mode(name)  # a mode of the registry, else ValueError naming them
        with self._lock:
            old = self._commanded["mode"]
            self._commanded["mode"] = name
            self._queue.put(lambda t: self._target.apply_mode(name, t, who))
        return old

    def set_mpc_config(self, cfg: MpcConfig, who: str = "") -> None:
        """New MPC configuration (e.g. ``loop.mpc_config.replace(lam_st=2.0)``) from the next plan."""
        if not isinstance(cfg, MpcConfig):
            raise ValueError(f"mpc config: expected an MpcConfig, got {type(cfg).__name__}")
        check_config(cfg)  # a configuration the planner refuses fails here, in the caller
        self._command("mpc", cfg, lambda t: self._target.apply_block("mpc", cfg, t, who))

    def set_baseline_config(self, cfg: BaselineConfig, who: str = "") -> None:
        if not isinstance(cfg, BaselineConfig):
            raise ValueError(f"baseline config: expected a BaselineConfig, got {type(cfg).__name__}")
        self._command("baseline", cfg, lambda t: self._target.apply_block("baseline", cfg, t, who))

    def set_pid_gains(self, loop: str, gains: PidGains, who: str = "") -> None:
        """New gains of one body-frame PID ("velocity", "depth" or "yaw_rate")."""
        _pid_loop(loop)
        if not isinstance(gains, PidGains):
            raise ValueError(f"gains: expected PidGains, got {type(gains).__name__}")
        self._command(f"pid.{loop}", gains, lambda t: self._target.apply_gains(loop, gains, t, who))

    def restart(self) -> None:
        """Start the body loops and every fin afresh at the next event."""
        self._queue.put(self._target.apply_restart)

    def _command(self, key: str, value: Any, apply: Callable[[float], None]) -> None:
        with self._lock:
            self._commanded[key] = value
            self._queue.put(apply)

    # ------------------------------------------------------------------ the loop's thread
    @property
    def waiting(self) -> bool:
        return not self._queue.empty()

    def drain(self, t: float) -> None:
        """Apply every queued command, in order, at loop time ``t``."""
        while True:
            try:
                fn = self._queue.get_nowait()
            except queue.Empty:
                return
            fn(t)


def _pid_loop(loop: str) -> str:
    if loop not in PID_LOOPS:
        raise ValueError(f"loop: {loop!r} is not one of {', '.join(PID_LOOPS)}")
    return loop
