"""What a message field is: its meaning, unit and frame, and the names of a vector's parts.

Message dataclasses annotate their fields with :class:`Doc` (``Annotated[Vec3, Doc(...)]``),
so the unit of a value is written once, beside the field, and the session schemas, the
CSV export and the Foxglove server read it from there. ``Annotated`` changes nothing at
run time: the dataclasses take and hold the same values as without it.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass

#: part names of the common fixed-length vectors
XYZ = ("x", "y", "z")
WXYZ = ("w", "x", "y", "z")  # a quaternion as the messages hold it (w first)
RPY = ("roll", "pitch", "yaw")
XY = ("x", "y")


@dataclass(frozen=True)
class Doc:
    """Description of one message field.

    ``unit``: SI unit symbol ("" for text, flags and counts, "1" for dimensionless
    numbers), written so that a units library parses it (``m/s``, ``rad/s``, ``N m``,
    ``m/s^2``); a tuple of them for
    a vector whose parts differ (one per part, in tuple order); ``frame``: the frame a
    vector is expressed in; ``names``: a fixed-length tuple is written as an object with
    these keys (in tuple order), so tools show ``position.x`` rather than ``position[0]``;
    ``wide``: an integer that may exceed 2^53 (JavaScript's exact range), written as a
    decimal string.
    """

    text: str
    unit: str | tuple[str, ...] = ""
    frame: str = ""
    names: tuple[str, ...] = ()
    wide: bool = False

    def units(self, n: int = 1) -> tuple[str, ...]:
        """The unit of each of ``n`` parts (a single unit repeated)."""
        if isinstance(self.unit, tuple):
            if len(self.unit) != n:
                raise TypeError(f"{len(self.unit)} units for {n} values")
            return self.unit
        return (self.unit,) * n

    def describe(self) -> str:
        """The text with its unit and frame, as a schema description says it."""
        unit = ", ".join(self.unit) if isinstance(self.unit, tuple) else self.unit
        extra = [x for x in (f"unit {unit}" if unit else "",
                             f"frame {self.frame}" if self.frame else "") if x]
        return self.text + (f" ({'; '.join(extra)})" if extra else "")


def field_docs(cls: type) -> dict[str, Doc]:
    """The :class:`Doc` of each annotated field of dataclass ``cls`` (fields without one
    are left out)."""
    out: dict[str, Doc] = {}
    for name, tp in typing.get_type_hints(cls, include_extras=True).items():
        if typing.get_origin(tp) is typing.Annotated:
            docs = [m for m in tp.__metadata__ if isinstance(m, Doc)]
            if docs:
                out[name] = docs[0]
    return out
