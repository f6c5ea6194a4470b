"""The robot's URDF: parsed by a URDF library (yourdfpy), its links the transform frames of the
session files (root base_link, FLU), its joints the fin mounts with the drive's limits, its
inertials the plant's rigid body and fin inertia, its hull the ellipsoid the console draws;
the shipped ROS package holds what the module makes now and resolves its package URIs."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from session_helpers import record

from ucat_console.backend.sessions import foxglove
from ucat_console.robot import hull, urdf
from ucat_console.robot.geometry import FIN_AREA, Geometry, fin_mount
from ucat_console.robot.motor import NOMINAL_CURRENT, FinMotor
from ucat_console.robot.rotations import quaternion_multiply, rotation_matrix
from ucat_console.robot.servo import FIN_MAX_RATE
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import BodyState, FinState

ROOT = Path(__file__).resolve().parents[3]

yourdfpy = pytest.importorskip("yourdfpy")


def _ros_package_path(fname: str) -> str:
    """A ``package://`` URI resolved as ROS_PACKAGE_PATH and Foxglove do: the folder of that
    name with a package.xml naming it, under the folder that holds the shipped package."""
    assert fname.startswith("package://"), fname
    package, _, rest = fname.removeprefix("package://").partition("/")
    folder = urdf.PACKAGE_DIR.parent / package
    assert ET.parse(folder / "package.xml").getroot().findtext("name") == package, fname
    return str(folder / rest)


def _load():
    return yourdfpy.URDF.load(str(urdf.URDF_PATH), build_scene_graph=True, load_meshes=True,
                              filename_handler=_ros_package_path)


def _matrix(position, wxyz) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation_matrix(wxyz)
    m[:3, 3] = position
    return m


def test_the_shipped_files_are_what_the_module_makes():
    assert urdf.URDF_PATH.read_text() == urdf.urdf_text()
    assert urdf.MESH_PATH.read_bytes() == urdf.sphere_stl()


def test_links_are_the_transform_frames_and_joints_the_fin_mounts_and_drive_limits():
    robot = _load()
    # every frame the files place below the vehicle is a link, and nothing else is
    below_vehicle = {c for c in foxglove.CHILD_FRAMES if c not in (foxglove.ODOM_FRAME, foxglove.ODOM_NED_FRAME)}
    assert set(robot.link_map) == below_vehicle
    assert robot.base_link == foxglove.BASE_LINK_FRAME == "base_link"
    # base_link_frd below the FLU base_link: the files' static transform, half a turn about x
    parent, wxyz = foxglove.STATIC_TRANSFORMS[foxglove.BODY_FRAME]
    assert parent == foxglove.BASE_LINK_FRAME
    half_turn_about_x = np.diag([1.0, -1.0, -1.0, 1.0])
    np.testing.assert_allclose(_matrix((0.0, 0.0, 0.0), wxyz), half_turn_about_x, atol=1e-12)
    np.testing.assert_allclose(robot.get_transform(foxglove.BODY_FRAME, "base_link"), half_turn_about_x,
                               atol=1e-12)
    g = Geometry()
    for i in range(4):
        joint = robot.joint_map[f"fin{i}_joint"]
        assert (joint.parent, joint.child, joint.type) == (foxglove.BODY_FRAME, f"fin{i}", "continuous")
        assert joint.limit.velocity == FIN_MAX_RATE > 0
        # the torque the motor's nominal current gives the shaft: 0.036 x (2.52 - 0.238) x 35 x 0.7
        assert joint.limit.effort == pytest.approx(FinMotor().shaft_torque(NOMINAL_CURRENT), rel=1e-9)
        assert joint.limit.effort == pytest.approx(2.0127, abs=1e-4)
        np.testing.assert_allclose(joint.axis, (0.0, 0.0, 1.0))
        np.testing.assert_allclose(robot.get_transform(f"fin{i}", foxglove.BODY_FRAME),
                                   _matrix(*fin_mount(g, i)), atol=1e-8)


def test_the_hull_is_the_ellipsoid_of_the_hull_size():
    robot = _load()
    shape = next(v for v in robot.link_map[foxglove.BODY_FRAME].visuals if v.name == "hull")
    np.testing.assert_allclose(shape.geometry.mesh.scale, np.array(Geometry().hull_size) / 2)
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
    # what a layout saved before the ROS package names
    assert urdf.package_file("package://ucat_console/robot/urdf/ucat.urdf") == urdf.URDF_PATH
    for uri in ("package://ucat_description/urdf/../../../etc/passwd", "file:///etc/passwd",
                "package://ucat_description/package.xml", "package://ucat_console/robot/urdf.py", ""):
        assert urdf.package_file(uri) is None


def _world(inertial) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre of mass, inertia about it) of a yourdfpy inertial, in its link."""
    origin = inertial.origin if inertial.origin is not None else np.eye(4)
    r = origin[:3, :3]
    return inertial.mass, origin[:3, 3], r @ inertial.inertia @ r.T


def test_every_link_but_the_root_has_a_physical_inertial_and_a_collision():
    robot = _load()
    for name, link in robot.link_map.items():
        if name == robot.base_link:
            continue  # (KDL takes no inertial on the root; the hull is in base_link_frd)
        assert link.inertial is not None and link.collisions, name
        mass, _, inertia = _world(link.inertial)
        assert mass > 0, name
        np.testing.assert_allclose(inertia, inertia.T, atol=1e-15)
        principal = np.linalg.eigvalsh(inertia)
        assert principal.min() > 0, name  # positive definite
        a, b, c = principal
        assert a + b >= c and b + c >= a and a + c >= b, name  # a rigid body's moments
    hull_box = robot.link_map[foxglove.BODY_FRAME].collisions[0].geometry.box
    np.testing.assert_allclose(hull_box.size, Geometry().hull_size)
    for i in range(4):
        [collision] = robot.link_map[f"fin{i}"].collisions
        chord, thickness, span = collision.geometry.box.size
        assert chord * span == pytest.approx(FIN_AREA)  # the fin's planform area
        assert thickness < 0.01 and chord == pytest.approx(1.5 * Geometry().fin_length)
        # it hangs off the shaft (the joint's z axis through the link's origin) along x
        np.testing.assert_allclose(collision.origin[:3, 3], (chord / 2, 0.0, 0.0), atol=1e-12)


def test_the_whole_robot_is_the_plants_rigid_body_and_each_fin_the_plants_fin_inertia():
    robot = _load()  # fins at their neutral angle: the configuration the plant's inertias are of
    total, moment, parts = 0.0, np.zeros(3), []
    for name, link in robot.link_map.items():
        if link.inertial is None:
            continue
        mass, com, inertia = _world(link.inertial)
        pose = robot.get_transform(name, foxglove.BODY_FRAME)  # the link in base_link_frd
        r = pose[:3, :3]
        c = pose[:3, 3] + r @ com
        total += mass
        moment += mass * c
        parts.append((mass, c, r @ inertia @ r.T))
    cg = moment / total
    assert total == pytest.approx(hull.MASS)
    np.testing.assert_allclose(cg, hull.CG, atol=1e-10)
    about_cg = sum(i + m * (float((c - cg) @ (c - cg)) * np.eye(3) - np.outer(c - cg, c - cg))
                   for m, c, i in parts)
    np.testing.assert_allclose(about_cg, np.diag([hull.IXX, hull.IYY, hull.IZZ]), atol=1e-10)
    for i in range(4):
        mass, com, inertia = _world(robot.link_map[f"fin{i}"].inertial)
        # about the shaft: the link's z axis through its origin (parallel axis from the centre)
        assert inertia[2, 2] + mass * (com[0] ** 2 + com[1] ** 2) == pytest.approx(hull.FIN_INERTIA)


def test_the_ros_package_names_itself_and_resolves_the_urdfs_meshes():
    pkg = ET.parse(urdf.PACKAGE_XML).getroot()
    assert pkg.tag == "package" and pkg.get("format") == "3"
    assert pkg.findtext("name") == urdf.PACKAGE == "ucat_description"
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert pkg.findtext("license") == project["license"]
    assert pkg.findtext("version") == project["version"]
    maintainer = pkg.find("maintainer")
    assert maintainer is not None and maintainer.get("email")
    assert f"Copyright (c) 2026 {maintainer.text}" in (ROOT / "LICENSE").read_text()
    cmake = (urdf.PACKAGE_DIR / "CMakeLists.txt").read_text()
    assert "project(ucat_description)" in cmake and "install(DIRECTORY urdf meshes" in cmake
    meshes = [m.get("filename") for m in ET.parse(urdf.URDF_PATH).getroot().iter("mesh")]
    assert meshes and all(m == urdf.MESH_URI for m in meshes)
    assert urdf.MESH_URI.startswith("package://ucat_description/meshes/")
    assert Path(_ros_package_path(urdf.MESH_URI)) == urdf.MESH_PATH


def test_check_urdf_takes_the_urdf():
    tool = shutil.which("check_urdf")
    if tool is None:
        pytest.skip("check_urdf (liburdfdom-tools) is not installed")
    out = subprocess.run([tool, str(urdf.URDF_PATH)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "root Link: base_link" in out.stdout


def test_the_robots_pose_in_the_world_is_the_telemetrys(sessions):
    """map -> odom -> base_link -> base_link_frd (the files' transforms) is the telemetry's pose
    in odom_ned: the FLU base_link carries the same robot."""
    position = (1.5, -2.0, 3.0)
    q = np.array([0.3, -0.5, 0.2, 0.7])
    q /= np.linalg.norm(q)
    state = BodyState(1.0, position, tuple(q), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 3.0)
    [path] = record(sessions, [(C.BODY_STATE, state)])
    with open(path, "rb") as fh:
        tfs = {json.loads(m.data)["child_frame_id"]: json.loads(m.data)
               for _, ch, m in make_reader(fh).iter_messages() if ch.topic.startswith("foxglove/tf/")}

    def chain(frame: str) -> np.ndarray:
        tf = tfs[frame]
        own = _matrix([tf["translation"][k] for k in "xyz"], [tf["rotation"][k] for k in "wxyz"])
        return own if tf["parent_frame_id"] == foxglove.MAP_FRAME else chain(tf["parent_frame_id"]) @ own

    assert tfs["base_link"]["parent_frame_id"] == foxglove.ODOM_FRAME
    np.testing.assert_allclose(chain(foxglove.BODY_FRAME),
                               chain(foxglove.ODOM_NED_FRAME) @ _matrix(position, q), atol=1e-12)
