"""Fault injection on the simulated rig's device emulators, from the Safety tab."""

from __future__ import annotations

import math
from typing import Any

from ucat_console.backend.supervisor import CommandRefused


class RigFaultInputs:
    """Fault injection on the simulated rig's device emulators (Safety tab): rehearsing what
    the console and the failsafes do when a drive faults or a sensor goes silent, garbled,
    invalid or slow. Only built when the robot is the simulated rig; only the pilot injects."""

    def __init__(self, gui: Any, tables: tuple[dict[str, tuple[str, ...]], int]) -> None:
        EMULATOR_FAULTS, DEFAULT_EMCY = tables  # the supervisor's (RigControl.fault_tables)
        self.faults_of = EMULATOR_FAULTS
        device = next(iter(EMULATOR_FAULTS))
        with gui.add_folder("Rig faults (simulated devices)", order=50.0):
            self.device = gui.add_dropdown("Device", tuple(EMULATOR_FAULTS), initial_value=device)
            self.fault = gui.add_dropdown("Fault", EMULATOR_FAULTS[device])
            self.fin = gui.add_number("Fin [0, 3]", 0, min=0, max=3, step=1, hint="EPOS2 faults: the fin's drive")
            self.code = gui.add_text("EMCY code", f"0x{DEFAULT_EMCY:04X}",
                                     hint="EPOS2 emcy: the error code the drive reports (0x2310: overcurrent)")
            self.duration = gui.add_number("Duration s (0: until cleared)", 0.0, min=0.0, max=3600.0, step=1.0,
                                           hint="the fault ends by itself after this long (not for emcy: "
                                                "a drive fault stays until reset)")
            self.inject = gui.add_button("Inject fault", color="orange")
            self.clear = gui.add_button("Clear the device's faults")

    def show_faults_of_device(self) -> None:
        faults = self.faults_of.get(self.device.value, ())
        self.fault.options = faults
        if faults and self.fault.value not in faults:
            self.fault.value = faults[0]

    def arguments(self) -> dict[str, Any]:
        """The typed arguments of the chosen fault; CommandRefused naming a bad entry."""
        kw: dict[str, Any] = {}
        epos2, emcy = self.device.value == "epos2", self.fault.value == "emcy"
        if epos2:
            fin = self.fin.value
            if not (isinstance(fin, (int, float)) and math.isfinite(fin) and fin == int(fin)):
                raise CommandRefused(f"fin: expected a fin index 0..3, got {fin!r}")
            kw["fin"] = int(fin)
        if epos2 and emcy:
            text = str(self.code.value).strip()
            try:
                kw["code"] = int(text, 0)
            except ValueError:
                raise CommandRefused(f"EMCY code: {text!r} is not a number; write it as e.g. 0x2310") from None
        elif self.duration.value:
            kw["duration"] = float(self.duration.value)
        return kw

    def enable(self, pilot: bool) -> None:
        for h in (self.device, self.fault, self.fin, self.code, self.duration, self.inject, self.clear):
            h.disabled = not pilot
