#!/usr/bin/env bash
# Install the project (first time) and start the console on the simulated robot
# (config/sim-tuned.toml unless a --config is given). Arguments go to `ucat-console run`.
# The foxglove extra comes along, so that --foxglove-port works too.
source "$(dirname "$0")/_env.sh" "foxglove"
case " $* " in
  *" --config "*|*" --config="*) exec .venv/bin/ucat-console run "$@" ;;
  *) exec .venv/bin/ucat-console run --config config/sim-tuned.toml "$@" ;;
esac
