"""The shipped Foxglove / Lichtblick layout (ucat_console/foxglove-layout.json) shows what a session
file holds: every panel it arranges is configured, every plotted path resolves in its
channel's schema, and the 3-D view follows a frame the transforms place."""

from __future__ import annotations

import json
import re

from ucat_console import shipped
from ucat_console.backend.sessions import foxglove
from ucat_console.backend.sessions.schema import json_schema
from ucat_console.robot import urdf
from ucat_console.telemetry import channels as C

LAYOUT = shipped.foxglove_layout()


def _panels(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _panels(node["first"]) + _panels(node["second"])


def _resolve(path: str) -> dict:
    """The schema of a message path ``topic.field[.sub][i]`` (AssertionError if it is none)."""
    topic, _, rest = path.partition(".")
    assert topic in C.CHANNELS, f"{path}: no channel {topic!r}"
    schema = json_schema(C.CHANNELS[topic])
    for name, index in re.findall(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?", rest):
        assert schema.get("type") == "object" and name in schema["properties"], path
        schema = schema["properties"][name]
        if index:
            assert schema["type"] == "array" and int(index) < schema["maxItems"], path
            schema = schema["prefixItems"][int(index)]
    return schema


def test_every_panel_of_the_layout_is_configured_and_reads_existing_data():
    layout = json.loads(LAYOUT.read_text())
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"])
    kinds = {p.split("!")[0] for p in panels}
    assert {"3D", "Plot", "RosOut"} <= kinds
    plotted = []
    for pid, cfg in layout["configById"].items():
        if pid.startswith("Plot!"):
            for series in cfg["paths"]:
                schema = _resolve(series["value"])
                assert "number" in schema["type"], series["value"]
                plotted.append(series["value"])
        elif pid.startswith("3D!"):
            assert cfg["followTf"] == foxglove.BASE_LINK_FRAME
            assert set(cfg["topics"]) <= set(foxglove.DERIVED_TOPICS)
            assert cfg["layers"]["surface"]["frameId"] == foxglove.MAP_FRAME
            # the robot's URDF, the shipped file (its links are the transform frames)
            assert cfg["layers"]["urdf"]["layerId"] == "foxglove.Urdf"
            assert urdf.package_file(cfg["layers"]["urdf"]["url"]) == urdf.URDF_PATH
        elif pid.startswith("RosOut!"):
            assert cfg["topicToRender"] == foxglove.LOG_TOPIC
    # what the issue asked to see: St per fin with the corridor, depth, velocity, yaw rate,
    # power
    for i in range(4):
        assert f"fin/{i}/strouhal.st" in plotted
    for path in ("fin/0/strouhal.st_low", "fin/0/strouhal.st_high", "body/state.depth",
                 "body/state.velocity.x", "body/state.rates.z", "power.total",
                 "power/electrical.total"):
        assert path in plotted
