"""CiA 402 / CiA 301 facts used by the EPOS2 driver and its emulator (devices.md).

Controlword commands, statusword bits and state masks, object indices, NMT command codes
and the EMCY error-code table. Both sides of the bus read them from here.

The state masks and the standard controlword commands are canopen's
(``canopen.profiles.p402.State402``), renamed to this project's state names; what the
profile table does not hold is the EPOS2's own use of the controlword (quick stop with the
enable bits kept, new set-point "change immediately", halt) and the bits of profile
position mode (set-point acknowledge, target reached). Why the driver does not run on
canopen's ``BaseNode402`` is in ``epos2.py``'s docstring.
"""

from __future__ import annotations

from canopen.profiles.p402 import State402

# --- object dictionary indices -------------------------------------------------------------
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
CONSUMER_HEARTBEAT_TIME = 0x1016
PRODUCER_HEARTBEAT_TIME = 0x1017
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
CURRENT_ACTUAL = 0x6078
TARGET_POSITION = 0x607A
PROFILE_VELOCITY = 0x6081
PROFILE_ACCELERATION = 0x6083
PROFILE_DECELERATION = 0x6084
QUICK_STOP_DECELERATION = 0x6085
SUPPORTED_DRIVE_MODES = 0x6502
# maxon's own objects (EPOS2 Firmware Specification, rel5466): motor current averaged by the
# drive (INT16, mA) and the supply voltage at the power stage (0x2200 sub 1, UINT16, 0.1 V)
CURRENT_ACTUAL_AVERAGED = 0x2027
POWER_SUPPLY = 0x2200
POWER_SUPPLY_VOLTAGE_SUB = 1
#: volts per unit of 0x2200 sub 1
POWER_SUPPLY_VOLTAGE_UNIT = 0.1
#: amperes per unit of 0x6078 and 0x2027
CURRENT_UNIT = 0.001

#: device profile number in the low 16 bits of 0x1000
PROFILE_402 = 402

# --- modes of operation (0x6060, INT8) ------------------------------------------------------
MODE_PROFILE_POSITION = 1
MODE_PROFILE_VELOCITY = 3
MODE_HOMING = 6
#: bit of each mode in 0x6502 supported drive modes
MODE_SUPPORT_BIT = {MODE_PROFILE_POSITION: 0, MODE_PROFILE_VELOCITY: 2, MODE_HOMING: 5}

# --- controlword (0x6040) ---------------------------------------------------------------------
CW_SWITCH_ON = 1 << 0
CW_ENABLE_VOLTAGE = 1 << 1
CW_QUICK_STOP = 1 << 2  # active low: 0 requests a quick stop
CW_ENABLE_OPERATION = 1 << 3
CW_NEW_SETPOINT = 1 << 4
CW_CHANGE_IMMEDIATELY = 1 << 5
CW_RELATIVE = 1 << 6
CW_FAULT_RESET = 1 << 7
CW_HALT = 1 << 8

DISABLE_VOLTAGE = State402.CW_DISABLE_VOLTAGE
SHUTDOWN = State402.CW_SHUTDOWN
SWITCH_ON = State402.CW_SWITCH_ON
ENABLE_OPERATION = State402.CW_OPERATION_ENABLED
QUICK_STOP = 0x000B  # quick stop (bit 2 low) with voltage and operation still enabled
FAULT_RESET = State402.CW_SWITCH_ON_DISABLED  # bit 7: fault reset (transition 15)
NEW_SETPOINT_IMMEDIATE = 0x003F
HALT = 0x010F

# --- statusword (0x6041) ----------------------------------------------------------------------
SW_READY_TO_SWITCH_ON = 1 << 0
SW_SWITCHED_ON = 1 << 1
SW_OPERATION_ENABLED = 1 << 2
SW_FAULT = 1 << 3
SW_VOLTAGE_ENABLED = 1 << 4
SW_QUICK_STOP = 1 << 5  # active low: 0 while a quick stop is active
SW_SWITCH_ON_DISABLED = 1 << 6
SW_WARNING = 1 << 7
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_SETPOINT_ACK = 1 << 12
SW_FOLLOWING_ERROR = 1 << 13

NOT_READY = "not_ready_to_switch_on"
SWITCH_ON_DISABLED = "switch_on_disabled"
READY_TO_SWITCH_ON = "ready_to_switch_on"
SWITCHED_ON = "switched_on"
OPERATION_ENABLED = "operation_enabled"
QUICK_STOP_ACTIVE = "quick_stop_active"
FAULT_REACTION_ACTIVE = "fault_reaction_active"
FAULT = "fault"
UNKNOWN = "unknown"

#: (state, mask, value): the state is current when ``statusword & mask == value``
#: (canopen's table, State402.SW_MASK)
STATE_MASKS: tuple[tuple[str, int, int], ...] = tuple(
    (name.lower().replace(" ", "_"), mask, value)
    for name, (mask, value) in State402.SW_MASK.items()
)
_MASK_OF = {name: (mask, value) for name, mask, value in STATE_MASKS}


def state_of(statusword: int) -> str:
    """The CiA 402 state a statusword shows (``"unknown"`` if no mask matches)."""
    for name, mask, value in STATE_MASKS:
        if statusword & mask == value:
            return name
    return UNKNOWN


def is_state(statusword: int, state: str) -> bool:
    mask, value = _MASK_OF[state]
    return statusword & mask == value


# --- NMT (CiA 301) ----------------------------------------------------------------------------
NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
#: states as heartbeats carry them
NMT_BOOTUP = 0x00
NMT_STOPPED = 0x04
NMT_OPERATIONAL = 0x05
NMT_PRE_OP_STATE = 0x7F
NMT_STATE_NAMES = {
    NMT_BOOTUP: "boot-up",
    NMT_STOPPED: "stopped",
    NMT_OPERATIONAL: "operational",
    NMT_PRE_OP_STATE: "pre-operational",
}

# --- EMCY -------------------------------------------------------------------------------------
EMCY_NAMES: dict[int, str] = {
    0x0000: "no error",
    0x2310: "overcurrent",
    0x3210: "overvoltage",
    0x3220: "undervoltage",
    0x4210: "overtemperature",
    0x8611: "following error",
    0x81FD: "CAN bus off",
    0x8130: "CAN life guard error",
}
#: CiA 301 error classes (mask, value, name) for codes not in EMCY_NAMES
_EMCY_CLASSES: tuple[tuple[int, int, str], ...] = (
    (0xFF00, 0xFF00, "device specific"),
    (0xFF00, 0x1000, "generic error"),
    (0xF000, 0x2000, "current"),
    (0xF000, 0x3000, "voltage"),
    (0xF000, 0x4000, "temperature"),
    (0xFF00, 0x5000, "device hardware"),
    (0xF000, 0x6000, "device software"),
    (0xFF00, 0x7000, "additional modules"),
    (0xFF00, 0x8100, "communication"),
    (0xFF00, 0x8200, "protocol error"),
    (0xF000, 0x8000, "monitoring"),
    (0xFF00, 0x9000, "external error"),
)
#: error register (0x1001) bits by error class, CiA 301
ERROR_REGISTER_GENERIC = 0x01
_REGISTER_BITS: tuple[tuple[int, int, int], ...] = (
    (0xF000, 0x2000, 0x02),  # current
    (0xF000, 0x3000, 0x04),  # voltage
    (0xF000, 0x4000, 0x08),  # temperature
    (0xFF00, 0x8100, 0x10),  # communication
    (0xFF00, 0xFF00, 0x80),  # manufacturer specific
)

#: EMCY error code: PDO not processed because of a length error (CiA 301)
EMCY_PDO_LENGTH = 0x8210
EMCY_LIFE_GUARD = 0x8130


def emcy_name(code: int) -> str:
    """Name of an EMCY error code: the EPOS2 table first, then the CiA 301 class."""
    if code in EMCY_NAMES:
        return EMCY_NAMES[code]
    for mask, value, name in _EMCY_CLASSES:
        if code & mask == value:
            return f"{name} (0x{code:04X})"
    return f"unlisted error (0x{code:04X})"


def error_register_for(code: int) -> int:
    """The 0x1001 error register a device sets together with an EMCY code."""
    if code == 0:
        return 0
    register = ERROR_REGISTER_GENERIC
    for mask, value, bit in _REGISTER_BITS:
        if code & mask == value:
            register |= bit
    return register
