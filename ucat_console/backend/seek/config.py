"""The efficiency seeker's configuration, ``[seek]`` (docs/seek.md).

::

    [seek]
    settle_s = 10.0
    window_s = 30.0
    max_candidates = 20
    confirm = 3
    [[seek.params]]
    name = "mpc.st_opt"
    lo = 0.2
    hi = 0.45

The parameters are the live tuning's keys (``backend.loop.blocks``: ``mpc.lam_st``,
``baseline.frequency`` ...); whether a name is tunable and whether its bounds lie inside
its field's own range is checked against the registry when a seek starts (the registry may
grow after this file is read), never here.
"""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.typedconf import Config, param, require_below


@dataclass(frozen=True)
class SeekParam(Config):
    """One parameter the seeker varies, inside ``[lo, hi]``."""

    name: str = param("mpc.st_opt", doc="a tunable parameter's key (block.field), e.g. mpc.lam_st")
    lo: float = param(0.2, doc="the lowest value the seeker tries (inside the parameter's own range)")
    hi: float = param(0.45, doc="the highest value the seeker tries (inside the parameter's own range)")

    def _check(self) -> None:
        if "." not in self.name:
            raise ValueError(f"name: {self.name!r} is not a tunable parameter's key (block.field)")
        require_below(self, "lo", "hi", "the seeker's bounds")


DEFAULT_PARAMS = (SeekParam("mpc.st_opt", 0.2, 0.45), SeekParam("mpc.lam_st", 0.5, 20.0))


@dataclass(frozen=True)
class SeekConfig(Config):
    """Seek efficiency (docs/seek.md): candidates measured on electrical energy per metre."""

    params: tuple[SeekParam, ...] = param(
        DEFAULT_PARAMS, doc="the parameters the seeker may vary and their bounds ([[seek.params]] tables)")
    settle_s: float = param(10.0, lo=0.0, hi=600.0, unit="s",
                            doc="after each change, this long before the measure window starts")
    window_s: float = param(30.0, lo=0.5, hi=3600.0, unit="s",
                            doc="each candidate's measure window (energy per metre with its bootstrap interval)")
    max_candidates: int = param(20, lo=1, hi=1000, doc="candidates measured in one search (the start's included)")
    confirm: int = param(3, lo=0, hi=100,
                         doc="after a search, its best this many accepted candidates measured once more each; "
                             "the least of these second measures is the best (0: the first measures decide)")
    seed: int = param(0, lo=0, hi=2**31 - 1, doc="seed of the search's sampler (the same seed suggests the same)")
    startup: int = param(5, lo=1, hi=100, doc="candidates drawn at random before the search models the results")
    speed_band: float = param(0.03, lo=0.0, hi=1.0, unit="m/s",
                              doc="a candidate whose speed error (mean |error| over its window) is larger is rejected")
    depth_band: float = param(0.1, lo=0.0, hi=10.0, unit="m",
                              doc="a candidate whose depth error (mean |error| over its window) is larger is rejected")
    heading_band: float = param(0.15, lo=0.0, hi=3.2, unit="rad",
                                doc="a candidate whose heading error (mean |error| over its window) is larger is rejected")
    abort_s: float = param(5.0, lo=0.5, hi=600.0, unit="s",
                           doc="a candidate whose speed, depth or heading has been off its expected response "
                               "(the tracking failsafe's measure) this long is rejected at once and the best put "
                               "back; shorter than the tracking failsafe's timeout")
    drift_check: bool = param(True, doc="after a search, keep measuring the best and seek again when a "
                                        "window's energy per metre falls outside the best's interval")
    max_seeks: int = param(3, lo=1, hi=100, doc="searches in one run at most (the first and the re-seeks)")
    on_stop: str = param("revert", choices=("revert", "best"),
                         doc="what a seek stopped by a disarm, a failsafe or the pilot's loss leaves in force: "
                             "revert: the values it found; best: the best measured")

    def _check(self) -> None:
        if not self.params:
            raise ValueError("params: give at least one [[seek.params]] table")
        names = [p.name for p in self.params]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"params: {', '.join(twice)} given more than once")

    def bounds(self, name: str) -> SeekParam:
        """The bounds of parameter ``name`` (ValueError naming the configured ones)."""
        for p in self.params:
            if p.name == name:
                return p
        raise ValueError(f"{name}: not one of the seeker's parameters ([[seek.params]]: "
                         f"{', '.join(p.name for p in self.params)})")

    def only(self, names: tuple[str, ...]) -> tuple[SeekParam, ...]:
        """The configured bounds of ``names`` (all when empty)."""
        return tuple(self.bounds(n) for n in names) if names else self.params
