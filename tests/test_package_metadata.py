"""The package as a package index and a distribution packager see it: the project's metadata
(URLs, classifiers, the team named as in the ROS package), a README whose links work on an
index (absolute, under the repository, each naming a file that exists), the third-party
notices; and the built wheel (marked ``slow``): its metadata, the notices and the bundled
schemas inside, and no compiled cache of numba's."""

from __future__ import annotations

import email
import re
import shutil
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
SOURCE = PROJECT["urls"]["Source"].rstrip("/")
NOTICES = "THIRD_PARTY_NOTICES.md"
SCHEMAS = ROOT / "ucat_console" / "backend" / "sessions" / "foxglove_schemas"
LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_the_project_names_its_addresses_team_and_classifiers() -> None:
    assert set(PROJECT["urls"]) >= {"Homepage", "Documentation", "Source", "Issues"}
    assert all(u.startswith(SOURCE) for u in PROJECT["urls"].values())
    assert any(c.startswith("Development Status ::") for c in PROJECT["classifiers"])
    assert "Programming Language :: Python :: 3.11" in PROJECT["classifiers"]
    assert PROJECT["keywords"]
    # one team name: the distribution's, the ROS package's maintainer, the licence's holder
    pkg = ET.parse(ROOT / "ucat_console" / "robot" / "ucat_description" / "package.xml").getroot()
    team = pkg.findtext("maintainer")
    assert [a["name"] for a in PROJECT["authors"]] == [m["name"] for m in PROJECT["maintainers"]] == [team]
    assert f"Copyright (c) 2026 {team}" in (ROOT / "LICENSE").read_text()


def test_every_readme_link_is_absolute_and_names_a_file_of_the_repository() -> None:
    links = LINK.findall((ROOT / "README.md").read_text())
    assert links
    for link in links:
        if link.startswith("#"):
            continue
        assert link.startswith(("https://", "http://")), f"README: {link} is relative (breaks on a package index)"
        m = re.match(re.escape(SOURCE) + r"/(?:blob|raw|tree)/main/(.+)$", link)
        if m:
            assert (ROOT / m.group(1)).exists(), f"README: {link} names no file of the repository"


def test_the_notices_cover_the_bundled_schemas_and_ship_as_licence_files() -> None:
    assert PROJECT["license-files"] == ["LICENSE", NOTICES]
    text = (ROOT / NOTICES).read_text()
    for schema in SCHEMAS.glob("*.json"):
        assert schema.name in text, f"{NOTICES}: {schema.name} is bundled but not listed"
    assert "Copyright (c) Foxglove Technologies Inc" in text and "MIT License" in text
    assert "Apache License" in text and "ucat_console/ui/page_client.py" in text


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_wheel_carries_metadata_notices_and_schemas_and_no_compiled_cache(tmp_path: Path) -> None:
    src = tmp_path / "src"  # a copy: building writes into the source tree
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE", NOTICES):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "ucat_console", src / "ucat_console", ignore=shutil.ignore_patterns("__pycache__"))
    # numba's cache files where an older version, or a user's NUMBA_CACHE_DIR, could leave them
    for d in (src / "ucat_console" / "control" / "__pycache__", src / "ucat_console" / "__pycache__" / "ucat-numba-x"):
        d.mkdir(parents=True)
        (d / "k.core-1.py311.nbi").write_bytes(b"index")
        (d / "k.core-1.py311.1.nbc").write_bytes(b"code")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path / "dist"), str(src)],
                   check=True, timeout=600)
    (wheel,) = (tmp_path / "dist").glob("ucat_console-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        (meta_name,) = [n for n in names if n.endswith(".dist-info/METADATA")]
        meta = email.message_from_bytes(z.read(meta_name))
        (notice_name,) = [n for n in names if n.endswith(f".dist-info/licenses/{NOTICES}")]
        notice = z.read(notice_name).decode()
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert "Copyright (c) Foxglove Technologies Inc" in notice
    assert {f"ucat_console/backend/sessions/foxglove_schemas/{s.name}" for s in SCHEMAS.glob("*.json")} <= names
    assert not [n for n in names if n.endswith((".nbi", ".nbc")) or "ucat-numba-" in n]
    assert "ucat_console/__main__.py" in names

    assert meta["Version"] == PROJECT["version"]
    assert meta["Description-Content-Type"] == "text/markdown"
    urls = dict(u.split(", ", 1) for u in meta.get_all("Project-URL"))
    assert urls == PROJECT["urls"]
    assert set(meta.get_all("Classifier")) == set(PROJECT["classifiers"])
    assert meta["Author"] == PROJECT["authors"][0]["name"] and meta["License-Expression"] == "MIT"
    assert set(meta.get_all("License-File")) == {"LICENSE", NOTICES}
    assert any(r.startswith("argcomplete") for r in meta.get_all("Requires-Dist"))
    # the long description is the README, its links absolute (they work on the index's page)
    description = meta.get_payload()
    assert description.startswith("# ucat-console")
    assert all(link.startswith(("https://", "http://", "#")) for link in LINK.findall(description))
