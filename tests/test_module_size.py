"""No module over 600 lines without a one-line reason at its top."""

from __future__ import annotations

import re
from pathlib import Path

import ucat_console

PACKAGE = Path(ucat_console.__file__).parent
MAX_LINES = 600
REASON = re.compile(r"^# Over 600 lines: \S.{20,}$")


def test_a_long_module_says_why_on_its_first_line() -> None:
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        lines = path.read_text(encoding="utf-8").splitlines()
        if len(lines) > MAX_LINES and not REASON.match(lines[0]):
            unexplained.append(f"{path.relative_to(PACKAGE.parent)} ({len(lines)} lines)")
    assert unexplained == []
