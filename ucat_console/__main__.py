"""``python -m ucat_console``: the ``ucat-console`` command."""

import sys

from ucat_console.cli import main

if __name__ == "__main__":
    sys.exit(main())
