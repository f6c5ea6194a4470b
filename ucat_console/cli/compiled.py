"""The compiled code before ``run`` starts: :mod:`ucat_console.compiled` (outside the
command line, so that the benchmarks call it too); the names ``run`` reads from here."""

from ucat_console.compiled import console_steps, needed_steps, planner_step, prepare

__all__ = ["console_steps", "needed_steps", "planner_step", "prepare"]
