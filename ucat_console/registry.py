"""A live registry of named entries: the one shape of the console's extension points (the
fin modes, the tunable blocks, the robots, the auxiliary sensors).

A :class:`Registry` maps each entry's name to the entry, in the order registered; it is read
live wherever the set is needed (never copied at import), as python-can reads its backends.
Registering checks the entry's type and that its name is new; a lookup of a name that is
not there is a ValueError naming the ones that are. It imports nothing of the package, so
every layer may hold one.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Mapping[str, T], Generic[T]):
    """Entries of type ``kind`` by their ``name`` (module docstring); ``what`` names the
    kind in errors ("mode", "robot")."""

    def __init__(self, what: str, kind: type[T]) -> None:
        self.what = what
        self.kind = kind
        self._entries: dict[str, T] = {}

    def register(self, entry: T) -> T:
        """Add ``entry`` (ValueError if it is not of the registry's kind or its name is
        taken); returns it."""
        if not isinstance(entry, self.kind):
            raise ValueError(f"{self.what}: expected a {self.kind.__name__}, got {type(entry).__name__}")
        name = entry.name  # type: ignore[attr-defined]
        if name in self._entries:
            raise ValueError(f"{self.what}: {name!r} is registered already")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> T:
        """Take ``name`` out (a test's entry, or a plug-in's going away); returns it."""
        entry = self.get_entry(name)
        del self._entries[name]
        return entry

    def get_entry(self, name: object) -> T:
        """The entry called ``name``, else ValueError naming the registered ones."""
        try:
            return self._entries[name]  # type: ignore[index]
        except (KeyError, TypeError):
            raise ValueError(f"{self.what}: {name!r} is not one of "
                             f"{', '.join(self._entries) or '(none registered)'}") from None

    def names(self) -> tuple[str, ...]:
        """The registered names, in the order registered (read live)."""
        return tuple(self._entries)

    def __getitem__(self, name: str) -> T:
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)
