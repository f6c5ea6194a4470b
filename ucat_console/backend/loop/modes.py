"""The fin controllers (modes): one registration each, read by everything that names one.

A :class:`Mode` says what a controller is called (its name, the page's label, the status
bar's short label), which logical fins it plans for (each fin alone, or the rear pair
synchronised), how one logical fin's planner is made, which configuration blocks that
planner is made from (a change to one rebuilds it), and whether its fins follow the body
loops' force targets. :data:`MODES` holds them in order; the loop
(``closed_loop``: planners, fin groups, tracking), its configuration (``LoopConfig.mode``),
the supervisor, the page's mode dropdown and status bar, the command line (``run --mode``,
``bench --modes``) and the telemetry (a message's ``mode`` is one of these names) all read
it. A new controller is one :func:`register` call below::

    register(Mode("oracle", "MPC with the true plant", "oracle", INDEPENDENT_FINS,
                  lambda s: OraclePlanner(s.mpc, s.seed, s.executor), reads=("mpc",)))
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ucat_console.backend.loop.planners import BaselineFinPlanner, ManoeuvreFinPlanner, MpcFinPlanner, Planner
from ucat_console.control.allocation import INDEPENDENT_FINS, SYNC_FINS
from ucat_console.control.baseline import fin_model_inverse
from ucat_console.control.params import BaselineConfig, ExecutorConfig, ManoeuvreConfig, MpcConfig
from ucat_console.registry import Registry

#: the configuration blocks a planner may be made from (the loop's tunable blocks)
BLOCKS = ("mpc", "baseline", "manoeuvre")


@dataclass(frozen=True)
class PlannerSetting:
    """What one logical fin's planner is made from: the blocks in force and its own seed
    (distinct per logical fin and per planner generation)."""

    mpc: MpcConfig
    baseline: BaselineConfig
    executor: ExecutorConfig
    manoeuvre: ManoeuvreConfig
    seed: int


@dataclass(frozen=True)
class Mode:
    """One fin controller (module docstring)."""

    name: str
    label: str  # the page: what the controller is
    short: str  # the status bar
    fins: tuple[tuple[int, ...], ...]  # logical fins (paper fin indices), one planner each
    planner: Callable[[PlannerSetting], Planner]
    reads: tuple[str, ...] = ("mpc",)  # blocks of BLOCKS its planners are made from
    follows_targets: bool = True  # False: its fins ignore the body loops (no tracking to judge)
    mpc: bool = False  # its planner is the MPC (an experiment's ``mpc_planner`` stands in for it)
    #: the largest mean force (N) one fin's planner can make, where it is less than the fin
    #: model's deliverable force (a fixed beat frequency): the body layer's allocation limits
    #: follow it, so that an axis the fins cannot serve is cut in priority order rather than
    #: lost in the strokes' saturation; None: the fin model's deliverable force
    fin_force: Callable[[PlannerSetting], float] | None = None
    #: the body loops follow the fins' executed cycle periods under this mode
    #: (``BodyConfig.schedule``): its beat frequency is the operator's choice, so its cycles
    #: may run far longer than the delay the loops are designed for (the MPC modes hold
    #: theirs within ``MpcConfig.max_cycle`` and run the designed gains)
    schedules_body: bool = False

    def __post_init__(self) -> None:
        if self.fins not in (INDEPENDENT_FINS, SYNC_FINS):
            raise ValueError(f"mode {self.name!r}: fins must be INDEPENDENT_FINS or SYNC_FINS "
                             "(the loop's core computes the targets of those two layouts)")
        unknown = set(self.reads) - set(BLOCKS)
        if unknown:
            raise ValueError(f"mode {self.name!r}: reads {sorted(unknown)} not of {', '.join(BLOCKS)}")

    @property
    def rear_synchronised(self) -> bool:
        """Whether the rear pair is one logical fin (the core's targets follow)."""
        return self.fins == SYNC_FINS


#: every fin controller by name, in the order the page lists them
MODES: Registry[Mode] = Registry("mode", Mode)
#: add a mode (its name must be new); returns it
register = MODES.register
#: take a mode out (a test's, or a plug-in's going away)
unregister = MODES.unregister
#: the mode called ``name``, else ValueError naming the modes there are
mode = MODES.get_entry


def mode_names(*, follows_targets: bool | None = None) -> tuple[str, ...]:
    """The registered modes' names (only those whose ``follows_targets`` is that, if given)."""
    return tuple(m.name for m in MODES.values() if follows_targets is None or m.follows_targets == follows_targets)


register(Mode("mpc", "MPC", "MPC", INDEPENDENT_FINS,
              lambda s: MpcFinPlanner(s.mpc, s.seed, s.executor), mpc=True))
register(Mode("mpc_sync", "MPC, rear fins synchronised", "MPC sync", SYNC_FINS,
              lambda s: MpcFinPlanner(s.mpc, s.seed, s.executor), mpc=True))
register(Mode("baseline", "baseline inverse model", "baseline", INDEPENDENT_FINS,
              lambda s: BaselineFinPlanner(s.mpc, s.baseline, s.executor), reads=("mpc", "baseline"),
              fin_force=lambda s: fin_model_inverse(s.mpc, s.baseline, s.executor.acceleration,
                                                    s.executor.max_rate).peak_force, schedules_body=True))
register(Mode("identify", "the identification manoeuvre (Session tab)", "identify", INDEPENDENT_FINS,
              lambda s: ManoeuvreFinPlanner(s.manoeuvre, s.mpc), reads=("mpc", "manoeuvre"),
              follows_targets=False))
