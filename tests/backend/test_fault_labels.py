"""Each sensor and drive fault, injected in the emulators of the simulated rig, reaches the
failsafes with a label that says what happened: silent, garbled, invalid; a drive's fault
names the drive and what it reported."""

from __future__ import annotations


import pytest
from support import wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.supervisor import Supervisor
from ucat_console.config import AccessConfig, FailsafeRule, load_config

pytestmark = pytest.mark.slow

TOKEN = "fault-label-token"
PILOT = 1
SENSOR_OF = {"imu": "imu", "dvl": "dvl", "pressure": "depth"}
#: (device, fault injected) -> what the failsafe's cause must say
SENSOR_FAULTS = [
    ("imu", "silence", "(silent)"), ("imu", "corrupt", "(garbled: "), ("imu", "invalid", "(invalid: "),
    ("dvl", "silence", "(silent)"), ("dvl", "corrupt", "(garbled: "), ("dvl", "invalid", "(invalid: "),
    ("pressure", "silence", "(silent)"), ("pressure", "corrupt", "(garbled: "), ("pressure", "invalid", "(invalid: "),
]
#: drive fault injected -> what the motor failsafe's cause must say about the drive
DRIVE_FAULTS = [("emcy", "epos2.1: EMCY 0x2310 overcurrent"), ("heartbeat_loss", "epos2.2: no heartbeat for"),
                ("silence", "epos2.3: no heartbeat for")]


@pytest.fixture(scope="module")
def sup(tmp_path_factory: pytest.TempPathFactory):
    cfg = load_config("sim-devices")
    warn = FailsafeRule("warn", 0.5)  # shown, not acted on: the robot stays as it is
    cfg = cfg.replace(access=AccessConfig(token=TOKEN),
                      console=cfg.console.replace(record_on_arm=False),
                      failsafe=cfg.failsafe.replace(imu=warn, dvl=warn, depth=warn, motor=FailsafeRule("warn", 0.0)))
    s = Supervisor(cfg, sessions_dir=tmp_path_factory.mktemp("sessions"))
    s.start()
    s.client_connected(PILOT)
    assert s.take_control(PILOT, TOKEN)
    wait_for(lambda: s.loop.time > 1.0, what="the loop running on the rig")
    yield s
    s.stop()


def cause(sup: Supervisor, name: str) -> str:
    state = next(st for st in sup.safety.states() if st.name == name)
    return state.cause if state.active else ""


@pytest.mark.parametrize("device, fault, label", SENSOR_FAULTS, ids=[f"{d}-{f}" for d, f, _ in SENSOR_FAULTS])
def test_a_sensor_fault_is_labelled_with_what_happened(sup: Supervisor, device: str, fault: str, label: str) -> None:
    sensor = SENSOR_OF[device]
    wait_for(lambda: not sup.safety.is_active(sensor), what=f"{sensor} clear before the injection")
    sup.inject_fault(PILOT, device, fault)
    try:
        found = wait_for(lambda: cause(sup, sensor), what=f"the {sensor} failsafe")
        assert label in found, found
        assert f"{sensor.upper()} without a valid reading" in found
    finally:
        sup.clear_fault(PILOT, device, fault)
    wait_for(lambda: not sup.safety.is_active(sensor), what=f"the {sensor} failsafe clearing")


@pytest.mark.parametrize("fault, label", DRIVE_FAULTS, ids=[f for f, _ in DRIVE_FAULTS])
def test_a_drive_fault_is_labelled_with_the_drive_and_what_it_reported(sup: Supervisor, fault: str, label: str) -> None:
    fin = {"epos2.1": 0, "epos2.2": 1, "epos2.3": 2}[label.split(":")[0]]
    wait_for(lambda: not sup.safety.is_active("motor"), what="no motor fault before the injection")
    sup.inject_fault(PILOT, "epos2", fault, fin=fin)
    try:
        found = wait_for(lambda: cause(sup, "motor"), what="the motor failsafe")
        assert label in found, found
    finally:
        if fault == "emcy":
            sup.reset_drive_faults(PILOT)
        else:
            sup.clear_fault(PILOT, "epos2", fault)
    wait_for(lambda: not sup.safety.is_active("motor"), what="the motor failsafe clearing")
    assert not sup.armed and LOCAL  # nothing was armed: the labels only
