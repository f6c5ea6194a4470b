"""``ucat-console devices probe epos --emulate``: an emulated EPOS2 on the virtual bus, probed."""

from __future__ import annotations

import json
import uuid

import ucat_console.cli as cli


def test_probe_epos_emulated_node_reaches_operation_enabled(monkeypatch, tmp_path) -> None:
    monkeypatch.setattr(cli, "COMMANDS", ["devices"])
    out = tmp_path / "epos.jsonl"
    channel = f"probe-emu-{uuid.uuid4().hex[:8]}"
    # --interface socketcan is overridden: the emulated node lives on the in-process bus
    status = cli.main(["devices", "probe", "epos", "--emulate", "--interface", "socketcan",
                       "--channel", channel, "--node", "7", "--duration", "0.3",
                       "--json", str(out), "--quiet"])
    assert status == 0
    records = [json.loads(line) for line in out.read_text().splitlines()]
    feedback = [r for r in records if r["kind"] == "feedback"]
    assert feedback, records
    # the node streams in operation enabled (the probe disables it at the end, and a
    # feedback of that may come last)
    enabled = [r for r in feedback if r["state"] == "operation_enabled"]
    assert enabled, feedback
    # the emulated node holds position 0 while nothing commands it
    assert all(r["position_rad"] == 0.0 for r in feedback)
    assert not [r for r in records if r["kind"] == "fault"]
