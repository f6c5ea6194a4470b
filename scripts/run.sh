#!/usr/bin/env bash
# Install the project (first time) and start the console on the simulated robot
# (the shipped sim-tuned configuration unless a --config is given). Arguments go to
# `ucat-console run`; recordings go where `ucat-console paths` says.
# The foxglove extra comes along, so that --foxglove-port works too.
source "$(dirname "$0")/_env.sh" "foxglove"
case " $* " in
  *" --config "*|*" --config="*) exec "$VENV/bin/ucat-console" run "$@" ;;
  *) exec "$VENV/bin/ucat-console" run --config sim-tuned "$@" ;;
esac
