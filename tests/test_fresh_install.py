"""The wheel, installed in a fresh virtual environment with constraints.txt: it holds the
shipped configurations, the Foxglove layout, the licence and the third-party notices; every
package at its pinned version, consistent (pip check), none of the experiments' libraries
(the ``experiments`` extra); and a headless recorded run from another folder compiles on its
first start, showing its progress, into the user's cache folder (nothing into the package),
and records into the folder the environment names."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from ucat_console.backend.sessions.reader import SessionReader

ROOT = Path(__file__).resolve().parents[1]


def _pins() -> dict[str, set[str]]:
    """Package name -> the versions constraints.txt allows (one per environment marker)."""
    pins: dict[str, set[str]] = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.-]+)==([^ ;]+)", line)
        if m:
            pins.setdefault(_norm(m[1]), set()).add(m[2])
    return pins


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_wheel_installs_in_a_fresh_venv_and_runs_from_another_folder(tmp_path):
    src = tmp_path / "src"  # a copy: building writes into the source tree
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE", "THIRD_PARTY_NOTICES.md", "constraints.txt"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "ucat_console", src / "ucat_console",
                    ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path / "dist"),
                    str(src)], check=True, timeout=600)
    (wheel,) = (tmp_path / "dist").glob("ucat_console-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    shipped = {"ucat_console/configs/robot.toml", "ucat_console/configs/sim-devices.toml",
               "ucat_console/configs/sim-tuned.toml", "ucat_console/configs/ucat-console.schema.json",
               "ucat_console/foxglove-layout.json",
               *(f"ucat_console/manoeuvres/{n}.toml" for n in ("e4_ladder", "fig8_circle", "depth_step", "ab_modes")),
               *(f"ucat_console/robot/ucat_description/{n}" for n in ("package.xml", "CMakeLists.txt",
                                                                       "urdf/ucat.urdf", "meshes/hull.stl")),
               *(f"ucat_console/robot/ucat_msgs/{n}" for n in ("package.xml", "CMakeLists.txt", "msg/FinState.msg",
                                                                "msg/FinStrouhal.msg", "msg/Power.msg",
                                                                "msg/ElectricalPower.msg"))}
    assert shipped <= names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert any(n.endswith(".dist-info/licenses/THIRD_PARTY_NOTICES.md") for n in names)
    assert not any(n.endswith((".mcap", ".nbi", ".nbc")) for n in names)

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    subprocess.run([py, "-m", "pip", "install", "-q", "-c", str(ROOT / "constraints.txt"), str(wheel)],
                   check=True, timeout=840)
    subprocess.run([py, "-m", "pip", "check"], check=True, timeout=60, capture_output=True)
    listed = subprocess.run([py, "-m", "pip", "list", "--format=freeze"], check=True,
                            capture_output=True, text=True, timeout=60).stdout.split()
    installed = {_norm(n): v for n, v in (x.split("==") for x in listed)}
    pins = _pins()
    for name, version in installed.items():
        if name in ("pip", "setuptools", "ucat-console"):  # the venv's own, and the project
            continue
        assert name in pins, f"{name} {version}: installed but not pinned in constraints.txt"
        assert version in pins[name], f"{name}: {version} installed, {pins[name]} pinned"
    assert not {"matplotlib", "dask", "distributed", "foxglove-sdk"} & set(installed)
    site = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    assert (site / "ucat_console" / "configs" / "sim-tuned.toml").is_file()

    # a headless recorded run from a folder of its own: the compiled code is made on this
    # first run (an empty cache: the user's cache folder, here a new one), with its progress
    # shown; the recording goes where the environment says; nothing is written into the package
    elsewhere, data, xdg = tmp_path / "elsewhere", tmp_path / "recordings", tmp_path / "xdg"
    cache = tmp_path / "cache"
    elsewhere.mkdir()
    package_files = {f for f in (site / "ucat_console").rglob("*") if "__pycache__" not in f.parts}
    env = {k: v for k, v in os.environ.items() if not k.startswith(("UCAT_", "NUMBA_", "PYTHON"))}
    env.update(UCAT_CONSOLE_SESSIONS=str(data), XDG_DATA_HOME=str(xdg), XDG_CACHE_HOME=str(cache))
    proc = subprocess.run([venv / "bin" / "ucat-console", "run", "--config", "sim-tuned", "--headless",
                           "--duration", "5", "--record", "--mode", "baseline", "--velocity", "0.2"],
                          cwd=elsewhere, env=env, capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert re.search(r"preparing the paper's MPC and the baseline \(0 of \d done", out), out
    assert out.index("compiled code ready") < out.index("headless run: mode baseline")
    (recorded,) = re.findall(r"recorded (\S+)", out)
    assert Path(recorded).parent == data.resolve()
    with SessionReader(recorded, data) as r:
        assert r.duration >= 5.0 - 0.05
    assert not list(venv.rglob("*.mcap")) and not (site / "sessions").exists()
    assert not list(elsewhere.iterdir()) and not xdg.exists()
    assert list((cache / "ucat-console").glob("ucat-numba-*/**/*.nbi"))
    assert {f for f in (site / "ucat_console").rglob("*") if "__pycache__" not in f.parts} == package_files
    assert not [f for f in (site / "ucat_console").rglob("*") if f.suffix in (".nbi", ".nbc") or f.name.startswith("ucat-numba-")]

    # E4R's second setting is the shipped sim-tuned, found in the installed package
    proc = subprocess.run([py, "-c", "from ucat_console.experiments.closed_loop_runs import e4r_settings; "
                           "print(e4r_settings()['sim_tuned'][0].lam_f)"],
                          cwd=elsewhere, env=env, capture_output=True, text=True, timeout=120)
    with open(ROOT / "ucat_console" / "configs" / "sim-tuned.toml", "rb") as fh:
        lam_f = tomllib.load(fh)["loop"]["mpc"]["lam_f"]
    assert proc.stdout.split() == [repr(float(lam_f))], proc.stderr

    # the experiments say what to install rather than failing on an import
    proc = subprocess.run([venv / "bin" / "ucat-console", "experiment", "E1", "--quick", "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=120,
                          cwd=elsewhere)
    assert proc.returncode == 2
    assert "pip install 'ucat-console[experiments]'" in proc.stderr
