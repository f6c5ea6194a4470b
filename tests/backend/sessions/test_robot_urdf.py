"""The robot's URDF: parsed by a URDF library (yourdfpy), its links the transform frames of the
session files, its joints the fin mounts and the servo model's limits, its hull the
ellipsoid the console draws; the shipped files are what the module makes now."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from mcap.reader import make_reader
from session_helpers import record

from ucat_console.backend.sessions import foxglove
from ucat_console.robot import urdf
from ucat_console.robot.geometry import Geometry, fin_mount
from ucat_console.robot.rotations import quaternion_multiply, rotation_matrix
from ucat_console.robot.servo import FIN_MAX_RATE
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import FinState

yourdfpy = pytest.importorskip("yourdfpy")


def _load():
    return yourdfpy.URDF.load(str(urdf.URDF_PATH), build_scene_graph=True, load_meshes=True,
                              filename_handler=lambda fname: str(urdf.package_file(fname)))


def _matrix(position, wxyz) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation_matrix(wxyz)
    m[:3, 3] = position
    return m


def test_the_shipped_files_are_what_the_module_makes():
    assert urdf.URDF_PATH.read_text() == urdf.urdf_text()
    assert urdf.MESH_PATH.read_bytes() == urdf.sphere_stl()


def test_links_are_the_transform_frames_and_joints_the_fin_mounts_and_servo_limits():
    robot = _load()
    # every frame the files place below the vehicle is a link, and nothing else is
    below_vehicle = {c for c in foxglove.CHILD_FRAMES if c not in (foxglove.ODOM_FRAME, foxglove.ODOM_NED_FRAME)}
    assert set(robot.link_map) == below_vehicle | {foxglove.BODY_FRAME}
    assert robot.base_link == foxglove.BODY_FRAME
    # the FLU base_link: the files' static transform
    parent, wxyz = foxglove.STATIC_TRANSFORMS[foxglove.BASE_LINK_FRAME]
    assert parent == foxglove.BODY_FRAME
    np.testing.assert_allclose(robot.get_transform("base_link", foxglove.BODY_FRAME),
                               _matrix((0.0, 0.0, 0.0), wxyz), atol=1e-12)
    g = Geometry()
    for i in range(4):
        joint = robot.joint_map[f"fin{i}_joint"]
        assert (joint.parent, joint.child, joint.type) == (foxglove.BODY_FRAME, f"fin{i}", "continuous")
        assert joint.limit.velocity == FIN_MAX_RATE
        np.testing.assert_allclose(joint.axis, (0.0, 0.0, 1.0))
        np.testing.assert_allclose(robot.get_transform(f"fin{i}", foxglove.BODY_FRAME),
                                   _matrix(*fin_mount(g, i)), atol=1e-8)


def test_the_hull_is_the_ellipsoid_of_the_hull_size():
    robot = _load()
    hull = next(v for v in robot.link_map[foxglove.BODY_FRAME].visuals if v.name == "hull")
    np.testing.assert_allclose(hull.geometry.mesh.scale, np.array(Geometry().hull_size) / 2)
    sphere = np.array([p for tri in urdf.unit_sphere() for p in tri])
    np.testing.assert_allclose(np.linalg.norm(sphere, axis=1), 1.0, atol=1e-12)
    lo, hi = robot.scene.bounds  # the whole robot: the hull's length, the fins outside it
    assert hi[0] - lo[0] >= Geometry().hull_size[0] - 1e-3


def test_a_recorded_fin_transform_is_the_urdf_joint_at_the_measured_angle(sessions):
    angle = 0.7
    [path] = record(sessions, [(C.fin_state(2), FinState(1.0, 2, angle, 0.0, 0.0, 0.0))])
    with open(path, "rb") as fh:
        [(_, channel, message)] = list(make_reader(fh).iter_messages(topics=["foxglove/tf/fin2"]))
    tf = json.loads(message.data)
    robot = _load()
    robot.update_cfg({"fin2_joint": angle})
    want = robot.get_transform("fin2", tf["parent_frame_id"])
    got = _matrix([tf["translation"][k] for k in "xyz"], [tf["rotation"][k] for k in "wxyz"])
    np.testing.assert_allclose(got, want, atol=1e-8)
    # (and the angle turned the mount about its z axis)
    position, mount = fin_mount(Geometry(), 2)
    turned = quaternion_multiply(mount, (math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)))
    np.testing.assert_allclose(got, _matrix(position, turned), atol=1e-12)


def test_only_the_robots_files_are_package_files():
    assert urdf.package_file(urdf.URDF_URI) == urdf.URDF_PATH
    assert urdf.package_file(urdf.MESH_URI) == urdf.MESH_PATH
    for uri in ("package://ucat_console/robot/urdf/../../../etc/passwd", "file:///etc/passwd",
                "package://ucat_console/robot/urdf.py", ""):
        assert urdf.package_file(uri) is None
