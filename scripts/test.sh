#!/usr/bin/env bash
# Install the project with its test dependencies (and Debian's chromium for the
# browser tests), then run the whole test suite. Extra arguments go to pytest.
source "$(dirname "$0")/_env.sh" "test"
if [ ! -x /usr/bin/chromium ]; then
  as_root apt-get update -qq && as_root apt-get install -y -qq chromium
fi
exec .venv/bin/python -m pytest "$@"
