"""The pilot's commands to the robot's devices: fault injection on the simulated rig, drive
fault resets and depth zeroing on a robot with drives and a pressure sensor.

:class:`RigControl` reaches the console through a :class:`RigHost`, the few things these
commands need (the pilot check, the arming gate, the loop's thread, the events channel),
not the supervisor.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Protocol

from ucat_console.backend.access import Actor, actor_name
from ucat_console.backend.loop.commands import CommandRefused
from ucat_console.telemetry.events import Event

if TYPE_CHECKING:
    from ucat_console.backend.sim_rig import SimRig


class DeviceGate(Protocol):
    """What the commands use of the arming gate (``backend.arming.ArmingGate``)."""

    @property
    def armed(self) -> bool: ...
    @property
    def has_drives(self) -> bool: ...
    def reset_drive_faults(self) -> bool: ...
    def zero_depth(self) -> float: ...


@dataclass(frozen=True)
class RigHost:
    """What the device commands use of the console."""

    #: the configured robot (``AppConfig.robot``), for the refusals
    robot: str
    #: the simulated rig behind the drivers (robot ``sim-devices``), else None
    rig: SimRig | None
    gate: DeviceGate
    require_pilot: Callable[[Actor, str], None]
    #: run a function in the loop's thread, at its next event, and return its result
    in_loop: Callable[[Callable[[], Any]], Any]
    #: ``publish_event(source, code, message, level, data)`` onto the events channel
    publish_event: Callable[..., Event]
    #: the operator's view changed
    notify: Callable[[], None]
    #: ``leak(water)``: water at the emulated leak detector, or dry, and its event (None: no emulated detector)
    leak: Callable[[bool], Event] | None = None


class RigControl:
    def __init__(self, host: RigHost) -> None:
        self.host = host

    def _rig(self, what: str) -> SimRig:
        host = self.host
        if host.rig is None:
            raise CommandRefused(
                f"{what}: only the simulated robot behind the device emulators takes faults "
                f"(robot = 'sim-devices'); this console runs robot {host.robot!r}"
            )
        return host.rig

    def fault_tables(self) -> tuple[dict[str, tuple[str, ...]], int]:
        """(the faults each emulated device takes, the default EMCY code) for the page's
        inputs; CommandRefused when the robot is not the simulated rig."""
        self._rig("fault injection")
        from ucat_console.backend.sim_rig import DEFAULT_EMCY, EMULATOR_FAULTS

        return ({**EMULATOR_FAULTS, "leak": ("water",)} if self.host.leak else EMULATOR_FAULTS), DEFAULT_EMCY

    def _names(self, who: Actor, device: object, fault: object, fault_optional: bool) -> SimRig:
        self.host.require_pilot(who, "fault injection")
        rig = self._rig("fault injection")
        if not isinstance(device, str) or not (isinstance(fault, str) or (fault_optional and fault is None)):
            raise CommandRefused(f"fault injection: device and fault must be names, got {device!r}, {fault!r}")
        return rig

    def inject_fault(self, who: Actor, device: object, fault: object, **kw: Any) -> Event:
        """Start an emulator fault on the simulated rig (the pilot rehearsing a failsafe).

        Arguments as :meth:`SimRig.inject`; its ``fault_injected`` event and every event the
        fault causes reach the events channel (and the recording)."""
        rig = self._names(who, device, fault, False)
        if device == "leak" and self.host.leak is not None:  # the console's emulated leak detector
            if fault != "water" or kw:
                raise CommandRefused(f"fault injection: the leak detector takes only 'water', without arguments "
                                     f"(it lasts until cleared); got {fault!r} {kw or ''}")
            event = self.host.leak(True)
            self.host.notify()
            return event
        try:
            event = rig.inject(device, fault, **kw)  # type: ignore[arg-type]
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self.host.notify()
        return event

    def clear_fault(self, who: Actor, device: object, fault: object = None) -> None:
        """End one emulator fault of ``device`` on the simulated rig, or all of its faults."""
        rig = self._names(who, device, fault, True)
        if device == "leak" and self.host.leak is not None and fault in (None, "water"):
            self.host.leak(False)
            self.host.notify()
            return
        try:
            rig.clear(device, fault)  # type: ignore[arg-type]
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self.host.notify()

    def reset_drive_faults(self, who: Actor) -> None:
        """Reset the drives in fault (after an EMCY), disarmed; they are powered at arming."""
        host = self.host
        host.require_pilot(who, "drive fault reset")
        if not host.gate.has_drives:
            raise CommandRefused(f"drive fault reset: robot {host.robot!r} has no motor drives")
        if host.gate.armed:
            raise CommandRefused("drive fault reset: disarm first")
        ok = host.in_loop(host.gate.reset_drive_faults)
        host.publish_event("operator", "drive_fault_reset",
                           f"{actor_name(who)} reset the drive faults" + ("" if ok else ": not every drive left its fault"),
                           "info" if ok else "error", {"who": str(who), "ok": ok})
        host.notify()
        if not ok:
            raise CommandRefused("drive fault reset: not every drive left its fault (see its events)")

    def zero_depth(self, who: Actor) -> float:
        """Take the present pressure as the surface's (disarmed, the robot at the surface);
        the surface pressure (Pa)."""
        host = self.host
        host.require_pilot(who, "depth zeroing")
        if host.gate.armed:
            raise CommandRefused("depth zeroing: disarm first, with the robot floating at the surface")
        try:  # in the caller's thread: it waits for the sensor's next readings, the loop runs on
            p = host.gate.zero_depth()
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        host.publish_event("operator", "depth_zeroed", f"{actor_name(who)} zeroed the depth at "
                           f"{p:.1f} Pa", "info", {"who": str(who), "surface_pressure_pa": p})
        return p
