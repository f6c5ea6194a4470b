"""viser's page client as the console serves it: its websocket (re)connection patched so
that a page connects through slow links and always comes back after a restart.

Why: viser's client (1.1.1, ``src/viser/client/src/WebsocketInterface.tsx`` and
``WebsocketClientWorker.ts``) retries its socket every second, only while its window has
the focus, and each retry closes the socket still opening: a handshake slower than about a
second (a link of 0.6 s each way, or a console starting on a busy computer) never completes,
and a page without the focus never retries. Three exact pieces of the shipped bundle are
replaced (:data:`PATCHES`):

* ``retry``: the retries back off (:data:`FIRST_RETRY` s, doubling up to :data:`MAX_RETRY`
  s) and go on whether or not the window has the focus;
* ``keep-handshake``: a retry while the socket is still opening does nothing (a handshake in
  progress is never closed by a retry);
* ``handshake-timeout``: a socket that has not opened after :data:`HANDSHAKE_TIMEOUT` s is
  closed (viser: 5 s), so that a handshake through a slow link has time to complete.

viser ships its client as one HTML file whose script is zstd-compressed and written in an
88-character alphabet (its page loader decodes it). :func:`patched_index` decodes it,
replaces each piece (each must occur exactly once, else :class:`PageClientChanged` names
the piece: a new viser has to be checked, not patched blindly) and encodes it again; the
page server serves the result for ``/`` (:mod:`ucat_console.ui.viser_compat`). The installed
package's files are never changed. viser has no option for its retry policy; the upstream
change that would remove this: a back-off retry that never closes a socket still opening.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from pathlib import Path

import zstandard

import viser

from ucat_console.backend.dependencies import UnsupportedVersion

#: the viser versions whose client the pieces below were taken from
PATCHED_FOR = ("1.1.1",)
#: the first retry after a socket closed, and the longest wait between retries (s)
FIRST_RETRY = 1.0
MAX_RETRY = 4.0
#: a socket still opening after this long is closed (s)
HANDSHAKE_TIMEOUT = 20.0

#: the alphabet of viser's page loader (its ``de``): 4 bytes in 5 characters, big-endian
_ALPHABET = "!#$%()*+,-./0123456789:;=?@ABCDEFGHIJKLMNOPQRSTUVWXYZ[\\]^_abcdefghijklmnopqrstuvwxyz{|}~"
_VALUE = {c: i for i, c in enumerate(_ALPHABET)}
_LOADER = re.compile(r'<script data-p="([^"]*)" data-ss="(\d+)" data-cs="(\d+)">')


class PageClientChanged(UnsupportedVersion):
    """viser's shipped client no longer holds a piece of code the console replaces (the
    console stops at start with this error, as for an unsupported viser version)."""


@dataclass(frozen=True)
class Patch:
    name: str
    original: str
    replacement: str
    why: str


PATCHES: tuple[Patch, ...] = (
    Patch(
        "retry",
        "function u(){let t=!o&&document.hasFocus();o||e.useGui.set({websocketState:t?`reconnecting`:`inactive`}),"
        "t&&s===null?(c({type:`retry`}),s=setInterval(()=>{c({type:`retry`})},1e3)):"
        "!t&&s!==null&&(clearInterval(s),s=null)}",
        "function u(){let t=!o;o||e.useGui.set({websocketState:`reconnecting`}),"
        "t&&s===null?(c({type:`retry`}),s=((d)=>{let q=()=>{c({type:`retry`});d=Math.min(2*d,%d);"
        "s=setTimeout(q,d)};return setTimeout(q,d)})(%d)):!t&&s!==null&&(clearTimeout(s),s=null)}"
        % (int(MAX_RETRY * 1000), int(FIRST_RETRY * 1000)),
        "retries every second, only while the window has the focus",
    ),
    Patch(
        "keep-handshake",
        "a=()=>{n+=1;let a=n;t!==null&&t.close();",
        "a=()=>{if(t!==null&&t.readyState===0)return;n+=1;let a=n;t!==null&&t.close();",
        "each retry closes the socket still opening",
    ),
    Patch(
        "handshake-timeout",
        "let c=setTimeout(()=>{s.close()},5e3);",
        "let c=setTimeout(()=>{s.close()},%d);" % int(HANDSHAKE_TIMEOUT * 1000),
        "a socket still opening is closed after 5 s",
    ),
)


def _decode(text: str) -> bytes:
    """viser's page loader's ``de``."""
    n, r = divmod(len(text), 5)
    out = bytearray()
    for i in range(0, n * 5, 5):
        v = 0
        for c in text[i:i + 5]:
            v = v * 88 + _VALUE[c]
        out += v.to_bytes(4, "big")
    if r:
        v = 0
        for c in text[n * 5:]:
            v = v * 88 + _VALUE[c]
        out += v.to_bytes(r - 1, "big")
    return bytes(out)


def _encode(data: bytes) -> str:
    """The inverse of :func:`_decode`."""
    out: list[str] = []
    n, r = divmod(len(data), 4)
    for i in range(0, n * 4, 4):
        v = int.from_bytes(data[i:i + 4], "big")
        out.append("".join(_ALPHABET[(v // 88 ** k) % 88] for k in range(4, -1, -1)))
    if r:
        v = int.from_bytes(data[n * 4:], "big")
        out.append("".join(_ALPHABET[(v // 88 ** k) % 88] for k in range(r, -1, -1)))
    return "".join(out)


def shipped_index() -> str:
    """viser's client as it ships (its build's ``index.html``)."""
    return (Path(viser.__file__).parent / "client" / "build" / "index.html").read_text(encoding="utf-8")


def client_code(html: str) -> tuple[bytes, bytes]:
    """The (style, script) of a viser page's loader."""
    m = _LOADER.search(html)
    if m is None:
        raise PageClientChanged("viser's page has no script loader of the form the console knows "
                                "(data-p, data-ss, data-cs)")
    ss, cs = int(m.group(2)), int(m.group(3))
    raw = zstandard.ZstdDecompressor().decompress(_decode(m.group(1)), max_output_size=ss + cs)
    if len(raw) != ss + cs:
        raise PageClientChanged(f"viser's page loader holds {len(raw)} bytes, not the {ss + cs} it declares")
    return raw[:ss], raw[ss:]


def patched_index(html: str) -> str:
    """``html`` (viser's page) with :data:`PATCHES` applied; :class:`PageClientChanged` when a
    piece is not there exactly once."""
    style, script = client_code(html)
    text = script.decode("utf-8")
    for p in PATCHES:
        count = text.count(p.original)
        if count != 1:
            raise PageClientChanged(
                f"viser {viser.__version__}'s page client holds the code the console's '{p.name}' patch replaces "
                f"({p.why}) {count} times, not once: check the new client (ucat_console/ui/page_client.py)")
        text = text.replace(p.original, p.replacement)
    code = text.encode("utf-8")
    payload = _encode(zstandard.ZstdCompressor(level=9).compress(style + code))
    m = _LOADER.search(html)
    assert m is not None
    loader = f'<script data-p="{payload}" data-ss="{len(style)}" data-cs="{len(code)}">'
    return html[:m.start()] + loader + html[m.end():]


_CACHE: list[bytes] = []
_CACHE_LOCK = threading.Lock()


def check_version() -> None:
    """:class:`PageClientChanged` unless the installed viser is one whose client the pieces
    were taken from (:data:`PATCHED_FOR`)."""
    if viser.__version__ not in PATCHED_FOR:
        raise PageClientChanged(
            f"viser {viser.__version__} is installed; the console's patch of viser's page client "
            f"(ucat_console/ui/page_client.py) was made for viser {', '.join(PATCHED_FOR)}: "
            "check its pieces against the new client and add the version to PATCHED_FOR")


def index_bytes() -> bytes:
    """The page the console serves for ``/`` (viser's, patched), made once per process."""
    with _CACHE_LOCK:
        if not _CACHE:
            check_version()
            _CACHE.append(patched_index(shipped_index()).encode("utf-8"))
        return _CACHE[0]
