"""The rosbag2 export: a simulated session written as a ROS 2 bag and read back with rosbags'
own reader (types, counts, values in ROS axes, frames, the URDF, latching), a crafted one
for the cases a short simulation does not make, the errors, and the command line."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from scipy.spatial.transform import Rotation
from session_helpers import record

from ucat_console.backend.loop.clock import SimulatedClock
from ucat_console.backend.access import LOCAL, AccessConfig
from ucat_console.backend.sessions import ros_messages as rm
from ucat_console.backend.sessions import rosbag2_export as rb
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.backend.supervisor import Supervisor
from ucat_console.cli import main
from ucat_console.config import AppConfig, ConsoleConfig
from ucat_console.robot import urdf
from ucat_console.robot.readings import DepthReading, ImuReading
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinState, FinStrouhal, Power

#: NED axes in ENU, FRD axes in FLU (by hand: REP 103)
ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A two-second armed run of the simulated U-CAT, recorded, and its bag."""
    d = tmp_path_factory.mktemp("sessions")
    cfg = AppConfig(console=ConsoleConfig(supervise_period=0.05), access=AccessConfig(token="t" * 12))
    sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=d)
    try:
        sup.start_recording(LOCAL)
        sup.arm(LOCAL)
        sup.step(2.0)
        [path] = sup.stop_recording(LOCAL)
    finally:
        sup.stop()
    bag = d.parent / "bag"
    assert main(["sessions", "export", str(path), "--rosbag2", str(bag)]) == 0
    return path, bag


def _store_from_bag(reader: Reader) -> Any:
    """A Jazzy type store with every type the bag defines (from its own definitions, as a ROS
    user without ucat_msgs would read it)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for conn in reader.connections:
        if conn.msgtype.startswith("ucat_msgs/"):
            text = conn.msgdef.data.split("=" * 80)[0]
            store.register(get_types_from_msg(text, conn.msgtype))
    return store


def read_bag(bag: Path) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, Any]]:
    """topic -> [(bag time, message)], and topic -> connection."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with Reader(bag) as reader:
        store = _store_from_bag(reader)
        conns = {c.topic: c for c in reader.connections}
        for conn, ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((ns, store.deserialize_cdr(raw, conn.msgtype)))
    return out, conns


def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _matrix(q_wxyz: tuple[float, ...]) -> np.ndarray:
    w, x, y, z = q_wxyz
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def test_every_topic_has_its_standard_or_own_type_and_a_message_per_recorded_one(simulated):
    path, bag = simulated
    msgs, conns = read_bag(bag)
    with SessionParts(path, confined=False) as s:
        counts = s.message_counts()
    want = {
        "/tf_static": "tf2_msgs/msg/TFMessage", "/robot_description": "std_msgs/msg/String",
        "/tf": "tf2_msgs/msg/TFMessage", "/odom": "nav_msgs/msg/Odometry", "/imu": "sensor_msgs/msg/Imu",
        "/pressure": "sensor_msgs/msg/FluidPressure", "/joint_states": "sensor_msgs/msg/JointState",
        "/power": "ucat_msgs/msg/Power", "/power/electrical": "ucat_msgs/msg/ElectricalPower",
        "/rosout": "rcl_interfaces/msg/Log",
        **{f"/fin{i}/state": "ucat_msgs/msg/FinState" for i in range(4)},
        **{f"/fin{i}/strouhal": "ucat_msgs/msg/FinStrouhal" for i in range(4)},
    }
    assert {t: c.msgtype for t, c in conns.items()} == want
    assert all(c.msgdef.format.name == "MSG" for c in conns.values())  # ros2msg schemas
    fins = sum(counts[C.fin_state(i)] for i in range(4))
    assert counts[C.BODY_STATE] > 50 and counts[C.IMU] > 50 and counts[C.DEPTH] > 10 and counts[C.POWER] > 5
    n = {t: len(msgs.get(t, [])) for t in want}
    assert n["/tf_static"] == 1 and n["/robot_description"] == 1
    assert n["/odom"] == counts[C.BODY_STATE]
    assert n["/tf"] == counts[C.BODY_STATE] + fins  # every state finite: every transform
    assert n["/imu"] == counts[C.IMU] and n["/pressure"] == counts[C.DEPTH]
    assert n["/joint_states"] == fins
    assert n["/power"] == counts[C.POWER] and n["/power/electrical"] == counts[C.POWER_ELECTRICAL]
    assert n["/rosout"] == counts[C.EVENTS]
    for i in range(4):
        assert n[f"/fin{i}/state"] == counts[C.fin_state(i)]
        assert n[f"/fin{i}/strouhal"] == counts[C.fin_strouhal(i)]
    # metadata.yaml says the same
    with Reader(bag) as reader:
        assert reader.message_count == sum(n.values())
        assert reader.topics["/odom"].msgcount == counts[C.BODY_STATE]


def test_the_pose_and_velocities_are_the_body_states_in_enu_and_flu(simulated):
    path, bag = simulated
    msgs, _ = read_bag(bag)
    with SessionParts(path, confined=False) as s:
        states = [(r.log_time_ns, r.message) for r in s.records([C.BODY_STATE])]
        to_ns = s.to_ns
    odom = msgs["/odom"]
    assert len(odom) == len(states)
    moved = False
    for (ns, m), (log_ns, state) in zip(odom, states):
        assert ns == log_ns and _ns(m.header.stamp) == to_ns(state.t)
        assert m.header.frame_id == "odom" and m.child_frame_id == "base_link"
        p = m.pose.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], ENU_FROM_NED @ np.array(state.position), atol=1e-12)
        o = m.pose.pose.orientation
        np.testing.assert_allclose(_matrix((o.w, o.x, o.y, o.z)),
                                   ENU_FROM_NED @ _matrix(state.orientation) @ FLU_FROM_FRD.T, atol=1e-9)
        v, w = m.twist.twist.linear, m.twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z], FLU_FROM_FRD @ np.array(state.velocity), atol=1e-12)
        np.testing.assert_allclose([w.x, w.y, w.z], FLU_FROM_FRD @ np.array(state.rates), atol=1e-12)
        moved = moved or abs(state.position[2] - states[0][1].position[2]) > 1e-4
    assert moved  # the values compared change over the run
    # /tf's odom -> base_link is the same pose
    body_tfs = [m.transforms[0] for _, m in msgs["/tf"] if m.transforms[0].child_frame_id == "base_link"]
    assert len(body_tfs) == len(states)
    tf, (_, state) = body_tfs[-1], states[-1]
    assert tf.header.frame_id == "odom"
    t = tf.transform.translation
    np.testing.assert_allclose([t.x, t.y, t.z], ENU_FROM_NED @ np.array(state.position), atol=1e-12)


def test_imu_pressure_and_fins_are_the_recorded_readings(simulated):
    path, bag = simulated
    msgs, _ = read_bag(bag)
    with SessionParts(path, confined=False) as s:
        imu = [r.message for r in s.records([C.IMU])]
        depth = [r.message for r in s.records([C.DEPTH])]
        fin1 = [r.message for r in s.records([C.fin_state(1)])]
        power = [r.message for r in s.records([C.POWER])]
        to_ns = s.to_ns
    for (_, m), r in zip(msgs["/imu"], imu):
        assert m.header.frame_id == "base_link" and _ns(m.header.stamp) == to_ns(r.t)
        g, a = m.angular_velocity, m.linear_acceleration
        np.testing.assert_allclose([g.x, g.y, g.z], [r.gyro[0], -r.gyro[1], -r.gyro[2]], atol=1e-15)
        np.testing.assert_allclose([a.x, a.y, a.z], [r.accel[0], -r.accel[1], -r.accel[2]], atol=1e-15)
    # at rest, level: the specific force points up in FLU (+g)
    assert msgs["/imu"][0][1].linear_acceleration.z == pytest.approx(9.8, abs=0.3)
    assert [m.fluid_pressure for _, m in msgs["/pressure"]] == [r.pressure_pa + 101_325.0 for r in depth]  # absolute
    assert all(m.header.frame_id == "base_link" for _, m in msgs["/pressure"])
    states = [m for _, m in msgs["/fin1/state"]]
    assert [(m.fin, m.angle, m.rate, m.angle_cmd, m.rate_cmd) for m in states] == \
        [(1, r.angle, r.rate, r.angle_cmd, r.rate_cmd) for r in fin1]
    assert any(r.angle != 0.0 for r in fin1) and states[0].header.frame_id == "fin1"
    joints = [m for _, m in msgs["/joint_states"] if list(m.name) == ["fin1_joint"]]
    assert [float(m.position[0]) for m in joints] == [r.angle for r in fin1]
    assert [float(m.velocity[0]) for m in joints] == [r.rate for r in fin1]
    got = [m for _, m in msgs["/power"]]
    assert [list(m.per_fin) for m in got] == [list(r.per_fin) for r in power]
    assert [m.energy for m in got] == [r.energy for r in power] and power[-1].energy > 0.0


def test_static_frames_the_urdf_and_fin_transforms_follow_the_urdf(simulated):
    _, bag = simulated
    msgs, conns = read_bag(bag)
    for topic in ("/tf_static", "/robot_description"):
        [qos] = conns[topic].ext.offered_qos_profiles
        assert qos.durability == QosDurability.TRANSIENT_LOCAL and qos.depth == 1
    assert conns["/tf"].ext.offered_qos_profiles == []
    [(_, static)] = msgs["/tf_static"]
    pairs = {(t.header.frame_id, t.child_frame_id) for t in static.transforms}
    assert pairs == {("map", "odom"), ("odom", "odom_ned"), ("base_link", "base_link_frd")}
    frd = next(t for t in static.transforms if t.child_frame_id == "base_link_frd").transform.rotation
    # half a turn about x, as the URDF's fixed joint (rpy pi 0 0)
    np.testing.assert_allclose(_matrix((frd.w, frd.x, frd.y, frd.z)), FLU_FROM_FRD, atol=1e-12)
    [(_, description)] = msgs["/robot_description"]
    assert description.data == urdf.URDF_PATH.read_text()  # the default robot's, as shipped
    links = set(re.findall(r'<link name="([^"]+)"', description.data))
    frames = {t.child_frame_id for _, m in msgs["/tf"] for t in m.transforms}
    parents = {t.header.frame_id for _, m in msgs["/tf"] for t in m.transforms}
    assert frames == {"base_link", "fin0", "fin1", "fin2", "fin3"} and frames <= links
    assert parents == {"odom", "base_link_frd"}
    names = {n for _, m in msgs["/joint_states"] for n in m.name}
    assert names == set(re.findall(r'<joint name="(fin\d_joint)"', description.data))


def test_our_messages_carry_every_field_of_their_channels():
    for topic in (*rm.FIN_STATES, *rm.FIN_STROUHALS, rm.POWER, rm.ELECTRICAL):
        cls = C.message_type(topic.source)
        assert rm.own_fields(topic.msgtype) == [f.name for f in dataclasses.fields(cls) if f.name != "t"]
    assert {p.stem for p in rm.msg_files()} == {"FinState", "FinStrouhal", "Power", "ElectricalPower"}
    cmake = (rm.MSG_PACKAGE_DIR / "CMakeLists.txt").read_text()
    assert all(f'"msg/{p.name}"' in cmake for p in rm.msg_files())


def _crafted(sessions: Path) -> Path:
    items: list[tuple[str, Any]] = []
    for k in range(10):
        t = 0.1 * k
        items.append((C.BODY_STATE, BodyState(t, (1.0 + k, 2.0, 0.5), (1.0, 0.0, 0.0, 0.0),
                                              (0.3, 0.0, 0.0), (0.0, 0.0, 0.1), 0.5)))
        items.append((C.DEPTH, DepthReading(t, 0.5, 106_325.0 + k)))
        items.append((C.IMU, ImuReading(t, (0.0, 0.0, -9.8), (0.0, 0.0, 0.1))))  # no orientation
        items.append((C.fin_state(0), FinState(t, 0, math.nan if k == 3 else 0.1 * k, 1.0, 0.2, 2.0)))
    items.append((C.fin_strouhal(2), FinStrouhal(0.55, 2, 0.3, 0.25, 0.35, 0.3, 0.3, 0.5, 3.0)))
    items.append((C.POWER, Power(0.6, (1.0, math.nan, 2.0, 3.0), 6.0, 5.0, 1.0, 0.2, math.nan)))
    items.append((C.EVENTS, Event(0.7, "operator", "marker", "here", "warning")))
    [path] = record(sessions, items, label="ros", wall_time=1_700_000_000.0)
    return path


def test_a_crafted_session_and_a_time_range(sessions, tmp_path):
    path = _crafted(sessions)
    bag = tmp_path / "bag"
    with SessionParts(path, sessions) as s:
        counts = rb.export_rosbag2(s, bag, start=0.25, end=0.75)
        to_ns = s.to_ns
    msgs, _ = read_bag(bag)
    assert counts["/odom"] == len(msgs["/odom"]) == 5  # t 0.3 .. 0.7
    assert [_ns(m.header.stamp) for _, m in msgs["/odom"]] == [to_ns(0.1 * k) for k in range(3, 8)]
    assert [(m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z)
            for _, m in msgs["/odom"]] == [(2.0, 1.0 + k, -0.5) for k in range(3, 8)]  # east, north, up
    # the latched messages carry the range's first time
    assert msgs["/tf_static"][0][0] == to_ns(0.25) == _ns(msgs["/tf_static"][0][1].transforms[0].header.stamp)
    assert [m.fluid_pressure for _, m in msgs["/pressure"]] == [106_325.0 + k + 101_325.0 for k in range(3, 8)]
    imu = msgs["/imu"][0][1]
    assert imu.orientation_covariance[0] == -1.0 and math.isnan(imu.orientation.w)
    # fin 0's angle is NaN at t 0.3: on /fin0/state and /joint_states as recorded, not on /tf
    assert math.isnan(msgs["/fin0/state"][0][1].angle) and math.isnan(msgs["/joint_states"][0][1].position[0])
    assert counts["/tf"] == 5 + 4
    [(_, st)] = msgs["/fin2/strouhal"]
    assert (st.fin, st.st, st.header.frame_id) == (2, 0.3, "fin2")
    [(_, power)] = msgs["/power"]
    assert power.per_fin[0] == 1.0 and math.isnan(power.per_fin[1]) and math.isnan(power.energy_per_metre)
    [(_, log)] = msgs["/rosout"]
    assert (log.level, log.name, log.msg) == (30, "operator", "marker: here")
    assert counts["/power/electrical"] == 0 and "/power/electrical" not in msgs


def test_a_used_destination_or_a_bad_session_is_refused_and_nothing_is_left(sessions, tmp_path):
    path = _crafted(sessions)
    used = tmp_path / "used"
    used.mkdir()
    (used / "keep.txt").write_text("mine")
    with SessionParts(path, sessions) as s:
        with pytest.raises(ValueError, match="used.*not empty"):
            rb.export_rosbag2(s, used)
        empty = tmp_path / "empty"
        empty.mkdir()
        rb.export_rosbag2(s, empty)  # an empty directory is taken
        assert (empty / "metadata.yaml").is_file()
        a_file = tmp_path / "file"
        a_file.write_text("x")
        with pytest.raises(ValueError, match="not a directory"):
            rb.export_rosbag2(s, a_file)
    assert sorted(p.name for p in used.iterdir()) == ["keep.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "file", "sessions", "used"]


def test_a_failure_while_writing_leaves_nothing(sessions, tmp_path, monkeypatch):
    path = _crafted(sessions)

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise OSError("disk full")

    monkeypatch.setattr(rm.MessageBuilder, "pressure", broken)
    with SessionParts(path, sessions) as s, pytest.raises(OSError, match="disk full"):
        rb.export_rosbag2(s, tmp_path / "bag")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sessions"]


def test_the_command_line(sessions, tmp_path, capsys):
    path = _crafted(sessions)
    bag = tmp_path / "out" / "bag"
    assert main(["sessions", "export", path.name, "--dir", str(sessions), "--rosbag2", str(bag),
                 "--start", "0.0", "--end", "0.45"]) == 0
    out = capsys.readouterr().out
    assert "/odom" in out and str(bag) in out
    msgs, _ = read_bag(bag)
    assert len(msgs["/odom"]) == 5
    # again into the same directory: refused, named, the bag kept
    assert main(["sessions", "export", path.name, "--dir", str(sessions), "--rosbag2", str(bag)]) == 2
    assert str(bag) in capsys.readouterr().err
    assert len(read_bag(bag)[0]["/odom"]) == 5
    # a session that is not there; --rosbag2 with the CSV options
    assert main(["sessions", "export", "no-such-session", "--dir", str(sessions),
                 "--rosbag2", str(tmp_path / "b2")]) == 2
    assert "no-such-session" in capsys.readouterr().err and not (tmp_path / "b2").exists()
    assert main(["sessions", "export", path.name, "--dir", str(sessions), "--rosbag2", str(tmp_path / "b3"),
                 "--topics", "power"]) == 2
    assert "--rosbag2" in capsys.readouterr().err
    assert main(["sessions", "export", path.name, "--dir", str(sessions)]) == 2
    assert "--rosbag2" in capsys.readouterr().err
    not_mcap = sessions / "20231114-221320-junk_001.mcap"
    not_mcap.write_bytes(b"not an mcap file")
    assert main(["sessions", "export", str(not_mcap), "--rosbag2", str(tmp_path / "b4")]) == 2
    assert not_mcap.name in capsys.readouterr().err and not (tmp_path / "b4").exists()


def test_the_urdf_is_the_recorded_robots(sessions, tmp_path):
    """A session recorded with another hull: the bag's URDF is that robot's, not the shipped one."""
    cfg = AppConfig.from_dict({"plant": {"vehicle": {"hull_size": [0.7, 0.3, 0.25]}}})
    items = [(C.BODY_STATE, BodyState(0.1 * k, (0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                      (0.0, 0.0, 0.0), 0.5)) for k in range(3)]
    [path] = record(sessions, items, label="hull", wall_time=1_700_000_000.0, config_toml=cfg.to_toml(redact=True))
    bag = tmp_path / "bag"
    assert main(["sessions", "export", str(path), "--rosbag2", str(bag)]) == 0
    [(_, description)] = read_bag(bag)[0]["/robot_description"]
    assert '<box size="0.7 0.3 0.25"/>' in description.data
    assert description.data != urdf.URDF_PATH.read_text()


def test_the_bag_file_is_ros2_mcap(simulated):
    """The storage file as the MCAP library reads it: the ros2 profile, ros2msg schemas, CDR."""
    from mcap.reader import make_reader

    _, bag = simulated
    [file] = list(bag.glob("*.mcap"))
    assert file.name == f"{bag.name}.mcap"
    with open(file, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
