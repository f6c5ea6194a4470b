"""The live robot as ROS 2 topics, without a ROS install: :class:`Ros2Publisher` subscribes
to a telemetry stream (the supervisor's) and publishes the topics of a rosbag2 export, the
same types and the same messages (one builder: ``sessions/ros_messages.py``), through zenoh
as ``rmw_zenoh_cpp`` speaks it (``rmw_zenoh.py``), so that a ROS 2 machine whose nodes run on
rmw_zenoh (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``, with its router ``rmw_zenohd``) sees a node
(``ros2 node list``) and its topics (``ros2 topic list/echo``, rviz2, rqt).

One zenoh session (``[ros2]``: peer or client, the endpoints; multicast scouting off, as
rmw_zenoh's default) holds the node's liveliness token and, per topic, a zenoh-ext advanced
publisher on the topic's key expression with its publisher's token, as rmw_zenoh declares
them. ``/tf_static`` and ``/robot_description`` are latched (reliable, transient local, keep
last 1, as tf2's static broadcaster and robot_state_publisher offer them) the way rmw_zenoh
does it: their advanced publishers keep the last message in a cache, announce themselves
(publisher detection) and send sporadic heartbeats, so a transient-local subscription that
starts later queries the cache and gets them. They are published once, when the publisher
starts, stamped with its wall-clock time. ``/rosout`` is volatile here (rcl's is transient
local, keep last 1000, ten-second lifespan): an ``rqt_console`` started later sees the events
from then on.

Names: the node is ``[ros2] node_name`` in ``[ros2] namespace``; every topic but ``/tf``,
``/tf_static`` and ``/rosout`` (absolute by ROS convention) is put in the namespace
(``/ucat/odom``). Frames are not prefixed.

Times: a message's stamp is its own time ``t`` on the stream's clock made UNIX time by
``epoch_offset`` (the supervisor's ``wall0``), as a recording would stamp it; a message with
no usable time takes the last one seen. The attachment's source timestamp is the wall-clock
time the message is put, as rmw_zenoh's.

Never in the loop's way: the stream's callback only appends to a bounded queue (the oldest
are dropped and counted when it is full); a thread of the publisher's builds, serializes and
puts (zenoh's congestion control: drop). An error while building or putting a topic's message
is logged once per topic and counted, never raised into the stream; :meth:`close` logs the
counts. Nothing is read from the ROS side: there are no services (``ros2 param`` does not
answer for this node) and no subscriptions.
"""

from __future__ import annotations

import collections
import importlib
import json
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Sequence

from ucat_console.backend import rmw_zenoh
from ucat_console.backend.ros_config import Ros2Config
from ucat_console.backend.sessions import codec
from ucat_console.backend.sessions.foxglove import robot_geometry
from ucat_console.backend.sessions.ros_messages import (
    CHANNELS,
    ROBOT_DESCRIPTION,
    ROSOUT,
    TF,
    TF_STATIC,
    TOPICS,
    MessageBuilder,
    Topic,
    handlers,
    typestore,
)
from ucat_console.robot import urdf
from ucat_console.telemetry.stream import TelemetryStream

log = logging.getLogger(__name__)

MISSING = ("the live ROS 2 topics need zenoh, the optional extra 'ros': pip install 'ucat-console[ros]' "
           "(or pip install eclipse-zenoh xxhash)")
#: the QoS of a topic and of a latched one (rmw_zenoh's token says it; ros2 topic info -v shows it)
VOLATILE = rmw_zenoh.Qos(depth=10)
LATCHED = rmw_zenoh.Qos(transient_local=True, depth=1)
#: topics that stay absolute in a namespace
GLOBAL_TOPICS = frozenset({TF.name, TF_STATIC.name, ROSOUT.name})
#: s between a latched publisher's sporadic heartbeats (rmw_zenoh's sample miss detection period)
HEARTBEAT_PERIOD = 0.5


def import_zenoh() -> Any:
    """The ``zenoh`` module (and its ``ext``); ImportError naming the extra when missing."""
    try:
        importlib.import_module("xxhash")  # rmw_zenoh.gid
        zenoh = importlib.import_module("zenoh")
        importlib.import_module("zenoh.ext")
    except ImportError as e:
        raise ImportError(MISSING) from e
    return zenoh


def qualified(topic: str, namespace: str) -> str:
    """``topic`` (absolute, ``/odom``) in ``namespace`` (``/`` or ``/ucat``): ``/ucat/odom``;
    the global topics stay as they are."""
    if namespace == "/" or topic in GLOBAL_TOPICS:
        return topic
    return namespace + topic


def zenoh_config(zenoh: Any, cfg: Ros2Config) -> Any:
    """The zenoh session's configuration: mode, endpoints, no multicast scouting (gossip on,
    as rmw_zenoh's: the router tells the ROS nodes of this peer), timestamps on."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(cfg.mode))
    c.insert_json5("connect/endpoints", json.dumps(list(cfg.connect)))
    c.insert_json5("listen/endpoints", json.dumps(list(cfg.listen) if cfg.mode == "peer" else []))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("timestamping/enabled", "true")
    return c


@dataclass
class _Publisher:
    """One topic's zenoh publisher, its token, GID and sequence number."""

    topic: Topic
    name: str  # fully qualified
    key: str
    token: str
    gid: bytes
    publisher: Any
    liveliness: Any
    sequence: int = 0
    sent: int = 0


class Ros2Publisher:
    """The stream's telemetry as ROS 2 topics through zenoh (module docstring); :meth:`close`
    or a context manager.

    ``config``: the ``[ros2]`` block; ``epoch_offset`` (s): added to the messages' ``t`` to
    make UNIX time; ``plant``: the plant configuration (``PlantConfig``) whose geometry places
    the fins and makes the URDF (None: the default U-CAT's). ImportError naming the extra
    without zenoh; ValueError when the session cannot open (the endpoints)."""

    def __init__(self, stream: TelemetryStream, config: Ros2Config, *, epoch_offset: float = 0.0,
                 plant: Any = None) -> None:
        zenoh = import_zenoh()
        from zenoh import ext

        self.config = config
        self.epoch_offset = float(epoch_offset)
        self._store = typestore()
        self._make = MessageBuilder(self._store, robot_geometry(plant))
        self._handlers = handlers(self._make)
        description = urdf.urdf_text(plant.geometry if plant is not None else None)
        try:
            self._session = zenoh.open(zenoh_config(zenoh, config))
        except zenoh.ZError as e:
            raise ValueError(f"ros2: cannot open the zenoh session ({e}); check ros2.connect "
                             f"{list(config.connect)} and ros2.listen {list(config.listen)}") from None
        self._publishers: dict[str, _Publisher] = {}
        try:
            namespace = config.full_namespace
            self.node = rmw_zenoh.Node(config.domain_id, str(self._session.info.zid()), 0, namespace,
                                       config.node_name)
            self._node_token = self._session.liveliness().declare_token(self.node.token())
            for entity_id, topic in enumerate(TOPICS, start=1):
                self._publishers[topic.name] = self._declare(zenoh, ext, entity_id, topic, namespace)
        except BaseException:
            self._session.close()
            raise

        self._queue: collections.deque[tuple[str, Any]] = collections.deque(maxlen=config.queue_size)
        self._dropped = 0
        self._errors: collections.Counter[str] = collections.Counter()  # topic or channel -> errors
        self._last_ns = time.time_ns()
        latched_ns = self._last_ns
        self._put(TF_STATIC, self._make.static_tf(latched_ns))
        self._put(ROBOT_DESCRIPTION, self._make.string(description))
        self._stopping = False
        self._wake = threading.Event()  # set when the queue gets messages (or on close)
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="ros2-publisher", daemon=True)
        self._thread.start()
        self._unsubscribe = stream.subscribe_batches(self._on_batch, CHANNELS)
        log.info("ROS 2 node %s publishing %d topics through zenoh (%s, domain %d, zenoh id %s)",
                 self.node_name, len(self._publishers), config.mode, config.domain_id, self.node.zid)

    def _declare(self, zenoh: Any, ext: Any, entity_id: int, topic: Topic, namespace: str) -> _Publisher:
        cfg = self.config
        qos = LATCHED if topic.latched else VOLATILE
        name = qualified(topic.name, namespace)
        type_name = rmw_zenoh.dds_type_name(topic.msgtype)
        type_hash = (self._store.hash_rihs01(topic.msgtype) if cfg.distro != "humble"
                     else rmw_zenoh.NO_TYPE_HASH)
        key = rmw_zenoh.topic_key(cfg.domain_id, name, type_name, type_hash)
        token = self.node.publisher_token(entity_id, name, type_name, type_hash, qos)
        options: dict[str, Any] = {}
        if qos.transient_local:  # as rmw_zenoh: a cache, publisher detection, sporadic heartbeats
            options = {"cache": ext.CacheConfig(qos.depth), "publisher_detection": True,
                       "sample_miss_detection": ext.MissDetectionConfig(heartbeat=None,
                                                                        sporadic_heartbeat=HEARTBEAT_PERIOD)}
        publisher = ext.declare_advanced_publisher(
            self._session, key, reliability=zenoh.Reliability.RELIABLE if qos.reliable else zenoh.Reliability.BEST_EFFORT,
            congestion_control=zenoh.CongestionControl.DROP, **options)
        liveliness = self._session.liveliness().declare_token(token)
        return _Publisher(topic, name, key, token, rmw_zenoh.gid(token), publisher, liveliness)

    # ------------------------------------------------------------------ properties
    @property
    def node_name(self) -> str:
        """The node's fully qualified name (``/ucat_console``, ``/ucat/ucat_console``)."""
        ns = self.node.namespace
        return f"{ns.rstrip('/')}/{self.node.name}"

    @property
    def topics(self) -> dict[str, str]:
        """Topic name (qualified) -> its zenoh key expression."""
        return {p.name: p.key for p in self._publishers.values()}

    @property
    def sent(self) -> int:
        """Messages put."""
        return sum(p.sent for p in self._publishers.values())

    @property
    def dropped(self) -> int:
        """Telemetry messages dropped because the queue was full."""
        return self._dropped

    @property
    def errors(self) -> int:
        """Messages that could not be built or put."""
        return sum(self._errors.values())

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Stop publishing; the tokens go (the node leaves the ROS graph) and the session closes
        (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._unsubscribe()
        self._stopping = True
        self._wake.set()
        self._thread.join()
        for p in self._publishers.values():
            for entity in (p.liveliness, p.publisher):
                try:
                    entity.undeclare()
                except Exception:  # the session is going anyway
                    log.debug("ROS 2 publisher: undeclaring %s failed", p.name, exc_info=True)
        try:
            self._node_token.undeclare()
        finally:
            self._session.close()
        if self._dropped or self.errors:
            log.warning("ROS 2 publisher: %d telemetry messages dropped (the publisher fell behind), "
                        "%d messages not published (errors)", self._dropped, self.errors)

    def __enter__(self) -> Ros2Publisher:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ the stream's side
    def _on_batch(self, items: Sequence[tuple[str, Any]]) -> None:
        q = self._queue
        over = len(q) + len(items) - q.maxlen  # type: ignore[operator]
        if over > 0:
            self._dropped += min(over, q.maxlen)  # type: ignore[type-var]
        q.extend(items)
        self._wake.set()

    # ------------------------------------------------------------------ the publisher's thread
    def _run(self) -> None:
        popleft = self._queue.popleft
        while True:
            try:
                channel, msg = popleft()
            except IndexError:
                if self._stopping:
                    return
                # the messages are queued before the wake-up is set: one set between the
                # wait and the clear is found by the next popleft
                self._wake.wait()
                self._wake.clear()
                continue
            t = getattr(msg, "t", None)
            if isinstance(t, (int, float)) and math.isfinite(t):
                self._last_ns = codec.to_ns(t, self.epoch_offset)
            ns = self._last_ns  # no usable time: the last one seen
            try:
                out = self._handlers[channel](msg, ns)
            except Exception:
                self._failed(channel)
                continue
            for topic, ros_msg in out:
                self._put(topic, ros_msg)

    def _put(self, topic: Topic, ros_msg: Any) -> None:
        p = self._publishers[topic.name]
        try:
            data = self._store.serialize_cdr(ros_msg, topic.msgtype)
            p.sequence += 1
            p.publisher.put(bytes(data), attachment=rmw_zenoh.attachment(p.sequence, time.time_ns(), p.gid))
            p.sent += 1
        except Exception:
            self._failed(topic.name)

    def _failed(self, what: str) -> None:
        """Count an error of a topic (or of a channel's messages); log the first with its traceback."""
        self._errors[what] += 1
        if self._errors[what] == 1:
            log.exception("ROS 2 publisher: cannot publish on %s (further errors there are counted, not logged)", what)
