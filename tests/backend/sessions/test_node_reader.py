"""Session files read by an independent reader on the libraries Foxglove and Lichtblick use
(tests/node_reader: @mcap/core, @mcap/nodejs, @mcap/support, ajv, @foxglove/schemas, from
the npm registry, versions locked by its package-lock.json)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from mcap.writer import Writer
from session_helpers import BIG_SEED, FIXTURES, awkward_items, record, same

from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.backend.sessions import codec, foxglove, images
from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.backend.sessions.schema import json_schema_bytes
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import CameraImage
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream

pytestmark = pytest.mark.slow
READER = Path(__file__).resolve().parents[2] / "node_reader"
FOXGLOVE_TOPICS = set(foxglove.DERIVED_TOPICS)
FRAMES = {"map", "odom", "odom_ned", "base_link_frd", "base_link", "fin0", "fin1", "fin2", "fin3"}


@pytest.fixture(scope="module")
def node() -> str:
    """The node binary, with the reader's packages installed (npm ci, from the lock file)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.fail("node and npm are needed for the independent reader (Debian: nodejs npm)")
    lock = READER / "package-lock.json"
    stamp = READER / "node_modules" / ".package-lock.json"
    if not stamp.is_file() or stamp.stat().st_mtime < lock.stat().st_mtime:
        subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=READER, check=True,
                       timeout=600, capture_output=True)
    return node


def read(node: str, path: Path, *dump: str) -> tuple[int, dict, str]:
    proc = subprocess.run([node, str(READER / "read_session.mjs"), str(path), "--dump", *dump],
                          capture_output=True, text=True, timeout=120)
    return proc.returncode, json.loads(proc.stdout), proc.stderr


def test_every_message_validates_and_the_awkward_values_come_through(node, sessions):
    items = awkward_items()
    [path] = record(sessions, items)
    code, out, err = read(node, path, *C.CHANNELS)
    assert code == 0, err
    assert out["problems"] == []
    assert out["channels"] == len(C.CHANNELS) + len(FOXGLOVE_TOPICS)
    assert out["root"] == "map"
    assert set(out["frames"]) == FRAMES
    assert out["entity_frames"] == ["base_link_frd", "fin0", "fin1", "fin2", "fin3"]
    # what JavaScript parsed, decoded here: the same messages (infinities, the seed beyond
    # 2^53, the empty pilot and failsafe list, the missing orientation)
    got = [(d["topic"], images.decode(CameraImage, json.dumps(d["message"]).encode())
            if d["topic"] == C.CAMERA_IMAGE else codec.from_json_obj(C.CHANNELS[d["topic"]], d["message"]))
           for d in out["dumped"]]
    want = sorted(items, key=lambda item: item[1].t)
    assert len(got) == len(want)
    for (ch, msg), (ch2, msg2) in zip(want, got):
        assert ch == ch2 and same(msg, msg2), ch
    plans = [d["message"] for d in out["dumped"] if d["topic"] == C.fin_plan(1)]
    assert plans[-1]["seed"] == str(BIG_SEED)


def test_a_closed_loop_recording_is_one_transform_tree(node, sessions):
    stream = TelemetryStream()
    rec = Recorder(stream, directory=sessions, epoch_offset=1_700_000_000.0)
    loop = ClosedLoop(LoopConfig(mode="baseline"), SimRobotIO(depth=1.0, velocity=0.1), stream,
                      setpoints=BodySetpoints(velocity=0.1, depth=1.0))
    rec.start()
    loop.run_until(3.0)
    [path] = rec.stop()
    code, out, err = read(node, path)
    assert code == 0, err
    counts = out["counts"]
    assert counts["foxglove/tf/base_link"] == counts[C.BODY_STATE]
    assert all(counts[f"foxglove/tf/fin{i}"] == counts[C.fin_state(i)] for i in range(4))
    assert all(counts[C.fin_strouhal(i)] > 0 for i in range(4))
    assert counts["foxglove/scene"] == counts["foxglove/tf/odom"] == counts["foxglove/tf/base_link_frd"] == 1
    assert out["root"] == "map" and set(out["frames"]) == FRAMES
    # every channel in log-time order, as the reader met the messages in the file
    assert out["out_of_order"] == []


def test_a_message_its_schema_refuses_fails_the_reader(node, sessions):
    path = sessions / "bad.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ucat_console")
        sid = w.register_schema("ucat_console.Setpoints", "jsonschema", json_schema_bytes(Setpoints))
        cid = w.register_channel(C.SETPOINTS, "json", sid)
        w.add_message(cid, log_time=1, publish_time=1,
                      data=codec.encode(Setpoints(0.0, 0.1, 1.0, 0.0)))
        w.add_message(cid, log_time=2, publish_time=2, data=b'{"t":1.0,"velocity":"fast"}')
        w.finish()
    code, out, err = read(node, path)
    assert code == 1
    assert "body/setpoints at 2 ns" in err and "velocity" in err


def test_a_file_of_encoding_1_fails_where_the_tools_did(node, sessions):
    """What the apps refused in files written before encoding 2: 1e999, seeds past 2^53."""
    src = FIXTURES / "20231114-221320-legacy-v1_001.mcap"
    code, out, err = read(node, src)
    assert code == 1
    assert "integer beyond 2^53 at .seed" in err
    assert "data/yaw must be number" in err  # BodyCommand.yaw = -inf, written -1e999
