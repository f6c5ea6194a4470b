"""Each sensor and drive fault, injected in the emulators of the simulated rig, reaches the
failsafes with a label that says what happened: silent, garbled, invalid, implausible (with
how many readings were dropped and why); a drive's fault names the drive and what it
reported. An implausible reading never reaches the estimator or the depth loop."""

from __future__ import annotations

import math
import re

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.supervisor import Supervisor
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.failsafe_config import FailsafeRule
from ucat_console.config import load_config
from ucat_console.robot.rotations import euler_from_quaternion
from ucat_console.robot.units import GRAVITY
from ucat_console.telemetry import channels as ch

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
#: (device, the implausible values its emulator sends, the failsafes they start, the reason
#: their labels give)
IMPLAUSIBLE = [
    ("pressure", {"current_ma": 20.4}, ("depth",), "loop current 20.400 mA above 20 mA (depth 104.7 m)"),
    ("pressure", {"current_ma": 4.0}, ("depth",), "loop current 4.000 mA at or below 4 mA"),
    ("pressure", {"jump_m": 5.0}, ("depth",), "depth jumped +5.0"),
    ("imu", {"accel_g": (0.0, 0.0, 1e6)}, ("imu",), "acceleration 1e+06 g along z"),
    ("imu", {"gyro": (0.0, 0.0, 1000.0)}, ("imu",), "angular rate 1000 rad/s (57296 deg/s) about z"),
    ("imu", {"quaternion": (0.0, 0.0, 0.0, 0.0)}, ("imu",), "orientation quaternion of norm 0, not 1"),
    ("dvl", {"velocity": (5.0, 0.0, 0.0)}, ("dvl",), "velocity 5.00 m/s, beyond the DVL's 2 m/s"),
    # 0.8 m/s down, within the DVL's range, while the depth stays: the two disagree
    ("dvl", {"velocity": (0.0, 0.0, 0.8)}, ("dvl", "depth"), "depth rate and the DVL's vertical velocity"),
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
    s = Console(cfg, tmp_path_factory.mktemp("sessions"), clock=None).sup
    s.start()
    s.client_connected(PILOT)
    assert s.take_control(PILOT, TOKEN)
    s.set_setpoints(PILOT, depth=cfg.devices.start.depth)  # the depth loop holds where the robot is
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


class Taken:
    """What the loop publishes of the readings, the body state and the depth loop's command,
    from now until :meth:`stop`."""

    def __init__(self, sup: Supervisor) -> None:
        self.items: list = []
        self.stop = sup.stream.subscribe(lambda c, m: self.items.append((c, m)), [
            ch.DEPTH, ch.IMU, ch.DVL, ch.BODY_STATE, ch.BODY_ALLOCATION])

    def heave(self) -> list[float]:
        """The heave force the depth loop asked (N), each time."""
        return [abs(m.heave) for c, m in list(self.items) if c == ch.BODY_ALLOCATION]


@pytest.mark.parametrize("device, values, sensors, reason", IMPLAUSIBLE, ids=[
    "pressure-20.4mA", "pressure-4mA", "pressure-depth-jump", "imu-1e6g", "imu-1000rad_s", "imu-zero-quaternion",
    "dvl-5m_s", "dvl-apart-from-depth"])
def test_an_implausible_reading_is_dropped_counted_and_labelled_and_a_lasting_one_starts_the_failsafe(
        sup: Supervisor, device: str, values: dict, sensors: tuple[str, ...], reason: str) -> None:
    for sensor in ("imu", "dvl", "depth"):
        wait_for(lambda: not sup.safety.is_active(sensor), what=f"{sensor} clear before the injection")
    settled = Taken(sup)
    wait_for(lambda: len(settled.heave()) > 5 and max(settled.heave()[-5:]) < 0.1,
             what="the depth loop asking next to nothing")
    settled.stop()
    truth = sup.loop.truth()
    taken = Taken(sup)
    sup.inject_fault(PILOT, device, "implausible", **values)
    try:
        for sensor in sensors:  # a lasting fault: no valid reading, so the failsafe
            found = wait_for(lambda: cause(sup, sensor), what=f"the {sensor} failsafe")
            assert re.search(r"\(implausible: \d+ readings dropped, " + re.escape(reason), found), found
    finally:
        sup.clear_fault(PILOT, device, "implausible")
        taken.stop()
    # what the loop took: no reading the emulator made implausible (the DVL's disagreement
    # is judged over a window, so its first reports pass), and the estimate kept its course
    for c, m in taken.items:
        if c == ch.DEPTH:
            assert abs(m.depth_m - truth.depth) < 0.2, m
        elif c == ch.IMU:
            assert max(map(abs, m.accel)) < 8.0 * GRAVITY and max(map(abs, m.gyro)) < math.radians(300.0), m
            assert m.quaternion is None or abs(math.hypot(*m.quaternion) - 1.0) < 0.01, m
        elif c == ch.DVL and m.valid and sensors == ("dvl",):
            assert math.hypot(m.vx, m.vy, m.vz) < 2.0, m
        elif c == ch.BODY_STATE:
            assert abs(m.depth - truth.depth) < 0.2, m
            assert abs(euler_from_quaternion(m.orientation)[2] - truth.euler[2]) < math.radians(2.0), m
    assert max(taken.heave()) < 0.5  # the depth loop's command as it was (about 0.01 N)
    for sensor in sensors:
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
