"""ucat-console: operator console and onboard controller for the four-fin U-CAT robot."""

from importlib import metadata as _metadata

from ucat_console.compiled_cache import use_source_keyed_cache as _use_source_keyed_cache


def _version() -> str:
    """The installed distribution's version (pyproject.toml's, its one definition); from a
    source tree that was never installed, its pyproject.toml's; else ``0+unknown``."""
    try:
        return _metadata.version("ucat-console")
    except _metadata.PackageNotFoundError:
        pass
    import tomllib
    from pathlib import Path

    try:
        with open(Path(__file__).resolve().parent.parent / "pyproject.toml", "rb") as fh:
            project = tomllib.load(fh).get("project", {})
    except (OSError, tomllib.TOMLDecodeError):
        return "0+unknown"
    return str(project["version"]) if project.get("name") == "ucat-console" and "version" in project else "0+unknown"


__version__ = _version()

# before any kernel is defined: numba's cache keyed by the compiled sources (compiled_cache)
_use_source_keyed_cache()
