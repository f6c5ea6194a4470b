#!/usr/bin/env bash
# Install the project with its test dependencies (every extra; Debian's chromium for the
# browser tests, node and npm for the independent session reader), then run the whole test
# suite. Extra arguments go to pytest.
source "$(dirname "$0")/_env.sh" "test"
if [ ! -x /usr/bin/chromium ]; then
  as_root apt-get update -qq && as_root apt-get install -y -qq chromium
fi
if ! command -v npm >/dev/null; then
  as_root apt-get update -qq && as_root apt-get install -y -qq nodejs npm
fi
# the compiled code first, in two processes (seconds when numba's cache has it already)
"$VENV/bin/ucat-console" prepare
exec "$VENV/bin/python" -m pytest "$@"
