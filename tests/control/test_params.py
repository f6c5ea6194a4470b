"""MpcConfig: defaults from the spec, validation naming the field, TOML round trip."""

import math

import pytest

from ucat_console.control import MpcConfig


def test_defaults_are_the_papers_table_one():
    c = MpcConfig()
    assert (c.lam_f, c.lam_st, c.lam_a, c.lam_d) == (1.5, 5.0, 1.0, 1.0)
    assert (c.horizon, c.n_samples, c.max_iter) == (2, 500, 60)
    assert (c.rho, c.fin_area, c.fin_length, c.r_c) == (1000.0, 0.020, 0.10, 0.10)
    assert (c.st_opt, c.c_d, c.c_l) == (0.30, 0.70, 0.25)
    assert (c.eta_max, c.st_low, c.st_high, c.d_max, c.d_eps) == (1.0, 0.25, 0.35, 1.2, 0.05)
    assert (c.w_min, c.w_max, c.a_min, c.v_floor) == (0.5, 8.0, 0.03, 0.05)


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"lam_st": -1.0}, "lam_st"),
        ({"lam_f": math.nan}, "lam_f"),
        ({"n_samples": 0}, "n_samples"),
        ({"w_min": 9.0}, "w_min"),
        ({"d_eps": 1.5}, "d_eps"),
        ({"st_low": 0.4}, "st_low"),
        ({"solver": "cvxpy"}, "solver"),
        ({"force_model": "cfd"}, "force_model"),
        ({"rho": 0.0}, "rho"),
        ({"max_iter": 2.5}, "max_iter"),
    ],
)
def test_bad_values_name_the_field(changes, field):
    with pytest.raises(ValueError, match=field):
        MpcConfig(**changes)


def test_toml_round_trip(tmp_path):
    c = MpcConfig(lam_st=2.0, n_samples=1000, force_model="table", solver="scipy")
    path = tmp_path / "mpc.toml"
    path.write_text(c.to_toml())
    assert MpcConfig.from_toml(path) == c


def test_toml_errors_name_file_and_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("lam_st = -2.0\n")
    with pytest.raises(ValueError, match=r"bad\.toml: lam_st"):
        MpcConfig.from_toml(bad)
    bad.write_text("lam_typo = 2.0\n")
    with pytest.raises(ValueError, match="lam_typo: unknown key"):
        MpcConfig.from_toml(bad)
    bad.write_text('n_samples = "many"\n')
    with pytest.raises(ValueError, match="n_samples: expected an integer"):
        MpcConfig.from_toml(bad)
    bad.write_text("w_min = 9.0\n")
    with pytest.raises(ValueError, match="w_min"):
        MpcConfig.from_toml(bad)
    bad.write_text("this is = not toml [")
    with pytest.raises(ValueError, match="not valid TOML"):
        MpcConfig.from_toml(bad)
    with pytest.raises(ValueError, match="not found"):
        MpcConfig.from_toml(tmp_path / "none.toml")
