"""The ``[ros2]`` configuration: the live ROS 2 publisher (``backend/ros_live.py``) through
zenoh, as rmw_zenoh speaks it: domain, node, namespace, the zenoh session's mode and
endpoints, the ROS distribution whose type hashes the key expressions carry."""

from __future__ import annotations

import re
from dataclasses import dataclass

from ucat_console.backend.rmw_zenoh import DISTROS
from ucat_console.typedconf import Config, param

#: the highest ROS domain id (ROS 2's documented range, 0..232)
MAX_DOMAIN_ID = 232
#: a node name: letters, digits and underscores, not starting with a digit (rcl's rule)
_NODE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: a zenoh endpoint: <protocol>/<address>[#config]
_ENDPOINT = re.compile(r"^[a-z][a-z0-9+-]*/[^/\s#][^\s#]*(#\S*)?$")


def check_node_name(name: str) -> None:
    """ValueError unless ``name`` is a valid ROS 2 node name."""
    if not _NODE_NAME.match(name) or len(name) > 255:
        raise ValueError(f"node_name: {name!r} is not a ROS 2 node name; allowed: letters, digits and "
                         "underscores, not starting with a digit, e.g. 'ucat_console'")


def normalized_namespace(ns: str) -> str:
    """``ns`` as a fully qualified namespace (``""`` -> ``/``, ``robot`` -> ``/robot``);
    ValueError for one that is not a ROS 2 namespace."""
    full = "/" + ns.strip("/") if ns not in ("", "/") else "/"
    tokens = [t for t in full.split("/") if t]
    if ns.endswith("/") and ns != "/" or "//" in ns or not all(_NODE_NAME.match(t) for t in tokens):
        raise ValueError(f"namespace: {ns!r} is not a ROS 2 namespace; allowed: '' (none) or '/a/b', each "
                         "token letters, digits and underscores, not starting with a digit")
    return full


@dataclass(frozen=True)
class Ros2Config(Config):
    """The live ROS 2 topics, ``run --ros2`` (docs/sessions.md, Live ROS 2 topics)."""

    enabled: bool = param(False, doc="publish the live telemetry as ROS 2 topics through zenoh (rmw_zenoh); "
                                     "needs the 'ros' extra")
    domain_id: int = param(0, lo=0, hi=MAX_DOMAIN_ID, doc="ROS_DOMAIN_ID of the ROS 2 machines that read the topics")
    node_name: str = param("ucat_console", doc="the node the topics belong to (ros2 node list)")
    namespace: str = param(
        "", doc="the node's namespace ('' for none, or '/ucat'); every topic but /tf, /tf_static and /rosout "
        "is put in it",
    )
    mode: str = param("peer", choices=("peer", "client"),
                      doc="the zenoh session's mode: peer (as rmw_zenoh's nodes) or client (through the router only)")
    connect: tuple[str, ...] = param(
        ("tcp/localhost:7447",),
        doc="zenoh endpoints to connect to: the rmw_zenoh router (ros2 run rmw_zenoh_cpp rmw_zenohd) of this "
        "machine by default; another machine's as 'tcp/192.168.1.10:7447'",
    )
    listen: tuple[str, ...] = param(
        ("tcp/localhost:0",),
        doc="zenoh endpoints a peer listens on for the ROS nodes' direct connections (as rmw_zenoh's "
        "default: this machine, any port); 'tcp/0.0.0.0:0' for nodes on other machines",
    )
    distro: str = param(
        "jazzy", choices=DISTROS,
        doc="the ROS 2 distribution of the machines that read the topics: jazzy (Jazzy, Kilted, Rolling: "
        "Jazzy's type hashes) or humble (no type hashes)",
    )
    queue_size: int = param(
        10_000, lo=100, hi=1_000_000,
        doc="telemetry messages waiting to be published before the oldest are dropped (and counted)",
    )

    def _check(self) -> None:
        check_node_name(self.node_name)
        normalized_namespace(self.namespace)
        for key, endpoints in (("connect", self.connect), ("listen", self.listen)):
            for e in endpoints:
                if not _ENDPOINT.match(e):
                    raise ValueError(f"{key}: {e!r} is not a zenoh endpoint; allowed: <protocol>/<address>, "
                                     "e.g. 'tcp/localhost:7447'")
        if self.mode == "client" and not self.connect:
            raise ValueError("connect: a client connects to a router; give its endpoint, e.g. 'tcp/localhost:7447'")

    @property
    def full_namespace(self) -> str:
        return normalized_namespace(self.namespace)
