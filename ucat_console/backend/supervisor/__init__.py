"""The supervisor and its parts (one module each): the robot's clock (``robots``), live tuning and its journal (``tuning``), the two-step arming (``arm_requests``), recording (``recording``),
the device commands (``rig_control``), the identification manoeuvre (``manoeuvre``), the
loop's stream onto the public one (``forwarding``), the health line (``health``), the
console as the page shows it (``console_state``: one immutable snapshot), and the
:class:`Supervisor` that holds them together (``supervisor``). Refused commands raise
:class:`CommandRefused` (``backend.loop.commands``, where the loop's commands are)."""

from ucat_console.backend.loop.commands import CommandRefused
from ucat_console.backend.supervisor.console_state import ConsoleState
from ucat_console.backend.supervisor.health import Health
from ucat_console.backend.supervisor.robots import RobotFactory, SteadyPacedClock
from ucat_console.backend.supervisor.supervisor import SETPOINTS, Supervisor
from ucat_console.backend.supervisor.tuning import JournalEntry

__all__ = ["CommandRefused", "ConsoleState", "Health", "RobotFactory", "SETPOINTS", "SteadyPacedClock", "Supervisor",
           "JournalEntry"]
