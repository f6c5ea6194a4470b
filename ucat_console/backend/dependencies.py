"""The versions of the libraries whose internals or exact behaviour the console relies on,
and the start-up check of the installed ones (a clear error naming the package, the
installed and the supported version).

viser: :mod:`ucat_console.ui.viser_compat` uses some of its private names (each with its
reason there); they change between minor versions. mcap: the session files' reader and
the recorder's writer (:mod:`ucat_console.backend.sessions.mcap_writer`) are checked
against its 1.6 series. ``pyproject.toml`` states the same ranges.
"""

from __future__ import annotations

from importlib import metadata

#: package -> (lowest supported version, first unsupported version)
SUPPORTED: dict[str, tuple[str, str]] = {
    "viser": ("1.1.1", "1.2"),
    "mcap": ("1.6.0", "1.7"),
}


class UnsupportedVersion(RuntimeError):
    """An installed library is outside the range the console supports."""


def _numbers(version: str) -> tuple[int, ...]:
    """The leading numeric release of ``version`` ("1.1.1rc2" -> (1, 1, 1))."""
    out = []
    for part in version.split("."):
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        if not digits:
            break
        out.append(int(digits))
        if len(digits) < len(part):
            break
    return tuple(out)


def supported(package: str, installed: str) -> bool:
    """Whether ``installed`` lies in ``package``'s supported range."""
    low, high = SUPPORTED[package]
    return _numbers(low) <= _numbers(installed) < _numbers(high)


def require(package: str) -> str:
    """The installed version of ``package``; :class:`UnsupportedVersion` when it is outside
    :data:`SUPPORTED` or not installed."""
    low, high = SUPPORTED[package]
    try:
        installed = metadata.version(package)
    except metadata.PackageNotFoundError:
        raise UnsupportedVersion(f"{package} is not installed; the console needs {package}>={low},<{high}") from None
    if not supported(package, installed):
        raise UnsupportedVersion(
            f"{package} {installed} is installed; the console supports {package}>={low},<{high} "
            f"(pip install '{package}>={low},<{high}')")
    return installed
