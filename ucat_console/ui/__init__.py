"""The viser web UI."""
