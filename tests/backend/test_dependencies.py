"""The start-up check of the libraries' installed versions against the supported ranges."""

from __future__ import annotations

from importlib import metadata

import pytest

from ucat_console.backend import dependencies
from ucat_console.backend.dependencies import SUPPORTED, UnsupportedVersion, require, supported


def test_the_ranges_hold_the_installed_versions() -> None:
    for package in SUPPORTED:
        assert supported(package, metadata.version(package)), package
        assert require(package) == metadata.version(package)


@pytest.mark.parametrize("version, ok", [
    ("1.1.1", True), ("1.1.9", True), ("1.1.1.post1", True), ("1.1.0", False), ("1.0.21", False),
    ("1.2", False), ("1.2.0", False), ("1.2.0rc1", False), ("2.0.0", False),
])
def test_viser_s_range(version: str, ok: bool) -> None:
    assert supported("viser", version) is ok


def _installed(monkeypatch, versions: dict[str, str]) -> None:
    real = metadata.version
    monkeypatch.setattr(dependencies.metadata, "version", lambda p: versions.get(p) or real(p))


def test_an_unsupported_version_is_a_clear_error_naming_package_and_versions(monkeypatch) -> None:
    _installed(monkeypatch, {"viser": "1.0.21", "mcap": "1.7.2"})
    with pytest.raises(UnsupportedVersion, match=r"viser 1\.0\.21 is installed; the console supports "
                                                 r"viser>=1\.1\.1,<1\.2"):
        require("viser")
    with pytest.raises(UnsupportedVersion, match=r"mcap 1\.7\.2 is installed; .*mcap>=1\.6\.0,<1\.7"):
        require("mcap")


def test_a_missing_package_is_named(monkeypatch) -> None:
    def missing(p: str) -> str:
        raise metadata.PackageNotFoundError(p)
    monkeypatch.setattr(dependencies.metadata, "version", missing)
    with pytest.raises(UnsupportedVersion, match="mcap is not installed"):
        require("mcap")


def test_the_page_server_and_the_recorder_check_at_start(monkeypatch, tmp_path) -> None:
    from ucat_console.backend.sessions.recorder import Recorder
    from ucat_console.telemetry.stream import TelemetryStream
    from ucat_console.ui import viser_compat

    _installed(monkeypatch, {"viser": "1.2.0", "mcap": "1.5.0"})
    monkeypatch.setattr(viser_compat, "_INSTALLED", False)
    with pytest.raises(UnsupportedVersion, match="viser 1.2.0"):
        viser_compat.install()
    with pytest.raises(UnsupportedVersion, match="mcap 1.5.0"):
        Recorder(TelemetryStream(), directory=tmp_path)


def test_the_command_line_reports_it_as_an_error(monkeypatch, capsys) -> None:
    from ucat_console import cli

    def unsupported(args) -> int:
        require("viser")
        return 0
    _installed(monkeypatch, {"viser": "1.0.21"})
    monkeypatch.setattr(cli.argparse.ArgumentParser, "parse_args",
                        lambda self, argv=None: cli.argparse.Namespace(func=unsupported, verbose=False))
    assert cli.main([]) == 2
    assert "viser 1.0.21 is installed" in capsys.readouterr().err
