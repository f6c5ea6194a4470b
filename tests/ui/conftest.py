"""The page's tests; their helpers live beside this file (``plots_reference.py``)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # for ``import plots_reference``
