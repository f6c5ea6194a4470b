"""``ucat_console.sessions.open``: a recording made here, read back as arrays with units."""

from __future__ import annotations

import numpy as np
import pytest

import ucat_console.sessions
from ucat_console.backend.loop.closed_loop import ClosedLoop
from ucat_console.backend.loop.config import LoopConfig
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.backend.sim_robot_io import SimRobotIO
from ucat_console.control.allocation import BodySetpoints
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.stream import TelemetryStream

OFFSET = 1_700_000_000.0


def _run(sessions, seconds: float, config: RecorderConfig | None = None):
    """A closed-loop run recorded, and every message the stream carried, by channel."""
    stream = TelemetryStream()
    seen: dict[str, list] = {}
    stream.subscribe(lambda c, m: seen.setdefault(c, []).append(m))
    rec = Recorder(stream, config, directory=sessions, epoch_offset=OFFSET)
    loop = ClosedLoop(LoopConfig(mode="baseline"), SimRobotIO(depth=1.0, velocity=0.1), stream,
                      setpoints=BodySetpoints(velocity=0.2, depth=1.2))
    rec.start()
    loop.run_until(seconds)
    paths = rec.stop()
    return paths, seen


def test_each_channel_comes_back_as_arrays_with_units(sessions):
    [path], seen = _run(sessions, 2.0)
    with ucat_console.sessions.open(path) as rec:
        assert {C.BODY_STATE, C.fin_plan(0), C.POWER, C.STATUS} <= set(rec.channels)
        assert all(seen.get(c) for c in rec.channels)
        body = rec[C.BODY_STATE]
        want = seen[C.BODY_STATE]
        assert len(body) == len(want)
        np.testing.assert_array_equal(body.t, [m.t for m in want])
        np.testing.assert_array_equal(body.log_time_ns, [round((m.t + OFFSET) * 1e9) for m in want])
        np.testing.assert_array_equal(body["velocity.x"], [m.velocity[0] for m in want])
        np.testing.assert_array_equal(body["orientation.w"], [m.orientation[0] for m in want])
        np.testing.assert_array_equal(body["orientation.z"], [m.orientation[3] for m in want])
        assert body["position.z"].dtype == np.float64
        assert (body.units["velocity.x"], body.units["position.z"], body.units["t"],
                body.units["log_time_ns"]) == ("m/s", "m", "s", "ns")
        assert "NED" in body.descriptions["position.x"]
        with pytest.raises(ValueError):
            body["depth"][0] = 1.0  # read-only
        plan = rec[C.fin_plan(0)]
        assert plan.units["u.d_1"] == "rad" and plan.units["u.w_1"] == "rad/s"
        assert list(plan["seed"]) == [m.seed for m in seen[C.fin_plan(0)]]
        assert list(plan["mode"]) == [m.mode for m in seen[C.fin_plan(0)]]
        power = rec[C.POWER]
        np.testing.assert_array_equal(power["per_fin[2]"], [m.per_fin[2] for m in seen[C.POWER]])
        status = rec[C.STATUS]
        assert status["armed"].dtype == bool
        assert list(status["failsafes"]) == [list(m.failsafes) for m in seen[C.STATUS]]
        with pytest.raises(KeyError, match="no column"):
            body["speed"]
        with pytest.raises(KeyError, match="not a telemetry channel"):
            rec["foxglove/scene"]
        assert len(rec[C.DVL]) == len(seen.get(C.DVL, []))
    pint = pytest.importorskip("pint")
    ureg = pint.UnitRegistry()
    for unit in body.units.values():
        if unit:
            ureg.parse_units(unit)


def test_a_split_session_is_read_whole_from_any_part(sessions):
    paths, seen = _run(sessions, 2.5, RecorderConfig(split_duration=1.0))
    assert len(paths) >= 2
    with ucat_console.sessions.open(paths[-1]) as rec:
        assert rec.paths == tuple(paths)
        body = rec[C.BODY_STATE]
        assert len(body) == len(seen[C.BODY_STATE])
        assert np.all(np.diff(body.log_time_ns) >= 0)
        assert rec.metadata["session"]["id"] == rec.session_id


def test_pandas_frame_with_units_or_a_clear_error(sessions):
    [path], seen = _run(sessions, 0.5)
    with ucat_console.sessions.open(path) as rec:
        body = rec[C.BODY_STATE]
        try:
            import pandas  # noqa: F401
        except ImportError:
            with pytest.raises(ImportError, match="pandas"):
                body.to_pandas()
            return
        df = body.to_pandas()
        assert list(df.columns) == list(body.columns)
        assert df.attrs["units"]["velocity.x"] == "m/s"
        assert df["depth"].tolist() == pytest.approx([m.depth for m in seen[C.BODY_STATE]], nan_ok=True)


def test_what_is_not_a_session_file_is_refused(tmp_path):
    with pytest.raises(ValueError, match="no such session file"):
        ucat_console.sessions.open(tmp_path / "missing.mcap")
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not mcap")
    with pytest.raises(ValueError, match="not an MCAP file"):
        ucat_console.sessions.open(bad)
