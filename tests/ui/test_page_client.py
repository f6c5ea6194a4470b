"""The console's patch of viser's page client (``ucat_console/ui/page_client.py``): the shipped
client still holds each piece the patch replaces, the served page holds the patched code,
and a client without a piece is refused with its name."""

from __future__ import annotations

import os

import pytest
import zstandard

import viser
from ucat_console.ui import page_client
from ucat_console.ui.page_client import PATCHES, PageClientChanged


def test_the_shipped_client_holds_each_piece_the_patch_replaces_once() -> None:
    # fails when a new viser changes the code patched: the patch must then be checked again
    page_client.check_version()
    _, script = page_client.client_code(page_client.shipped_index())
    text = script.decode()
    for p in PATCHES:
        assert text.count(p.original) == 1, p.name


def test_the_served_page_holds_the_patched_code_and_nothing_else_changed() -> None:
    shipped = page_client.shipped_index()
    style, script = page_client.client_code(shipped)
    new_style, new_script = page_client.client_code(page_client.index_bytes().decode())
    assert new_style == style
    expected = script.decode()
    for p in PATCHES:
        assert p.original not in new_script.decode()
        expected = expected.replace(p.original, p.replacement)
    assert new_script.decode() == expected


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 5, 6, 7, 8, 1001])
def test_the_loader_alphabet_round_trips(n: int) -> None:
    data = os.urandom(n)
    assert page_client._decode(page_client._encode(data)) == data


def test_a_client_without_a_piece_is_refused_naming_it() -> None:
    style, script = b"body{}", b"console.log(1);"
    payload = page_client._encode(zstandard.ZstdCompressor().compress(style + script))
    html = f'<html><script data-p="{payload}" data-ss="{len(style)}" data-cs="{len(script)}">loader</script></html>'
    with pytest.raises(PageClientChanged, match="'retry' patch"):
        page_client.patched_index(html)
    with pytest.raises(PageClientChanged, match="no script loader"):
        page_client.patched_index("<html></html>")


def test_another_viser_version_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(viser, "__version__", "1.1.9")
    with pytest.raises(PageClientChanged, match="viser 1.1.9 is installed"):
        page_client.check_version()
