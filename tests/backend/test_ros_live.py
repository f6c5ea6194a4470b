"""The live ROS 2 topics through zenoh: the simulated console's publisher read by a zenoh
session of the test's own (what a node on rmw_zenoh would see: key expressions, CDR payloads,
attachments, liveliness tokens, the latched topics for a late subscriber), the mapping against
rmw_zenoh's documented examples, the queue that never blocks the stream, the configuration and
the command line. No ROS install: the format is checked against rmw_zenoh's documentation and
sources (docs/design.md and attachment_helpers.cpp of its Jazzy release), not a running ROS."""

from __future__ import annotations

import json
import logging
import socket
import struct
import threading
from typing import Any

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh", reason="the 'ros' extra")
xxhash = pytest.importorskip("xxhash", reason="the 'ros' extra")
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from support import wait_for  # noqa: E402
from zenoh import ext  # noqa: E402

from ucat_console.backend import ros_live  # noqa: E402
from ucat_console.backend.access import LOCAL, AccessConfig  # noqa: E402
from ucat_console.backend.loop.clock import SimulatedClock  # noqa: E402
from ucat_console.backend.rmw_zenoh import Node, Qos, attachment, dds_type_name, gid, topic_key  # noqa: E402
from ucat_console.backend.ros_config import Ros2Config  # noqa: E402
from ucat_console.backend.ros_live import Ros2Publisher  # noqa: E402
from ucat_console.backend.sessions import codec  # noqa: E402
from ucat_console.backend.sessions.ros_messages import TOPICS, typestore  # noqa: E402
from ucat_console.backend.supervisor import Supervisor  # noqa: E402
from ucat_console.cli import main  # noqa: E402
from ucat_console.config import AppConfig, ConsoleConfig  # noqa: E402
from ucat_console.robot import urdf  # noqa: E402
from ucat_console.telemetry import channels as C  # noqa: E402
from ucat_console.telemetry.messages import BodyState  # noqa: E402
from ucat_console.telemetry.stream import TelemetryStream  # noqa: E402

#: from rmw_zenoh's docs/design.md (Jazzy release 0.2.x): a talker's publisher token, the key
#: expressions of /chatter and of /robot1/chatter
TALKER_TOKEN = ("@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::"
                "String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,")
LISTENER_NODE = "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
CHATTER_KEY = "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ROBOT1_KEY = "0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
#: GIDs of key expressions by rmw_zenoh's own hash (its simplified_xxhash3.cpp, 0.2.10, compiled
#: and run on these strings): the low 64 bits then the high 64, little endian
RMW_GIDS = {
    "@ros2_lv/0/4310eb178ca355065642d389738309dd/0/3/MP/%/%/ucat_console/%odom/nav_msgs::msg::dds_::Odometry_/"
    "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0/::,10:,:,:,,":
        "ed7cb4201ebc8a137f8f06fbe02c397a",
    "abc": "50392f89945faf7885613a73b65ab006",
    "x" * 300: "5435c87d60b4d1a57abcd72aea375212",
}
#: rmw_zenoh's attachment as its subscriptions read it (zenoh-cpp's Deserializer: int64, int64,
#: std::array<uint8_t, 16> as a sequence: its length, then the bytes)
ATTACHMENT = struct.Struct("<qqB16s")
VOLATILE_QOS = "::,10:,:,:,,"
LATCHED_QOS = ":1:,1:,:,:,,"  # transient local (1), keep last 1


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ros_config(port: int, **kw: Any) -> Ros2Config:
    """The publisher listening on ``port`` of this machine, connecting nowhere."""
    return Ros2Config(enabled=True, connect=(), listen=(f"tcp/127.0.0.1:{port}",), **kw)


def reader(port: int) -> Any:
    """The test's own zenoh session, connected to the publisher's (no scouting)."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("peer"))
    c.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    c.insert_json5("listen/endpoints", "[]")
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(c)


def tokens(session: Any) -> list[str]:
    return [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/**", timeout=5.0) if r.ok is not None]


def jazzy() -> Any:
    return get_typestore(Stores.ROS2_JAZZY)


# ---------------------------------------------------------------------- the mapping
def test_the_mapping_gives_rmw_zenohs_documented_names_gids_and_attachment():
    store = typestore()
    string = dds_type_name("std_msgs/msg/String")
    h = store.hash_rihs01("std_msgs/msg/String")
    talker = Node(0, "8b20917502ee955ac4476e0266340d5c", 0, "/", "talker")
    assert talker.publisher_token(10, "/chatter", string, h, Qos(depth=7)) == TALKER_TOKEN
    assert Node(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener").token() == LISTENER_NODE
    assert topic_key(0, "/chatter", string, h) == CHATTER_KEY
    assert topic_key(0, ros_live.qualified("/chatter", "/robot1"), string, h) == ROBOT1_KEY
    assert ros_live.qualified("/tf", "/robot1") == "/tf"
    assert Qos(depth=42).token() == "::,:,:,:,,"  # rmw_zenoh's defaults are left empty
    for text, expected in RMW_GIDS.items():
        assert gid(text).hex() == expected
    g = bytes(range(16))
    assert ATTACHMENT.unpack(attachment(7, -3, g)) == (7, -3, 16, g)
    with pytest.raises(ValueError, match="16 bytes"):
        attachment(1, 1, b"short")
    with pytest.raises(ValueError, match="not a ROS 2 message type"):
        dds_type_name("Odometry")


# ---------------------------------------------------------------------- the simulated console
@pytest.fixture
def console(tmp_path: Any) -> Any:
    """A supervisor on the simulated robot and a simulated clock, stepped by the test."""
    cfg = AppConfig(console=ConsoleConfig(supervise_period=0.05, record_on_arm=False, write_reports=False),
                    access=AccessConfig(token="t" * 12))
    sup = Supervisor(cfg, clock=SimulatedClock(), sessions_dir=tmp_path)
    yield sup
    sup.stop()


def _expected_key(topic: Any) -> str:
    """A topic's key expression written out by hand from rmw_zenoh's format, with rosbags'
    RIHS01 hash (of ROS 2 Jazzy's definitions; ours registered into the console's store)."""
    pkg, _, name = topic.msgtype.split("/")
    store = typestore() if pkg == "ucat_msgs" else jazzy()
    return f"0/{topic.name[1:]}/{pkg}::msg::dds_::{name}_/{store.hash_rihs01(topic.msgtype)}"


def test_the_simulated_console_is_published_as_rmw_zenoh_publishes(console, tmp_path):
    sup = console
    port = free_port()
    states: list[BodyState] = []
    sup.stream.subscribe(lambda c, m: states.append(m), [C.BODY_STATE])
    pub = Ros2Publisher(sup.stream, ros_config(port), epoch_offset=sup.wall0)
    session = reader(port)
    try:
        got: list[tuple[str, bytes, bytes]] = []
        lock = threading.Lock()

        def on_sample(s: Any) -> None:
            with lock:
                got.append((str(s.key_expr), s.payload.to_bytes(), s.attachment.to_bytes()))

        session.declare_subscriber("0/**", on_sample)
        # the graph: the node and one publisher per topic, with type, hash and QoS
        zid = pub.node.zid
        wait_for(lambda: len(tokens(session)) == len(TOPICS) + 1, timeout=60, what="the liveliness tokens")
        lv = tokens(session)
        assert f"@ros2_lv/0/{zid}/0/0/NN/%/%/ucat_console" in lv
        by_topic = {}
        for t in lv:
            parts = t.split("/")
            if parts[5] == "MP":
                assert parts[:5] == ["@ros2_lv", "0", zid, "0", parts[4]] and parts[6:9] == ["%", "%", "ucat_console"]
                by_topic[parts[9].replace("%", "/")] = parts
        assert set(by_topic) == {tp.name for tp in TOPICS}
        for tp in TOPICS:
            parts = by_topic[tp.name]
            assert "/".join(["0", tp.name[1:], parts[10], parts[11]]) == _expected_key(tp)
            assert parts[12] == (LATCHED_QOS if tp.latched else VOLATILE_QOS)
        assert len({p[4] for p in by_topic.values()}) == len(TOPICS)  # one entity id each

        # the latched topics, put before this session subscribed: a late transient-local subscriber
        late: list[bytes] = []
        ext.declare_advanced_subscriber(session, "0/tf_static/**", lambda s: late.append(s.payload.to_bytes()),
                                        history=ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                                        subscriber_detection=True)
        ext.declare_advanced_subscriber(session, "0/robot_description/**", lambda s: late.append(s.payload.to_bytes()),
                                        history=ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                                        subscriber_detection=True)
        wait_for(lambda: len(late) >= 2, timeout=60, what="/tf_static and /robot_description from the cache")
        store = typestore()
        decoded = []
        for raw in late:
            try:
                decoded.append(store.deserialize_cdr(raw, "tf2_msgs/msg/TFMessage"))
            except Exception:
                decoded.append(store.deserialize_cdr(raw, "std_msgs/msg/String"))
        static = next(m for m in decoded if hasattr(m, "transforms"))
        assert {t.child_frame_id for t in static.transforms} == {"odom", "odom_ned", "base_link_frd"}
        assert next(m for m in decoded if hasattr(m, "data")).data == urdf.URDF_PATH.read_text()

        # the running console's topics
        sup.arm(LOCAL)
        wanted = {"/odom", "/tf", "/imu", "/joint_states", "/fin0/state", "/fin3/state", "/fin0/strouhal",
                  "/power", "/pressure", "/rosout"}

        topic_of = {_expected_key(tp): tp.name for tp in TOPICS}

        def arrived() -> bool:
            sup.step(0.2)
            with lock:
                seen = {topic_of.get(key) for key, _, _ in got}
            return wanted <= seen

        wait_for(arrived, timeout=120, what=f"messages on {sorted(wanted)}")
        sup.disarm(LOCAL)
        wait_for(lambda: not pub._queue, timeout=60, what="the publisher's queue to empty")
    finally:
        pub.close()
    with lock:
        samples = list(got)
    assert pub.dropped == 0 and pub.errors == 0 and pub.sent >= len(samples)
    keys = {tp.name: _expected_key(tp) for tp in TOPICS}
    msgtype = {_expected_key(tp): tp.msgtype for tp in TOPICS}
    assert {k for k, _, _ in samples} <= set(keys.values())
    # every payload is its type's CDR; every attachment rmw_zenoh's, numbered from 1 by its publisher
    sequences: dict[str, list[int]] = {}
    gids: dict[str, bytes] = {}
    store = typestore()
    odoms = []
    for key, payload, att in samples:
        msg = store.deserialize_cdr(payload, msgtype[key])
        assert msg.__msgtype__ == msgtype[key]
        seq, ts, n, g = ATTACHMENT.unpack(att)
        assert n == 16 and ts > 0
        sequences.setdefault(key, []).append(seq)
        assert gids.setdefault(key, g) == g
        if msgtype[key] == "nav_msgs/msg/Odometry":
            odoms.append(msg)
    for key, seqs in sequences.items():
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), key  # one by one, none lost
    for name, parts in by_topic.items():
        if keys[name] in gids:
            assert gids[keys[name]] == xxhash.xxh3_128_intdigest("/".join(parts).encode()).to_bytes(16, "little")
    # /odom: the stream's body states, NED -> ENU by hand, stamped with their own times
    by_ns = {codec.to_ns(s.t, sup.wall0): s for s in states}
    assert len(odoms) >= 2
    for m in odoms:
        s = by_ns[m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec]
        n, e, d = s.position
        p = m.pose.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], [e, n, -d], rtol=0, atol=1e-12)
        assert (m.header.frame_id, m.child_frame_id) == ("odom", "base_link")
    # closed: the node and its publishers have left the graph
    wait_for(lambda: not tokens(session), timeout=60, what="the tokens to go")
    session.close()


# ---------------------------------------------------------------------- never in the way
def test_a_publisher_that_falls_behind_drops_the_oldest_and_never_blocks_the_stream(monkeypatch, caplog):
    stream = TelemetryStream()
    release = threading.Event()
    entered = threading.Event()
    real_put = Ros2Publisher._put

    def slow_put(self: Any, topic: Any, msg: Any) -> None:
        if topic.name == "/odom":
            entered.set()
            release.wait()
        real_put(self, topic, msg)

    monkeypatch.setattr(Ros2Publisher, "_put", slow_put)
    pub = Ros2Publisher(stream, ros_config(free_port(), queue_size=100))
    try:
        state = BodyState(1.0, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.0, 0.0), 3.0)
        stream.publish(C.BODY_STATE, state)
        wait_for(entered.is_set, timeout=60, what="the publisher's thread to take the first message")
        for _ in range(500):  # returns at once: the publisher's thread is stuck
            stream.publish(C.BODY_STATE, state)
        assert pub.dropped == 400
    finally:
        release.set()
        pub.close()
    assert any("400 telemetry messages dropped" in r.getMessage() for r in caplog.records)


def test_an_error_is_logged_once_per_topic_and_never_raised_into_the_stream(monkeypatch, caplog):
    stream = TelemetryStream()

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("no odometry")

    monkeypatch.setattr(ros_live.MessageBuilder, "odometry", broken)
    with caplog.at_level(logging.ERROR, logger="ucat_console.backend.ros_live"), \
            Ros2Publisher(stream, ros_config(free_port())) as pub:
        for k in range(3):
            stream.publish(C.BODY_STATE, BodyState(1.0 + k, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0),
                                                   (0.1, 0.0, 0.0), (0.0, 0.0, 0.0), 3.0))
        wait_for(lambda: pub.errors == 3, timeout=60, what="three errors counted")
    logged = [r for r in caplog.records if r.name == "ucat_console.backend.ros_live" and r.levelno == logging.ERROR]
    assert len(logged) == 1 and C.BODY_STATE in logged[0].getMessage()


# ---------------------------------------------------------------------- configuration, command line
@pytest.mark.parametrize("table, key", [
    ({"domain_id": 233}, "ros2.domain_id"),
    ({"domain_id": -1}, "ros2.domain_id"),
    ({"node_name": "9lives"}, "ros2.node_name"),
    ({"node_name": "my-node"}, "ros2.node_name"),
    ({"namespace": "/ucat/"}, "ros2.namespace"),
    ({"namespace": "a//b"}, "ros2.namespace"),
    ({"connect": ["localhost:7447"]}, "ros2.connect"),
    ({"mode": "router"}, "ros2.mode"),
    ({"mode": "client", "connect": []}, "ros2.connect"),
])
def test_a_bad_ros2_table_is_refused_naming_its_key(table, key):
    with pytest.raises(ValueError, match=f"^{key.replace('.', '[.]')}: "):
        AppConfig.from_dict({"ros2": table})


def test_a_namespace_is_made_fully_qualified():
    assert AppConfig.from_dict({"ros2": {"namespace": "ucat"}}).ros2.full_namespace == "/ucat"
    assert AppConfig().ros2.full_namespace == "/"


def test_the_humble_mapping_has_no_type_hashes():
    stream = TelemetryStream()
    with Ros2Publisher(stream, ros_config(free_port(), distro="humble", domain_id=7, namespace="/ucat")) as pub:
        assert pub.node_name == "/ucat/ucat_console"
        assert pub.topics["/ucat/odom"] == "7/ucat/odom/nav_msgs::msg::dds_::Odometry_/TypeHashNotSupported"
        assert pub.topics["/tf"].startswith("7/tf/")


def test_run_names_the_extra_when_zenoh_is_missing(monkeypatch, capsys):
    def missing() -> Any:
        raise ImportError(ros_live.MISSING)

    monkeypatch.setattr(ros_live, "import_zenoh", missing)
    assert main(["run", "--headless", "--ros2", "--duration", "1"]) == 2
    assert "pip install 'ucat-console[ros]'" in capsys.readouterr().err
