"""The events list as the page's markdown renders it (CommonMark, as the page's renderer
follows): every event a list item of plain text, codes and messages shown as they are."""

from __future__ import annotations

import pytest

from ucat_console.telemetry.events import Event
from ucat_console.ui.markdown import events_markdown

markdown_it = pytest.importorskip("markdown_it")


def _tokens(text: str) -> list:
    return markdown_it.MarkdownIt("commonmark").parse(text)


def test_an_event_renders_as_a_list_item_of_text_not_a_code_block() -> None:
    events = [Event(3.2, "loop", "plan_overrun", "fin 2 waited 0.12 s past the hand-over", "warning", {}),
              Event(1234.5, "recorder", "write_failed", "OSError [Errno 28] *disk* full <tmp>", "error", {})]
    tokens = _tokens(events_markdown(events))
    kinds = {t.type for t in tokens}
    assert "code_block" not in kinds and "fence" not in kinds
    assert sum(t.type == "list_item_open" for t in tokens) == 2
    text = "".join(c.content for t in tokens if t.type == "inline" for c in t.children if c.type == "text")
    # what the page shows: the codes and messages as they are, no stray backslash or markup
    assert "loop plan_overrun" in text and "3.2 s" in text
    assert "OSError [Errno 28] *disk* full <tmp>" in text
    assert "\\" not in text
