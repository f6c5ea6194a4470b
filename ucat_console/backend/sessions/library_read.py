"""What the run library knows of one session, read from its files: :func:`read_facts`.

A session's facts are read once per change of its files (the library caches them):

* from the parts' summaries (:func:`~.index.part_info`): start, duration, size, whether a
  part is truncated, being recorded or unreadable (then nothing more is read);
* from its metadata records: the configuration (its TOML, the sha256 of that text, the
  robot, the plant variant, the MPC formulation, the configured mode), the recorded notes,
  the operator's name when the recording holds one (``session.operator``), the configuration's
  name when the recording holds one (``config.name``) or when its hash is one the caller
  names (the shipped configurations', :func:`read_facts`'s ``known_configs``);
* from its events and status messages: the modes used (the status's mode while armed, and
  every mode change; without either, the configured mode), markers, failsafes triggered (the
  names), the scripted manoeuvre's name and its measured segments;
* the run's figures (:func:`~ucat_console.backend.review.metrics.table_row`, the one
  definition) over its driven part: from the first to the last ``body/tracking`` sample with
  the fins driven. A run never driven, or without power messages, has no figures and says why.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ucat_console.backend.review.metrics import TABLE_CHANNELS, MetricsConfig, RunData, table_row
from ucat_console.backend.sessions import files, index
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.reader import Record, SessionParts
from ucat_console.backend.sim.params import FinHydroConfig
from ucat_console.backend.sim.variants import PLANT_VARIANTS, cd0_name, family_hydro
from ucat_console.telemetry.channels import EVENTS, STATUS

#: the channels :func:`read_facts` reads (its ``on_record`` sees each of their records)
FACT_CHANNELS: tuple[str, ...] = (*TABLE_CHANNELS, EVENTS, STATUS)

#: the figures the library keeps: (column, key of metrics.FIGURES, with its interval)
FIGURE_COLUMNS: tuple[tuple[str, str, bool], ...] = (
    ("epm", "energy_per_metre", True),
    ("cot", "cost_of_transport", True),
    ("power", "power", False),
    ("speed", "speed", False),
    ("speed_mae", "speed_mae", False),
    ("depth_mae", "depth_mae", False),
    ("heading_mae", "heading_mae", False),
    ("st_mae", "st_mae", False),
    ("st_in", "st_in", False),
)


@dataclass(frozen=True)
class PartStat:
    """One part file as the library keys it: name, size (bytes), modification time (ns)."""

    name: str
    size: int
    mtime_ns: int


@dataclass(frozen=True)
class Facts:
    """One session as its files describe it (module docstring); figures by column of
    :data:`FIGURE_COLUMNS` (``<col>``, ``<col>_lo``, ``<col>_hi``), None where there is none."""

    session_id: str
    status: str  # ok, truncated, recording, unreadable
    error: str = ""  # why not ok ("" when ok)
    start: float | None = None  # UNIX s
    duration: float | None = None  # s
    size: int = 0
    parts: int = 0
    robot: str = ""
    plant: str = ""
    config: str = ""  # the configuration's name ("" when unknown)
    config_hash: str = ""  # sha256 of the recorded configuration's TOML text ("" when none)
    config_toml: str = ""
    formulation: str = ""
    modes: tuple[str, ...] = ()
    manoeuvre: str = ""
    segments: tuple[str, ...] = ()
    operator: str = ""
    notes: str = ""  # the recorded notes
    markers: int = 0
    failsafes: tuple[str, ...] = ()  # the failsafes triggered, by name, each once
    figures: dict[str, float | None] = field(default_factory=dict)
    figures_note: str = ""  # why there are no figures, or their power source
    driven: tuple[float, float] | None = None  # stream s of the driven part


def config_hash(toml_text: str) -> str:
    return hashlib.sha256(toml_text.encode("utf-8")).hexdigest() if toml_text else ""


def plant_name(plant: Mapping[str, Any]) -> str:
    """The variant name of a recorded ``[plant]`` table's fins (backend/sim/variants.py):
    ``plate_cd<C_D0>`` for the plate on the paper's coefficients (the default is
    ``plate_cd0.05``), ``still_water``, ``eeuvsim``, ``scale<G>_<model>``; ``custom`` for
    any other; ValueError when the table is not a plant's."""
    hydro = FinHydroConfig.from_dict(dict(plant.get("hydro", {})))
    if hydro == FinHydroConfig(c_d0=hydro.c_d0):
        return cd0_name(hydro.c_d0)
    for name, h in PLANT_VARIANTS.items():
        if h == hydro:
            return name
    if hydro.coefficients == "custom" and hydro.custom.c_d > 0.0:
        scale = hydro.custom.c_d / FinHydroConfig().resolved().c_d
        name = f"scale{round(scale, 3):g}_{hydro.model}"
        if family_hydro(name) == hydro:
            return name
    return "custom"


def _config_facts(toml_text: str) -> dict[str, Any]:
    """robot, plant, formulation and the configured mode of a recorded configuration
    (ValueError naming what cannot be read)."""
    try:
        cfg = tomllib.loads(toml_text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"its configuration is not TOML ({e})") from None
    loop = cfg.get("loop", {})
    robot = str(cfg.get("robot", ""))
    try:
        plant = plant_name(cfg.get("plant", {})) if robot != "hardware" else ""
    except (ValueError, TypeError) as e:
        plant = f"unreadable ({e})"
    return {"robot": robot, "plant": plant, "formulation": str(loop.get("mpc", {}).get("formulation", "")),
            "mode": str(loop.get("mode", "")), "metrics": cfg.get("metrics", {})}


def driven_window(data: RunData) -> tuple[float, float] | None:
    """(first, last) time of the ``body/tracking`` samples with the fins driven (None: none)."""
    tr = data.tracking.array()
    t = tr[tr[:, 1] != 0.0, 0] if len(data.tracking) else np.empty(0)
    return (float(t[0]), float(t[-1])) if t.size > 1 and t[-1] > t[0] else None


def _figures(data: RunData, metrics: Mapping[str, Any], label: str) -> tuple[dict[str, float | None], str,
                                                                                tuple[float, float] | None]:
    window = driven_window(data)
    if window is None:
        return {}, "no figures: the fins were never driven", None
    cfg = metrics_config(metrics)
    try:
        row = table_row(data, window[0], window[1], cfg, label)
    except ValueError as e:
        return {}, f"no figures: {e}", window
    out: dict[str, float | None] = {}
    for col, key, interval in FIGURE_COLUMNS:
        est = row.figures[key]
        for suffix, v in (("", est.value), *((("_lo", est.lo), ("_hi", est.hi)) if interval else ())):
            out[col + suffix] = float(v) if math.isfinite(v) else None
    return out, f"power: {row.source_label}", window


def metrics_config(metrics: Mapping[str, Any]) -> MetricsConfig:
    """The figures' settings of a recorded configuration's ``[metrics]`` table (the
    defaults when it cannot be read: the figures are still made, on the defaults)."""
    try:
        return MetricsConfig.from_dict(dict(metrics))
    except (ValueError, TypeError):
        return MetricsConfig()


def recorded_metrics(toml_text: str) -> MetricsConfig:
    """The figures' settings a recorded configuration's TOML text names (defaults where none)."""
    try:
        metrics = _config_facts(toml_text)["metrics"] if toml_text else {}
    except ValueError:
        metrics = {}
    return metrics_config(metrics if isinstance(metrics, Mapping) else {})


def read_facts(session_id: str, paths: list[Path], directory: Path, *,
               known_configs: Mapping[str, str] | None = None, budget: MemoryBudget | None = None,
               on_record: Callable[[Record], None] | None = None) -> Facts:
    """The facts of the session ``session_id`` whose part files are ``paths`` (in part order)
    in ``directory`` (module docstring); ``known_configs``: configuration names by the hash
    of their TOML text; ``on_record``: called with each record read (of
    :data:`FACT_CHANNELS`, in time order), so that a caller needing more of the same
    messages (the run report) reads the session once."""
    budget = budget if budget is not None else MemoryBudget()
    infos = [index.part_info(p, directory, budget) for p in paths]
    base = dict(session_id=session_id, start=infos[0].start if infos else None,
                size=sum(i.size for i in infos), parts=len(infos),
                notes=next((i.notes for i in reversed(infos) if i.notes), ""))
    if any(i.recording for i in infos):
        return Facts(status="recording", error="being recorded", **base)
    if any(i.truncated for i in infos):
        return Facts(status="truncated", error="truncated: run `ucat-console sessions repair`", **base)
    bad = [f"{i.path.name}: {i.error}" for i in infos if i.error]
    if bad:
        return Facts(status="unreadable", error="; ".join(bad), **base)
    try:
        with SessionParts(paths[0], directory, budget=budget) as s:
            meta = s.metadata
            toml_text = s.config_toml
            data = RunData()
            events = []
            statuses = []
            for r in s.records(FACT_CHANNELS):
                if on_record is not None:
                    on_record(r)
                if r.channel == EVENTS:
                    events.append(r.message)
                elif r.channel == STATUS:
                    statuses.append(r.message)
                else:
                    data.feed(r.channel, r.message)
            duration, notes = s.duration, s.notes
    except (ValueError, OSError) as e:
        return Facts(status="unreadable", error=str(e), **base)
    base["notes"] = notes
    error = ""
    cfg: dict[str, Any] = {"robot": "", "plant": "", "formulation": "", "mode": "", "metrics": {}}
    if toml_text:
        try:
            cfg = _config_facts(toml_text)
        except ValueError as e:
            error = str(e)
    digest = config_hash(toml_text)
    name = meta.get(files.META_CONFIG, {}).get("name", "") or (known_configs or {}).get(digest, "")
    modes = list(dict.fromkeys([m.mode for m in statuses if m.armed]
                               + [str(e.data.get("to", "")) for e in events if e.code == "mode"]))
    modes = [m for m in modes if m] or ([cfg["mode"]] if cfg["mode"] else [])
    manoeuvre = next((str(e.data.get("manoeuvre", "")) for e in events if e.source == "manoeuvre"), "")
    segments = tuple(str(e.data.get("label", "")) for e in events
                     if e.source == "manoeuvre" and e.code == "segment")
    failsafes = tuple(dict.fromkeys(e.code for e in events if e.source == "failsafe" and e.code != "cleared"))
    figures, note, window = _figures(data, cfg["metrics"], session_id) if len(data.power) or len(data.tracking) \
        else ({}, "no figures: no power or tracking messages", None)
    return Facts(
        status="ok", error=error, duration=duration, robot=cfg["robot"], plant=cfg["plant"], config=name,
        config_hash=digest, config_toml=toml_text, formulation=cfg["formulation"], modes=tuple(modes),
        manoeuvre=manoeuvre, segments=segments, operator=meta.get(files.META_SESSION, {}).get("operator", ""),
        markers=sum(1 for e in events if e.code == "marker"), failsafes=failsafes, figures=figures,
        figures_note=note, driven=window, **base,
    )
