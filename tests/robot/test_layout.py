"""Declared row layouts: the columns follow from the fields, each table has one, and the
compiled code's column constants and the Python side's reads are the same columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ucat_console.control import body, loop_core, mpc_kernels, pid, power, stroke_watch
from ucat_console.robot import reading_rows as rr
from ucat_console.robot.layout import Layout


def test_columns_follow_from_the_fields_in_order() -> None:
    lay = Layout("a row", [("t", 1, "time"), ("q", 4, "attitude"), ("depth", 1, "depth")])
    assert (lay.at("t"), lay.at("q"), lay.at("depth"), lay.size) == (0, 1, 5, 6)
    assert lay.span("q") == slice(1, 5) and lay.width("q") == 4
    row = [0.5, 1.0, 0.0, 0.0, 0.0, 2.0]
    assert lay.get(row, "q") == (1.0, 0.0, 0.0, 0.0) and lay.get(row, "depth") == 2.0
    assert "1-4  q: attitude" in lay.describe()
    with pytest.raises(KeyError, match="no field 'x'"):
        lay.at("x")
    with pytest.raises(ValueError, match="declared twice"):
        Layout("bad", [("t", 1, ""), ("t", 1, "")])
    with pytest.raises(ValueError, match="width 0"):
        Layout("bad", [("t", 0, "")])


LAYOUTS = [loop_core.STATE, loop_core.BODY_COMMAND_ROW, loop_core.STATE_ROW, loop_core.POWER_ROW,
           mpc_kernels.PARAMS, mpc_kernels.PROBLEM, mpc_kernels.TERMS, mpc_kernels.RUN_ROW, body.BODY,
           pid.PID_ROW, power.POWER_ROW, stroke_watch.WATCH_ROW, *rr.LAYOUTS]


@pytest.mark.parametrize("lay", LAYOUTS, ids=lambda lay: lay.name)
def test_each_table_tiles_its_row(lay: Layout) -> None:
    cols: list[int] = []
    for f in lay.fields:
        cols += list(range(lay.span(f).start, lay.span(f).stop))
        assert lay.doc[f]
    assert cols == list(range(lay.size))


def test_the_arrays_are_as_wide_as_their_layouts() -> None:
    assert loop_core.NC == loop_core.STATE.size
    assert mpc_kernels.N_PARAMS == mpc_kernels.PARAMS.size == len(
        mpc_kernels.pack_params(mpc_kernels.MpcConfig(), None))
    assert mpc_kernels.N_PROBLEM == len(mpc_kernels.pack_problem((1.0, 2.0), 0.3, 0.1, (0.5, -0.5, 2.0, 2.0)))
    assert power.NP == power.POWER_ROW.size and pid.NPID == pid.PID_ROW.size
    assert stroke_watch.NW == stroke_watch.WATCH_ROW.size and mpc_kernels.RUN == mpc_kernels.RUN_ROW.size
    assert all(lay.size <= loop_core.OUT_ROW for lay in (loop_core.STATE_ROW, loop_core.POWER_ROW,
                                                         loop_core.BODY_COMMAND_ROW))


def test_the_kernels_constants_are_the_layouts_columns() -> None:
    k = mpc_kernels
    p = k.pack_params(k.MpcConfig(), None, (300.0, 20.0))
    assert p[k.PARAMS.at("acc")] == p[k.P_ACC] == 300.0 and p[k.P_VMAX] == 20.0
    q = k.pack_problem((1.0, 2.0), 0.3, 0.0, (0.5, -0.5, 2.0, 4.0))
    assert q[k.PROBLEM.span("u_prev")] == (0.5, -0.5, 2.0, 4.0) == q[k.Q_PREV:k.Q_PREV + 4]
    assert q[k.PROBLEM.at("c0")] == math.cos(0.0)
    row = np.full(rr.ROW, np.nan)
    from ucat_console.robot.readings import DvlVelocity

    rr.to_row(DvlVelocity(1.5, 0.1, 0.2, 0.3, True, 2.0, 0.01), row)
    assert rr.DVL_ROW.get(row, "v") == (0.1, 0.2, 0.3) and rr.DVL_ROW.get(row, "altitude") == 2.0
    assert row[rr.KIND] == rr.DVL and rr.DVL_ROW.get(row, "t") == 1.5


def test_the_mpc_entry_points_are_made_from_their_flags() -> None:
    k = mpc_kernels
    assert set(k.KERNELS) == {(f, m) for f in k.FORMULATIONS for m in k.FORCE_MODELS}
    for (formulation, model), entries in k.KERNELS.items():
        assert [e.__name__ for e in entries] == ["plan_kernel", "sample_kernel", "finish_kernel", "cost_kernel"]
        for e in entries:
            flags = dict(zip(e.py_func.__code__.co_freevars, (c.cell_contents for c in e.py_func.__closure__)))
            assert flags == {"table": model == "table", "closed": formulation == "closed_stroke"}
