"""Fin model (eqs 1-8) and the force table."""

import math

import numpy as np
import pytest

from ucat_console.control import MpcConfig
from ucat_console.control.fin_model import (
    ForceTable,
    dynamic_pressure_gain,
    fin_frame_force,
    rotate,
    stroke_force_body,
)

CFG = MpcConfig()


def test_fin_frame_force_hand_computed():
    # d = 0.6 rad, w = 2 rad/s: v = r_c w = 0.2 m/s (eq 2)
    # D = 0.5 * 1000 * 0.70 * 0.020 * 0.04 = 0.28 N ; L = 0.5 * 1000 * 0.25 * 0.020 * 0.04 = 0.10 N
    # thr = 0.3: cos 0.3 = 0.955336489, sin 0.3 = 0.295520207
    fxl, fyl = fin_frame_force(0.6, 2.0, CFG)
    assert fxl == pytest.approx(-0.10 * 0.955336489 - 0.28 * 0.295520207, abs=1e-9)
    assert fyl == pytest.approx(-0.10 * 0.295520207 - 0.28 * 0.955336489, abs=1e-9)
    assert fxl == pytest.approx(-0.1782793, abs=1e-6)
    assert fyl == pytest.approx(-0.2970462, abs=1e-6)


def test_force_grows_with_square_of_rate_and_ignores_rate_sign():
    f1 = np.array(fin_frame_force(0.4, 1.5, CFG))
    f2 = np.array(fin_frame_force(0.4, 3.0, CFG))
    np.testing.assert_allclose(f2, 4.0 * f1, rtol=1e-12)
    np.testing.assert_allclose(fin_frame_force(0.4, -3.0, CFG), f2, rtol=1e-12)


def test_body_force_rotates_by_mid_stroke_angle():
    # theta = 0.2, d = 0.6: mid-stroke angle 0.5 (eq 6)
    fxl, fyl = fin_frame_force(0.6, 2.0, CFG)
    fx, fy = stroke_force_body(0.2, 0.6, 2.0, CFG)
    c, s = math.cos(0.5), math.sin(0.5)
    assert fx == pytest.approx(c * fxl - s * fyl, abs=1e-12)
    assert fy == pytest.approx(s * fxl + c * fyl, abs=1e-12)
    # a rotation keeps the magnitude
    assert math.hypot(fx, fy) == pytest.approx(math.hypot(fxl, fyl), rel=1e-12)


def test_stroke_frame_closed_form():
    # g = R(d/2) f^l = -q w^2 (C_L cos d, C_L sin d + C_D) (derived in fin_model)
    q = dynamic_pressure_gain(CFG)
    assert q == pytest.approx(0.5 * 1000 * 0.020 * 0.01)
    for d, w in [(0.6, 2.0), (-1.1, 7.5), (0.05, 0.5)]:
        gx, gy = rotate(d / 2, *fin_frame_force(d, w, CFG))
        assert gx == pytest.approx(-q * w * w * CFG.c_l * math.cos(d), abs=1e-12)
        assert gy == pytest.approx(-q * w * w * (CFG.c_l * math.sin(d) + CFG.c_d), abs=1e-12)


def test_table_matches_analytic_model_below_one_millinewton():
    table = ForceTable.from_model(CFG)
    rng = np.random.default_rng(3)
    d = rng.uniform(-CFG.d_max, CFG.d_max, 20_000)
    w = rng.uniform(CFG.w_min, CFG.w_max, 20_000)
    fx_t, fy_t = table.interpolate(d, w)
    fx_a, fy_a = fin_frame_force(d, w, CFG)
    err = np.maximum(np.abs(fx_t - fx_a), np.abs(fy_t - fy_a))
    assert err.max() < 1e-3
    # the stroke-frame table the solver reads is equally close to the closed form
    gx_tab, gy_tab = table.stroke_frame()
    from ucat_console.control.fin_model import bilinear

    gx, gy = bilinear(table.d, table.w, gx_tab, gy_tab, d, w)
    q = dynamic_pressure_gain(CFG)
    assert np.abs(gx + q * w**2 * CFG.c_l * np.cos(d)).max() < 1e-3
    assert np.abs(gy + q * w**2 * (CFG.c_l * np.sin(d) + CFG.c_d)).max() < 1e-3


def test_table_exact_at_nodes():
    table = ForceTable.from_model(CFG)
    fx, fy = table.interpolate(table.d[7], table.w[5])
    ax, ay = fin_frame_force(table.d[7], table.w[5], CFG)
    assert fx == pytest.approx(ax, abs=1e-14)
    assert fy == pytest.approx(ay, abs=1e-14)


def test_table_file_round_trip(tmp_path):
    table = ForceTable.from_model(CFG.replace(table_n_d=31, table_n_w=17))
    path = tmp_path / "fins.npz"
    table.save(path)
    loaded = ForceTable.load(path)
    np.testing.assert_array_equal(loaded.fx, table.fx)
    np.testing.assert_array_equal(loaded.w, table.w)


def test_bad_table_files_are_refused(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        ForceTable.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "partial.npz", d=np.linspace(-1, 1, 3), w=np.linspace(1, 2, 3))
    with pytest.raises(ValueError, match="lacks array"):
        ForceTable.load(tmp_path / "partial.npz")
    d = np.array([-1.0, 0.0, 2.0])  # not uniform
    w = np.linspace(1, 2, 3)
    np.savez(tmp_path / "uneven.npz", d=d, w=w, fx=np.zeros((3, 3)), fy=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="uniform"):
        ForceTable.load(tmp_path / "uneven.npz")
    np.savez(tmp_path / "shape.npz", d=w, w=w, fx=np.zeros((3, 2)), fy=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="fx: shape"):
        ForceTable.load(tmp_path / "shape.npz")
    nan = np.zeros((3, 3))
    nan[1, 1] = np.nan
    np.savez(tmp_path / "nan.npz", d=w, w=w, fx=nan, fy=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        ForceTable.load(tmp_path / "nan.npz")
    (tmp_path / "text.npz").write_text("not a table")
    with pytest.raises(ValueError, match="not a readable"):
        ForceTable.load(tmp_path / "text.npz")
