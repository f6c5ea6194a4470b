#!/usr/bin/env bash
# Install the project (first time) and start the console on the simulated robot
# (the shipped sim-tuned configuration unless a --config is given). Arguments go to
# `ucat-console run`; recordings go where `ucat-console paths` says.
source "$(dirname "$0")/_env.sh" ""  # no extras; this script's own arguments stay its own
case " $* " in
  *" --config "*|*" --config="*) exec "$VENV/bin/ucat-console" run "$@" ;;
  *) exec "$VENV/bin/ucat-console" run --config sim-tuned "$@" ;;
esac
