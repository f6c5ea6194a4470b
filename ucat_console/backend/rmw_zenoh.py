"""rmw_zenoh's mapping of ROS 2 onto zenoh, for a publisher: the data key expression of a
topic, the liveliness tokens that put a node and its publishers in the ROS graph, the QoS
written into a token, the publisher's GID and the attachment every message carries.

It follows ``rmw_zenoh_cpp`` as released for Humble (0.1.x), Jazzy (0.2.x), Kilted (0.6.x)
and Rolling (0.12): ``docs/design.md`` and ``src/detail/liveliness_utils.cpp``,
``attachment_helpers.cpp``, ``rmw_publisher_data.cpp`` of those releases. Written here by hand
because no Python package speaks it (rclpy with rmw_zenoh needs a ROS install):

- data: ``<domain>/<topic without its leading and trailing />/<type>/<type hash>``, where
  the type is the DDS-style name (``nav_msgs::msg::dds_::Odometry_``) and the hash its
  REP-2011 ``RIHS01_<sha256>`` (Jazzy and later) or ``TypeHashNotSupported`` (Humble, which
  has no type hashes); the payload is the message in CDR, little endian, with its 4-byte
  encapsulation header (what ``rosbags``' ``serialize_cdr`` writes);
- liveliness: ``@ros2_lv/<domain>/<zenoh id>/<node id>/<entity id>/<NN|MP>/<enclave>/
  <namespace>/<node name>`` for a node, followed by ``/<topic>/<type>/<hash>/<qos>`` for a
  publisher, each name with its ``/`` written ``%`` (``mangle``); the node's two ids are its
  own, a publisher's the node's and its own (one counter of the session, from 0);
- QoS: ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:
  <liveliness>,<lease s>,<ns>`` with every field that equals rmw_zenoh's default (reliable,
  volatile, keep last 42, infinite durations, automatic liveliness) left empty, and the others
  as the numbers of rmw's enums (transient local is 1);
- GID: the XXH3 128-bit hash of the entity's liveliness key expression, its low 64 bits then
  its high 64 bits, each little endian;
- attachment: zenoh's serialization (``zenoh.ext.z_serialize``) of the sequence number (int64,
  from 1 for each publisher), the source timestamp (int64, ns since the UNIX epoch when the
  message is put) and the GID as a 16-byte sequence (its length, 16, then the bytes): 33 bytes.
  rmw_zenoh's subscriptions drop a sample whose attachment they cannot read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

#: the liveliness tokens' admin space
ADMIN_SPACE = "@ros2_lv"
NODE = "NN"
PUBLISHER = "MP"
#: the type hash of every type on Humble (its rosidl has no type hashes)
NO_TYPE_HASH = "TypeHashNotSupported"
#: rmw_zenoh's default history depth (a depth of 0 means it)
DEFAULT_DEPTH = 42
#: rmw's enums as rmw_zenoh writes them into a token
RELIABILITY_BEST_EFFORT = 2
DURABILITY_TRANSIENT_LOCAL = 1
#: the ROS distributions whose rmw_zenoh this mapping follows, and the type hash each uses
DISTROS = ("jazzy", "humble")
GID_SIZE = 16

_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(msg)/([A-Za-z][A-Za-z0-9]*)$")


def dds_type_name(msgtype: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (the type name rmw_zenoh's key expressions
    and tokens carry); ValueError for a name that is not a message type's."""
    m = _TYPE.match(msgtype)
    if m is None:
        raise ValueError(f"{msgtype!r} is not a ROS 2 message type name (package/msg/Name)")
    return f"{m[1]}::{m[2]}::dds_::{m[3]}_"


def mangle(name: str) -> str:
    """A ROS name in a token: every ``/`` written ``%`` (a key expression cannot hold ``//``)."""
    return name.replace("/", "%")


def topic_key(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The key expression a topic's messages are put on."""
    return f"{domain_id}/{topic.strip('/')}/{type_name}/{type_hash}"


@dataclass(frozen=True)
class Qos:
    """The QoS of one of our publishers: reliability, durability, keep-last depth (the rest:
    rmw_zenoh's defaults, which the token leaves empty)."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def token(self) -> str:
        """The QoS part of a liveliness token."""
        reliability = "" if self.reliable else str(RELIABILITY_BEST_EFFORT)
        durability = str(DURABILITY_TRANSIENT_LOCAL) if self.transient_local else ""
        depth = "" if self.depth in (0, DEFAULT_DEPTH) else str(self.depth)
        return f"{reliability}:{durability}:,{depth}:,:,:,,"


@dataclass(frozen=True)
class Node:
    """A ROS node of a zenoh session: its domain, the session's zenoh id (its text form),
    the node's id in the session, namespace (``/`` for none), name and enclave."""

    domain_id: int
    zid: str
    node_id: int
    namespace: str
    name: str
    enclave: str = "/"

    def _prefix(self, entity_id: int, kind: str) -> str:
        return "/".join((ADMIN_SPACE, str(self.domain_id), self.zid, str(self.node_id), str(entity_id), kind,
                         mangle(self.enclave), mangle(self.namespace), mangle(self.name)))

    def token(self) -> str:
        """The node's liveliness token."""
        return self._prefix(self.node_id, NODE)

    def publisher_token(self, entity_id: int, topic: str, type_name: str, type_hash: str, qos: Qos) -> str:
        """The liveliness token of the node's publisher ``entity_id`` on ``topic`` (fully qualified)."""
        return "/".join((self._prefix(entity_id, PUBLISHER), mangle(topic), mangle(type_name), mangle(type_hash),
                         qos.token()))


def gid(token: str) -> bytes:
    """The GID rmw_zenoh gives the entity of liveliness token ``token``."""
    import xxhash

    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")  # low 64 bits first


def attachment(sequence_number: int, source_timestamp_ns: int, source_gid: bytes) -> bytes:
    """The attachment of a message (module docstring)."""
    from zenoh.ext import Int64, z_serialize

    if len(source_gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(source_gid)}")
    return z_serialize((Int64(sequence_number), Int64(source_timestamp_ns), bytes(source_gid))).to_bytes()
