"""rosbag2 export of a session: a bag directory (``metadata.yaml`` and one MCAP file, CDR
messages with ``ros2msg`` schemas) that ``ros2 bag play``, ``ros2 bag info``, rviz, Foxglove
and PlotJuggler read, written by the ``rosbags`` library, so no ROS install is needed.

The topics, their types and the messages are :mod:`ros_messages`'s (the live ROS 2 publisher
sends the same): every topic of :data:`ros_messages.TOPICS` is in the bag, the latched
``/tf_static`` and ``/robot_description`` once, offered transient local.

Times: each message's ``header.stamp`` (``Log.stamp``) is the message's own time ``t`` on the
recorded stream's clock made UNIX time by the session's ``epoch_offset`` (wall-clock UNIX time
for live runs; for a simulated run, simulated time offset by the run's wall-clock start); the bag's
receive time of each message is its log time in the session file (the same, except for a
message that came late on its channel, which is logged at the channel's last time). The
latched messages carry the first exported message's time.

The bag is written into a temporary directory beside the destination and renamed into place
when complete, so a failed export leaves nothing behind.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer

from ucat_console.backend.sessions import foxglove
from ucat_console.backend.sessions.reader import SessionSource
from ucat_console.backend.sessions.ros_messages import (
    CHANNELS,
    ROBOT_DESCRIPTION,
    TF_STATIC,
    TOPICS,
    MessageBuilder,
    Topic,
    handlers,
    typestore,
)
from ucat_console.robot import urdf

#: the rosbag2 metadata version written (rosbags writes 8 or 9; Jazzy and later read 9)
BAG_VERSION = 9

_ZERO = QosTime(0, 0)
#: what a latching publisher offers (robot_state_publisher's /robot_description and
#: tf2's /tf_static): reliable, transient local, keep last 1; ``ros2 bag play`` replays a
#: topic with the QoS its recording offered
LATCHED_QOS = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                  _ZERO, _ZERO, QosLiveliness.AUTOMATIC, _ZERO, False)


# ---------------------------------------------------------------------- the bag
def check_destination(out: Path) -> None:
    """ValueError unless ``out`` is free: absent, or an empty directory."""
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise ValueError(f"--rosbag2: {out} exists and is not a directory")
        if any(out.iterdir()):
            raise ValueError(f"--rosbag2: {out} is not empty (a bag is written into a new or empty directory)")


def export_rosbag2(
    source: SessionSource,
    out_dir: str | Path,
    start: float | None = None,
    end: float | None = None,
    plant: Any = None,
) -> dict[str, int]:
    """Write the session ``source`` (a part or a whole session) within ``[start, end)``
    (stream seconds) as a rosbag2 bag in the directory ``out_dir`` (absent or empty).

    ``plant``: the recorded plant configuration (``PlantConfig``), whose geometry places the
    fins and makes the URDF; None: the default U-CAT's. Returns topic -> messages written.
    ValueError for a destination that is not free (nothing is written then, nor when
    writing fails).
    """
    out = Path(out_dir)
    check_destination(out)
    store = typestore()
    geometry = foxglove.robot_geometry(plant)
    make = MessageBuilder(store, geometry)
    description = urdf.urdf_text(plant.geometry if plant is not None else None)
    to_ns = source.to_ns
    present = set(source.channels)
    channels = [c for c in CHANNELS if c in present]
    first_ns = source.start_ns if start is None else max(source.start_ns, to_ns(start))
    handle = handlers(make)

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        bag = tmp / out.name
        writer = Writer(bag, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        with writer:
            conns = {
                tp.name: writer.add_connection(tp.name, tp.msgtype, typestore=store,
                                               offered_qos_profiles=[LATCHED_QOS] if tp.latched else [])
                for tp in TOPICS
            }
            counts = {tp.name: 0 for tp in TOPICS}

            def write(topic: Topic, msg: Any, log_ns: int) -> None:
                writer.write(conns[topic.name], log_ns, store.serialize_cdr(msg, topic.msgtype))
                counts[topic.name] += 1

            write(TF_STATIC, make.static_tf(first_ns), first_ns)
            write(ROBOT_DESCRIPTION, make.string(description), first_ns)
            for rec in source.records(channels, start, end) if channels else ():
                ns = to_ns(rec.message.t)
                for topic, msg in handle[rec.channel](rec.message, ns):
                    write(topic, msg, rec.log_time_ns)
            writer.set_custom_data("ucat_console.session", str(getattr(source, "session_id", source.path.name)))
            writer.set_custom_data("ucat_console.epoch_offset", repr(source.epoch_offset))
        check_destination(out)  # (still free: nothing else wrote there meanwhile)
        os.replace(bag, out)  # onto an empty directory too
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return counts
