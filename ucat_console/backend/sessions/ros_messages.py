"""The console's ROS 2 topics and the one builder of their messages, from the telemetry: what
a rosbag2 export writes (``rosbag2_export.py``) and what the live ROS 2 publisher sends
(``backend/ros_live.py``), with the same topics, types and values.

Topics (:data:`TOPICS`; frames as the URDF, ``robot/ucat_description``, and the session
files' transforms, ``foxglove.py``, name them)::

    /tf_static          tf2_msgs/TFMessage      map -> odom, odom -> odom_ned, base_link ->
                                                base_link_frd; once, transient local
    /robot_description  std_msgs/String         the URDF (of the recorded geometry); once,
                                                transient local
    /tf                 tf2_msgs/TFMessage      odom -> base_link with every body state,
                                                base_link_frd -> fin<i> with every fin state
    /odom               nav_msgs/Odometry       body/state: pose in odom (ENU), twist in
                                                base_link (FLU)
    /imu                sensor_msgs/Imu         sensors/imu, in base_link (FLU; orientation
                                                of base_link in ENU)
    /pressure           sensor_msgs/FluidPressure  sensors/depth's gauge pressure + the standard atmosphere (Pa)
    /joint_states       sensor_msgs/JointState  fin/<i>/state: fin<i>_joint's angle and rate
    /fin<i>/state       ucat_msgs/FinState      fin/<i>/state, every field
    /fin<i>/strouhal    ucat_msgs/FinStrouhal   fin/<i>/strouhal
    /power              ucat_msgs/Power         power
    /power/electrical   ucat_msgs/ElectricalPower  power/electrical
    /rosout             rcl_interfaces/Log      events (name: source, msg: "code: message")

The NED/FRD telemetry becomes ENU/FLU (REP 103/105) through the one conversion the session
files' transforms use (``foxglove.enu_position``, ``enu_flu_orientation``, ``flu_vector``).
Each message's ``header.stamp`` (``Log.stamp``) is the time handed to the builder (the
message's own time ``t`` made UNIX time by the caller).

Covariances follow sensor_msgs' convention: all zeros is "unknown" (the console has no
estimate of them); an IMU reading without orientation has ``orientation_covariance[0] = -1``
and a NaN orientation. A transform that is not finite is left out of ``/tf`` (tf2 refuses
it); every other message is built as given, NaN included.

Our own messages (``ucat_msgs``: ``robot/ucat_msgs``, an ament package a ROS user builds) are
read from their ``.msg`` files and registered into the ROS 2 Jazzy type store; each field
takes the telemetry field of its name (a test checks the names match).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from ucat_console.backend.sessions import foxglove
from ucat_console.robot import urdf
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event

#: the ROS 2 distribution whose standard message definitions (and type hashes) the messages carry
ROS_DISTRO = Stores.ROS2_JAZZY
MSG_PACKAGE = "ucat_msgs"
MSG_PACKAGE_DIR = Path(urdf.__file__).with_name(MSG_PACKAGE)
#: the standard atmosphere (Pa, ISO 2533): the depth transducer (Gems 3101P) is a gauge type,
#: reading above the atmosphere, and FluidPressure is absolute
STANDARD_ATMOSPHERE_PA = 101_325.0
#: the IMU's and the pressure sensor's frame: the URDF has no sensor links, and the sensors'
#: axes are the body's (the IMU's readings are converted from FRD to FLU)
SENSOR_FRAME = foxglove.BASE_LINK_FRAME
#: rcl_interfaces/Log's level of each event level
LOG_LEVELS = {"debug": 10, "info": 20, "warning": 30, "error": 40, "fatal": 50}


@dataclass(frozen=True)
class Topic:
    """One topic of the bag: its name, ROS type, the session channel it comes from, and
    whether it is latched (transient local, written once)."""

    name: str
    msgtype: str
    source: str
    latched: bool = False


def fin_topic(fin: int, kind: str) -> str:
    """``/fin<i>/state``, ``/fin<i>/strouhal`` (a ROS name's token cannot start with a digit,
    so ``fin/0/state`` cannot be kept as it is)."""
    return f"/{urdf.fin_link(fin)}/{kind}"


TF_STATIC = Topic("/tf_static", "tf2_msgs/msg/TFMessage", "fixed frames", latched=True)
ROBOT_DESCRIPTION = Topic("/robot_description", "std_msgs/msg/String", "the URDF", latched=True)
TF = Topic("/tf", "tf2_msgs/msg/TFMessage", f"{C.BODY_STATE}, fin/<i>/state")
ODOM = Topic("/odom", "nav_msgs/msg/Odometry", C.BODY_STATE)
IMU = Topic("/imu", "sensor_msgs/msg/Imu", C.IMU)
PRESSURE = Topic("/pressure", "sensor_msgs/msg/FluidPressure", C.DEPTH)
JOINT_STATES = Topic("/joint_states", "sensor_msgs/msg/JointState", "fin/<i>/state")
POWER = Topic("/power", f"{MSG_PACKAGE}/msg/Power", C.POWER)
ELECTRICAL = Topic("/power/electrical", f"{MSG_PACKAGE}/msg/ElectricalPower", C.POWER_ELECTRICAL)
ROSOUT = Topic("/rosout", "rcl_interfaces/msg/Log", C.EVENTS)
FIN_STATES = tuple(Topic(fin_topic(i, "state"), f"{MSG_PACKAGE}/msg/FinState", C.fin_state(i))
                   for i in range(C.N_FINS))
FIN_STROUHALS = tuple(Topic(fin_topic(i, "strouhal"), f"{MSG_PACKAGE}/msg/FinStrouhal", C.fin_strouhal(i))
                      for i in range(C.N_FINS))
#: every topic, in the bag's order
TOPICS: tuple[Topic, ...] = (TF_STATIC, ROBOT_DESCRIPTION, TF, ODOM, IMU, PRESSURE, JOINT_STATES,
                             *FIN_STATES, *FIN_STROUHALS, POWER, ELECTRICAL, ROSOUT)
#: the session channels read
CHANNELS = (C.BODY_STATE, C.IMU, C.DEPTH, *(C.fin_state(i) for i in range(C.N_FINS)),
            *(C.fin_strouhal(i) for i in range(C.N_FINS)), C.POWER, C.POWER_ELECTRICAL, C.EVENTS)

def msg_files() -> list[Path]:
    """The ``.msg`` files of ``ucat_msgs``."""
    return sorted((MSG_PACKAGE_DIR / "msg").glob("*.msg"))


@functools.cache
def typestore() -> Any:
    """The ROS 2 type store with ``ucat_msgs`` registered."""
    store = get_typestore(ROS_DISTRO)
    types: dict[str, Any] = {}
    for path in msg_files():
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), f"{MSG_PACKAGE}/msg/{path.stem}"))
    store.register(types)
    return store


def own_fields(msgtype: str) -> list[str]:
    """The fields of one of our messages that come from the telemetry (all but the header)."""
    cls = typestore().types[msgtype]
    return [f.name for f in dataclasses.fields(cls) if f.name != "header" and not f.name.startswith("__")]


# ---------------------------------------------------------------------- messages
class MessageBuilder:
    """The ROS messages of telemetry messages, built from the type store's classes (the bag
    export's and the live publisher's one builder)."""

    def __init__(self, store: Any, geometry: foxglove.RobotGeometry) -> None:
        t = store.types
        self._time = t["builtin_interfaces/msg/Time"]
        self._header = t["std_msgs/msg/Header"]
        self._vector = t["geometry_msgs/msg/Vector3"]
        self._point = t["geometry_msgs/msg/Point"]
        self._quaternion = t["geometry_msgs/msg/Quaternion"]
        self._t = t
        self.geometry = geometry
        self._own = {tp.msgtype: own_fields(tp.msgtype) for tp in TOPICS if tp.msgtype.startswith(MSG_PACKAGE)}

    def stamp(self, ns: int) -> Any:
        sec, nsec = divmod(int(ns), 1_000_000_000)
        return self._time(sec=sec, nanosec=nsec)

    def header(self, ns: int, frame: str) -> Any:
        return self._header(stamp=self.stamp(ns), frame_id=frame)

    def vector(self, v: Sequence[float]) -> Any:
        return self._vector(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quaternion(self, q: Sequence[float]) -> Any:  # q held w first
        return self._quaternion(x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0]))

    def transform(self, tf: dict[str, Any]) -> Any:
        """geometry_msgs/TransformStamped of a foxglove.FrameTransform (the same numbers)."""
        t = self._t
        ts = tf["timestamp"]
        tr, rot = tf["translation"], tf["rotation"]
        return t["geometry_msgs/msg/TransformStamped"](
            header=self._header(stamp=self._time(sec=ts["sec"], nanosec=ts["nsec"]),
                                frame_id=tf["parent_frame_id"]),
            child_frame_id=tf["child_frame_id"],
            transform=t["geometry_msgs/msg/Transform"](
                translation=self._vector(x=tr["x"], y=tr["y"], z=tr["z"]),
                rotation=self._quaternion(x=rot["x"], y=rot["y"], z=rot["z"], w=rot["w"])))

    def tf(self, transforms: list[dict[str, Any]]) -> Any:
        return self._t["tf2_msgs/msg/TFMessage"](transforms=[self.transform(x) for x in transforms])

    def static_tf(self, ns: int) -> Any:
        return self.tf([tf for _, tf in foxglove.static_transforms(ns)])

    def string(self, text: str) -> Any:
        return self._t["std_msgs/msg/String"](data=text)

    def odometry(self, m: Any, ns: int) -> Any:
        t = self._t
        p = foxglove.enu_position(m.position)
        zeros = np.zeros(36)
        return t["nav_msgs/msg/Odometry"](
            header=self.header(ns, foxglove.ODOM_FRAME),
            child_frame_id=foxglove.BASE_LINK_FRAME,
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](
                    position=self._point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    orientation=self.quaternion(foxglove.enu_flu_orientation(m.orientation))),
                covariance=zeros),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](linear=self.vector(foxglove.flu_vector(m.velocity)),
                                                   angular=self.vector(foxglove.flu_vector(m.rates))),
                covariance=zeros))

    def imu(self, m: Any, ns: int) -> Any:
        unknown = np.zeros(9)
        if m.quaternion is None:
            orientation = self._quaternion(x=math.nan, y=math.nan, z=math.nan, w=math.nan)
            orientation_cov = np.zeros(9)
            orientation_cov[0] = -1.0  # sensor_msgs/Imu: no orientation estimate
        else:
            orientation = self.quaternion(foxglove.enu_flu_orientation(m.quaternion))
            orientation_cov = unknown
        return self._t["sensor_msgs/msg/Imu"](
            header=self.header(ns, SENSOR_FRAME),
            orientation=orientation, orientation_covariance=orientation_cov,
            angular_velocity=self.vector(foxglove.flu_vector(m.gyro)), angular_velocity_covariance=unknown,
            linear_acceleration=self.vector(foxglove.flu_vector(m.accel)),
            linear_acceleration_covariance=unknown)

    def pressure(self, m: Any, ns: int) -> Any:
        return self._t["sensor_msgs/msg/FluidPressure"](
            header=self.header(ns, SENSOR_FRAME), fluid_pressure=float(m.pressure_pa) + STANDARD_ATMOSPHERE_PA, variance=0.0)

    def joint_state(self, m: Any, ns: int) -> Any:
        return self._t["sensor_msgs/msg/JointState"](
            header=self.header(ns, ""), name=[joint_name(m.fin)],
            position=np.array([m.angle], dtype=np.float64), velocity=np.array([m.rate], dtype=np.float64),
            effort=np.zeros(0, dtype=np.float64))

    def own(self, msgtype: str, m: Any, ns: int, frame: str) -> Any:
        """One of our messages: each field the telemetry field of its name."""
        values: dict[str, Any] = {}
        for name in self._own[msgtype]:
            v = getattr(m, name)
            values[name] = np.array(v, dtype=np.float64) if isinstance(v, tuple) else v
        return self._t[msgtype](header=self.header(ns, frame), **values)

    def log(self, e: Event, ns: int) -> Any:
        return self._t["rcl_interfaces/msg/Log"](
            stamp=self.stamp(ns), level=LOG_LEVELS[e.level], name=e.source, msg=f"{e.code}: {e.message}",
            file="", function="", line=0)


def joint_name(fin: int) -> str:
    """The URDF's joint of fin ``fin``."""
    return f"{urdf.fin_link(fin)}_joint"


Handler = Callable[[Any, int], list[tuple[Topic, Any]]]


def handlers(make: MessageBuilder) -> dict[str, Handler]:
    """channel -> the (topic, ROS message) pairs of one of its messages."""
    mounts = make.geometry.fin_mounts

    def body(m: Any, ns: int) -> list[tuple[Topic, Any]]:
        out = [(ODOM, make.odometry(m, ns))]
        tf = foxglove.frame_transform(m, ns)
        if tf is not None:
            out.insert(0, (TF, make.tf([tf])))
        return out

    def fin_state(fin: int) -> Handler:
        def handle(m: Any, ns: int) -> list[tuple[Topic, Any]]:
            out = [(JOINT_STATES, make.joint_state(m, ns)),
                   (FIN_STATES[fin], make.own(FIN_STATES[fin].msgtype, m, ns, urdf.fin_link(fin)))]
            tf = foxglove.fin_transform(m, mounts[fin], ns, fin)
            if tf is not None:
                out.insert(0, (TF, make.tf([tf])))
            return out
        return handle

    def fin_strouhal(fin: int) -> Handler:
        topic = FIN_STROUHALS[fin]
        return lambda m, ns: [(topic, make.own(topic.msgtype, m, ns, urdf.fin_link(fin)))]

    return {
        C.BODY_STATE: body,
        C.IMU: lambda m, ns: [(IMU, make.imu(m, ns))],
        C.DEPTH: lambda m, ns: [(PRESSURE, make.pressure(m, ns))],
        **{C.fin_state(i): fin_state(i) for i in range(C.N_FINS)},
        **{C.fin_strouhal(i): fin_strouhal(i) for i in range(C.N_FINS)},
        C.POWER: lambda m, ns: [(POWER, make.own(POWER.msgtype, m, ns, foxglove.BASE_LINK_FRAME))],
        C.POWER_ELECTRICAL: lambda m, ns: [(ELECTRICAL, make.own(ELECTRICAL.msgtype, m, ns,
                                                                 foxglove.BASE_LINK_FRAME))],
        C.EVENTS: lambda m, ns: [(ROSOUT, make.log(m, ns))],
    }

