"""Declared layouts of the row tables compiled code and Python share.

A compiled kernel keeps its state and hands its results over in flat float64 rows (numba
reads a row's columns fastest by constant index). Each such row table has one
:class:`Layout`: its fields in order, each with its width and meaning, from which the
column offsets follow. The kernels' modules take their column constants from it (module
globals, frozen into the compiled code as constants); the Python side (the loop's outbox,
the planners, tests) reads and writes fields by name through the same layout, so the two
sides can not disagree on a column, and nobody numbers columns by hand.
"""

from __future__ import annotations

from typing import Sequence


class Layout:
    """The columns of one row table: ``fields`` are (name, width, meaning), in order."""

    def __init__(self, name: str, fields: Sequence[tuple[str, int, str]]) -> None:
        self.name = name
        self._at: dict[str, int] = {}
        self._width: dict[str, int] = {}
        self.doc: dict[str, str] = {}
        k = 0
        for field, width, meaning in fields:
            if field in self._at:
                raise ValueError(f"{name}: field {field!r} is declared twice")
            if width < 1:
                raise ValueError(f"{name}: field {field!r} has width {width}; allowed: >= 1")
            self._at[field] = k
            self._width[field] = width
            self.doc[field] = meaning
            k += width
        self.size = k

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(self._at)

    def at(self, field: str) -> int:
        """The column of ``field`` (its first, for a wider one)."""
        try:
            return self._at[field]
        except KeyError:
            raise KeyError(f"{self.name}: no field {field!r}; fields: {', '.join(self._at)}") from None

    def width(self, field: str) -> int:
        return self._width[field]

    def span(self, field: str) -> slice:
        """The columns of ``field``."""
        a = self.at(field)
        return slice(a, a + self._width[field])

    def get(self, row: Sequence[float], field: str) -> float | tuple[float, ...]:
        """``field`` of ``row``: a number, or a tuple for a wider field."""
        a = self.at(field)
        w = self._width[field]
        return float(row[a]) if w == 1 else tuple(float(x) for x in row[a:a + w])

    def describe(self) -> str:
        """The layout as text, a line per field: columns, name, meaning."""
        lines = [f"{self.name} ({self.size} columns)"]
        for f in self._at:
            a, w = self._at[f], self._width[f]
            cols = str(a) if w == 1 else f"{a}-{a + w - 1}"
            lines.append(f"  {cols:>7}  {f}: {self.doc[f]}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"Layout({self.name!r}, {self.size} columns)"
