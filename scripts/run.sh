#!/usr/bin/env bash
# Install the project (first time) and start its main job.
source "$(dirname "$0")/_env.sh" ""
exec .venv/bin/ucat-console bench mpc "$@"
