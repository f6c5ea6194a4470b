"""The pilot's commands to the robot's devices: fault injection on the simulated rig, drive
fault resets and depth zeroing on a robot with drives and a pressure sensor."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ucat_console.backend.access import Actor, actor_name
from ucat_console.backend.supervisor.commands import CommandRefused
from ucat_console.telemetry.events import Event

if TYPE_CHECKING:
    from ucat_console.backend.sim_rig import SimRig
    from ucat_console.backend.supervisor.supervisor import Supervisor


class RigControl:
    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup

    def _rig(self, what: str) -> SimRig:
        sup = self.sup
        if sup.rig is None:
            raise CommandRefused(
                f"{what}: only the simulated robot behind the device emulators takes faults "
                f"(robot = 'rig' with devices.robot = 'sim-devices'); this console runs robot "
                f"{sup.cfg.robot!r}"
            )
        return sup.rig

    def fault_tables(self) -> tuple[dict[str, tuple[str, ...]], int]:
        """(the faults each emulated device takes, the default EMCY code) for the page's
        inputs; CommandRefused when the robot is not the simulated rig."""
        self._rig("fault injection")
        from ucat_console.backend.sim_rig import DEFAULT_EMCY, EMULATOR_FAULTS

        return EMULATOR_FAULTS, DEFAULT_EMCY

    def inject_fault(self, who: Actor, device: object, fault: object, **kw: Any) -> Event:
        """Start an emulator fault on the simulated rig (the pilot rehearsing a failsafe).

        Arguments as :meth:`SimRig.inject`; its ``fault_injected`` event and every event the
        fault causes reach the events channel (and the recording)."""
        self.sup.access.require_pilot(who, "fault injection")
        rig = self._rig("fault injection")
        if not isinstance(device, str) or not isinstance(fault, str):
            raise CommandRefused(f"fault injection: device and fault must be names, got {device!r}, {fault!r}")
        try:
            event = rig.inject(device, fault, **kw)
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self.sup._notify()
        return event

    def clear_fault(self, who: Actor, device: object, fault: object = None) -> None:
        """End one emulator fault of ``device`` on the simulated rig, or all of its faults."""
        self.sup.access.require_pilot(who, "fault injection")
        rig = self._rig("fault injection")
        if not isinstance(device, str) or not (fault is None or isinstance(fault, str)):
            raise CommandRefused(f"fault injection: device and fault must be names, got {device!r}, {fault!r}")
        try:
            rig.clear(device, fault)
        except ValueError as e:
            raise CommandRefused(f"fault injection: {e}") from None
        self.sup._notify()

    def reset_drive_faults(self, who: Actor) -> None:
        """Reset the drives in fault (after an EMCY), disarmed; they are powered at arming."""
        sup = self.sup
        sup.access.require_pilot(who, "drive fault reset")
        if not sup.has_drives:
            raise CommandRefused(f"drive fault reset: robot {sup.cfg.robot!r} has no motor drives")
        if sup.gate.armed:
            raise CommandRefused("drive fault reset: disarm first")
        ok = sup.commands.run(sup.gate.reset_drive_faults)
        sup._publish_event("operator", "drive_fault_reset",
                           f"{actor_name(who)} reset the drive faults" + ("" if ok else ": not every drive left its fault"),
                           "info" if ok else "error", {"who": str(who), "ok": ok})
        sup._notify()
        if not ok:
            raise CommandRefused("drive fault reset: not every drive left its fault (see its events)")

    def zero_depth(self, who: Actor) -> float:
        """Take the present pressure as the surface's (disarmed, the robot at the surface);
        the surface pressure (Pa)."""
        sup = self.sup
        sup.access.require_pilot(who, "depth zeroing")
        if sup.gate.armed:
            raise CommandRefused("depth zeroing: disarm first, with the robot floating at the surface")
        try:  # in the caller's thread: it waits for the sensor's next readings, the loop runs on
            p = sup.gate.zero_depth()
        except ValueError as e:
            raise CommandRefused(str(e)) from None
        sup._publish_event("operator", "depth_zeroed", f"{actor_name(who)} zeroed the depth at "
                           f"{p:.1f} Pa", "info", {"who": str(who), "surface_pressure_pa": p})
        return p
