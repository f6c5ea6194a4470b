"""What the package ships besides its code: the configurations and the Foxglove layout.

They are package data (installed with the package, found wherever it is installed):

* ``configs/<name>.toml``: configurations a run names by their name, ``--config sim-tuned``
  (:func:`config_path`): ``sim-tuned`` (the simulated robot with controller settings under
  which it swims from rest), ``sim-devices`` (the same drivers as the robot's, against the
  device emulators) and ``robot`` (the U-CAT's devices);
* ``manoeuvres/<name>.toml``: scripted manoeuvres a run names by their name,
  ``--manoeuvre e4_ladder`` (:func:`manoeuvre_path`; docs/manoeuvres.md);
* ``foxglove-layout.json``: the layout for a session or the live robot in Foxglove and
  Lichtblick (*Layouts*, *Import from file*).

``ucat-console paths`` prints where each of them is.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

#: a configuration's name: what ``--config`` takes besides a file (no folder, no suffix)
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")


def _package_file(name: str) -> Path:
    # the package is installed as files (a folder or an editable install), never zipped
    return Path(str(resources.files("ucat_console").joinpath(name)))


def configs_dir() -> Path:
    """The folder holding the shipped configurations."""
    return _package_file("configs")


def config_names() -> list[str]:
    """The shipped configurations' names, sorted."""
    return sorted(p.stem for p in configs_dir().glob("*.toml"))


def is_name(value: str | Path) -> bool:
    """Whether ``value`` names a configuration rather than a file: letters, digits, ``_``
    and ``-`` only (``sim-tuned``; a file is given with its folder or its ``.toml``)."""
    return bool(_NAME.match(str(value)))


def config_path(value: str | Path) -> Path:
    """The file of a configuration given by name (a shipped one) or by path.

    A name (:func:`is_name`) that is not shipped is an error listing the shipped ones; a
    path is returned as given (the loader says when it does not exist)."""
    return _named(value, configs_dir(), "config", "configuration", "my-config")


def manoeuvres_dir() -> Path:
    """The folder holding the shipped manoeuvres."""
    return _package_file("manoeuvres")


def manoeuvre_names() -> list[str]:
    """The shipped manoeuvres' names, sorted."""
    return sorted(p.stem for p in manoeuvres_dir().glob("*.toml"))


def manoeuvre_path(value: str | Path) -> Path:
    """The file of a manoeuvre given by name (a shipped one) or by path (as :func:`config_path`)."""
    return _named(value, manoeuvres_dir(), "manoeuvre", "manoeuvre", "my-manoeuvre")


def _named(value: str | Path, folder: Path, key: str, what: str, example: str) -> Path:
    if not is_name(value):
        return Path(value)
    path = folder / f"{value}.toml"
    if not path.is_file():
        names = sorted(p.stem for p in folder.glob("*.toml"))
        raise ValueError(f"{key}: {str(value)!r} is neither a shipped {what} ("
                         f"{', '.join(names)}) nor a file (give a file with its "
                         f"folder or its .toml suffix, e.g. ./{example}.toml)")
    return path


def foxglove_layout() -> Path:
    """The Foxglove / Lichtblick layout file."""
    return _package_file("foxglove-layout.json")
