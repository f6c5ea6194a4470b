"""`ucat-console run --playback FILE`: refused with a clear message when it cannot work."""

from ucat_console.cli import main


def test_playback_outside_the_sessions_directory_is_refused(tmp_path, capsys):
    f = tmp_path / "elsewhere.mcap"
    f.write_bytes(b"\x89MCAP0\r\n")
    assert main(["run", "--port", "0", "--playback", str(f), "--duration", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "--playback" in err and "not in the sessions directory" in err


def test_playback_needs_the_web_page(tmp_path, capsys):
    assert main(["run", "--headless", "--playback", str(tmp_path / "x.mcap")]) == 2
    assert "--playback: only with the web page" in capsys.readouterr().err
