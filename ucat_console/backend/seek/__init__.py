"""The efficiency seeker's configuration and search (docs/seek.md); its run on the console
is :mod:`ucat_console.backend.supervisor.seek_run`."""
