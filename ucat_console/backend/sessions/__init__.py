"""Session recording and reading (MCAP), index, repair, export, playback and replay.

The recorder and the player are the two ends of the one telemetry stream: the recorder
writes what is published, the player publishes what was written.

    schema     JSON Schemas derived from the message dataclasses (encoding 2: named vectors,
               wide integers as text, non-finite numbers listed in ``nonfinite``)
    codec      message <-> JSON bytes; stream seconds <-> file nanoseconds
    legacy     reading files of encoding 1 (written before encoding 2)
    foxglove   the robot for Foxglove's 3-D panel (transforms, scene) and foxglove.Log,
               written beside our channels (and served live by backend.foxglove_live)
    files      the sessions directory, file names, metadata record names, a session's part
               files (a page's paths confined to the directory, the shell's not)
    recorder   Recorder: stream -> crash-safe MCAP parts (its writer: mcap_writer)
    mcap_read  one MCAP file's summary, metadata and chunks, read within the limits
    reader     SessionReader (one part file) and SessionParts (every part of a session as one
               recording): decoded messages, time ranges, state_at, events
    repair     rewrite a truncated file fully indexed
    index      list sessions from their summaries
    library    the run library: an SQLite index of every session with its facts and
               figures (library_read), queried in a small language (library_query); tags
               and notes given after recording in a sidecar beside the session (sidecar)
    export     CSV per channel
    markers    review markers in a sidecar file
    player     Player: file -> stream, with its own clock
    replay     counterfactual replay of recorded fin plans with other MPC weights
"""

from ucat_console.backend import sensors as _sensors  # noqa: F401  the built-in sensors' channels, before a file is read
