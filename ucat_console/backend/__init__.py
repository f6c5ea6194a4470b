"""The imperative shell: supervisor, loops, safety, drivers, simulated robot, sessions."""
