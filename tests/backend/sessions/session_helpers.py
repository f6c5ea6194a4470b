"""Helpers of the session tests: example messages, recording, NaN-aware equality."""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Any, Iterable

from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.telemetry.events import LEVELS
from ucat_console.telemetry.stream import TelemetryStream

FIXTURES = Path(__file__).parent / "fixtures"


def _value(tp: Any, name: str, k: int, nan: bool) -> Any:
    """A value of annotated type ``tp`` built from the type alone (no per-class code)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType")):
        inner = [a for a in args if a is not type(None)][0]
        return _value(inner, name, k, nan)
    if tp is float:
        return math.nan if nan and k % 3 == 1 else 0.25 * k + 0.1
    if tp is bool:
        return k % 2 == 0
    if tp is int:
        return k % 4
    if tp is bytes:  # a picture's compressed bytes (every byte value, some each time)
        return bytes((k * 7 + i) % 256 for i in range(300))
    if tp is str and name == "format":
        return "jpeg"
    if tp is str:
        return LEVELS[k % len(LEVELS)] if name == "level" else f"{name}-{k}"
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_value(args[0], name, k + i, nan) for i in range(3))
        return tuple(
            math.nan if nan and i == 1 and a is float else _value(a, name, k + i, False)
            for i, a in enumerate(args)
        )
    if origin is dict:
        return {"k": k, "note": f"{name}-{k}", "list": [1, 2.5, "x"], "nested": {"a": True}}
    raise TypeError(f"no example value for {tp!r}")


def example_message(cls: type, k: int = 1, t: float | None = None, nan: bool = True) -> Any:
    """One message of ``cls`` built from its type hints; ``nan`` puts NaN in some floats
    and in the second element of every float tuple."""
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for i, f in enumerate(dataclasses.fields(cls)):
        kwargs[f.name] = _value(hints[f.name], f.name, k + i, nan)
    if t is not None:
        kwargs["t"] = t
    return cls(**kwargs)


def same(a: Any, b: Any) -> bool:
    """Equality that takes NaN == NaN (dataclasses, tuples, dicts, floats)."""
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        return type(a) is type(b) and all(
            same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
        )
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


def record(
    directory: Path,
    items: Iterable[tuple[str, Any]],
    config: RecorderConfig | None = None,
    epoch_offset: float = 1_700_000_000.0,
    **start: Any,
) -> list[Path]:
    """Record ``(channel, message)`` items through a real stream and recorder."""
    stream = TelemetryStream()
    rec = Recorder(stream, config or RecorderConfig(), directory=directory,
                   epoch_offset=epoch_offset)
    rec.start(**start)
    for channel, msg in items:
        stream.publish(channel, msg)
    paths = rec.stop()
    stats = rec.stats()
    assert stats.dropped == 0 and stats.rejected == 0 and not stats.error
    return paths


BIG_SEED = 17029223188912930816  # > 2^53 and > 2^63: JavaScript and int64 would change it


def awkward_items() -> list[tuple[str, Any]]:
    """Every channel once (example messages, NaN in some floats), plus the values that
    tools lose most easily: infinities, a seed beyond 2^63, an empty pilot name and an empty
    failsafe list, an IMU reading without orientation."""
    import dataclasses

    from ucat_console.robot.readings import ImuReading
    from ucat_console.telemetry import channels as C
    from ucat_console.telemetry.messages import BodyState, FinPlan, FinState, Power, Status

    items = [(ch, example_message(cls, k=i, t=0.5 * i)) for i, (ch, cls) in enumerate(C.CHANNELS.items())]
    t = 0.5 * len(items)
    plan = dataclasses.replace(example_message(FinPlan, k=3, t=t, nan=False), fin=1,
                               seed=BIG_SEED, cost_total=math.inf)
    items += [
        (C.fin_plan(1), plan),
        (C.POWER, Power(t + 0.1, (0.1, math.inf, 0.0, -math.inf), 0.5, 0.4, 2.0, 0.0, math.nan)),
        (C.STATUS, Status(t + 0.2, False, "mpc", "", (), 0, "sim")),
        (C.IMU, ImuReading(t + 0.3, (0.0, 0.0, -1.0), (0.0, math.inf, 0.0))),
        # a finite pose and fin angles, so that every frame of the robot is placed
        (C.BODY_STATE, BodyState(t + 0.4, (1.0, 2.0, 0.5), (0.9, 0.1, -0.2, 0.3), (0.2, 0.0, 0.0),
                                 (0.0, 0.0, 0.1), 0.5)),
        *[(C.fin_state(i), FinState(t + 0.4, i, 0.2 * i - 0.3, 1.0, 0.4, 2.0)) for i in range(4)],
    ]
    return items
