# Shared by scripts/run.sh and scripts/test.sh: make a virtual environment in .venv
# and install the project into it (with extras given as $1, e.g. "test"), every package at
# the version constraints.txt pins, so that every install is the same.
# PYTHON picks the interpreter (default python3) and VENV the folder (default .venv), e.g.
#   PYTHON=python3.12 VENV=.venv-3.12 scripts/test.sh
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# numba's compiled cache of this checkout: in it (.cache/, ignored by git), so that a clone
# and its cache go together (CI's fresh clones leave none behind in the user's cache folder);
# UCAT_CONSOLE_CACHE_DIR or NUMBA_CACHE_DIR set beforehand choose another (docs/install.md)
export UCAT_CONSOLE_CACHE_DIR="${UCAT_CONSOLE_CACHE_DIR:-$ROOT/.cache/numba}"
PY="${PYTHON:-python3}"
VENV="${VENV:-.venv}"

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
  echo "need root to run: $*" >&2; return 1; fi; }

if [ ! -x "$VENV/bin/python" ]; then
  if ! "$PY" -m venv "$VENV" 2>/dev/null; then
    echo "$PY -m venv failed; installing Debian's python3-venv" >&2
    as_root apt-get update -qq && as_root apt-get install -y -qq python3-venv
    "$PY" -m venv "$VENV"
  fi
fi
extras="${1:-}"
stamp="$VENV/.installed${extras:+-$extras}"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ]; then
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -c constraints.txt -e ".${extras:+[$extras]}"
  touch "$stamp"
fi
