"""The loop's tunable blocks: one live registry, read wherever the set is needed.

A :class:`Block` is one configuration the operator may change while the loop runs: its
name (``"mpc"``, ``"pid.depth"``), its frozen config dataclass, the page's title for it,
which of its fields are tuned live, where the loop starts it from (its value in the loop's
configuration) and how the loop puts a new one in force. The loop's one command for them
(``commands.SetBlock``), what the loop holds as commanded, the supervisor's tuning (the
check of a value against its field's kind and range, the journal, undo, revert) and the
page's tuning folders all read this registry when they need it, so a block registered
before the console starts (``register(Block(...))`` from your own module) is tuned like a
built-in one, as a mode is (``modes``).

The built-in blocks (registered below, in the page's order): ``mpc`` (the fin MPC's
weights and horizon), ``pid.velocity``, ``pid.depth``, ``pid.yaw_rate`` (the body-frame
PIDs) and ``baseline`` (the baseline's gait)::

    register(Block("pid.depth", PidGains, "Depth PID", ("kp", "ki", "kd", "limit"),
                   initial=lambda c: c.body.depth,
                   apply=lambda loop, g: loop.body.pid("depth").set_gains(g),
                   configure=lambda c, g: c.replace(body=c.body.replace(depth=g)), label="depth "))
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import TYPE_CHECKING, Any, Callable, Protocol

from ucat_console.backend.loop.config import LoopConfig
from ucat_console.control.mpc import check_config
from ucat_console.control.params import BaselineConfig, MpcConfig, PidGains
from ucat_console.registry import Registry

if TYPE_CHECKING:
    from ucat_console.backend.loop.actuators import Actuators
    from ucat_console.control.body import BodyController

#: the body-frame PIDs, each a block "pid.<loop>"
PID_LOOPS = ("velocity", "depth", "yaw_rate")


class BlockTarget(Protocol):
    """What a block's ``apply`` reaches of the loop (``ClosedLoop``), in the loop's thread:
    the body-frame layer and the fins' actuators."""

    body: BodyController
    fins: Actuators


@dataclass(frozen=True)
class Block:
    """One tunable block of the loop (module docstring)."""

    name: str
    config: type  # the frozen config dataclass a value of the block is
    title: str  # the page's folder
    fields: tuple[str, ...]  # the fields tuned live (on the page, in the supervisor)
    #: the block's value in a loop configuration (where the loop starts)
    initial: Callable[[LoopConfig], Any]
    #: put a new value in force, in the loop's thread (from the loop's next event)
    apply: Callable[[BlockTarget, Any], None]
    #: the loop configuration holding a new value (the configuration in force, as saved with
    #: a recording); None: the block is not part of the loop's configuration
    configure: Callable[[LoopConfig, Any], LoopConfig] | None = None
    #: a check of a whole value beyond its fields' ranges (ValueError saying what is wrong)
    check: Callable[[Any], object] | None = None
    label: str = ""  # what the page writes before each field's name ("depth " for pid.depth)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name != self.name.strip():
            raise ValueError(f"block: expected a name, got {self.name!r}")
        if not (isinstance(self.config, type) and is_dataclass(self.config)):
            raise ValueError(f"block {self.name!r}: config must be a frozen config dataclass, got {self.config!r}")
        known = {f.name for f in fields(self.config)}
        unknown = [f for f in self.fields if f not in known]
        if not self.fields or unknown:
            raise ValueError(f"block {self.name!r}: fields {unknown or '()'} are not fields of "
                             f"{self.config.__name__} ({', '.join(sorted(known))})")
        for what in ("initial", "apply"):
            if not callable(getattr(self, what)):
                raise ValueError(f"block {self.name!r}: {what} must be callable")


#: every tunable block by name, in the order the page lists them
BLOCKS: Registry[Block] = Registry("block", Block)
#: add a block (its name must be new); returns it
register = BLOCKS.register
#: take a block out (a test's, or a plug-in's going away)
unregister = BLOCKS.unregister
#: the block called ``name``, else ValueError naming the blocks there are
block = BLOCKS.get_entry
#: the registered blocks' names, in the order registered (read live)
block_names = BLOCKS.names


def initial_blocks(cfg: LoopConfig) -> dict[str, Any]:
    """Every registered block's value in the loop configuration ``cfg``: name -> config."""
    return {name: entry.initial(cfg) for name, entry in BLOCKS.items()}


def _apply_mpc(loop: BlockTarget, cfg: MpcConfig) -> None:
    loop.fins.retune("mpc", cfg)  # the loop then sets the body layer's limits (``ClosedLoop.limit_fins``)


def _pid(name: str, title: str) -> Block:
    return Block(f"pid.{name}", PidGains, title, ("kp", "ki", "kd", "limit"),
                 initial=lambda c: getattr(c.body, name),
                 apply=lambda loop, gains: loop.body.pid(name).set_gains(gains),
                 configure=lambda c, gains: c.replace(body=c.body.replace(**{name: gains})),
                 label=f"{name} ")


register(Block("mpc", MpcConfig, "MPC weights and horizon",
               ("formulation", "lam_f", "lam_st", "lam_a", "lam_d", "lam_c", "lam_e", "st_opt", "st_low",
                "st_high", "n_samples", "c_d", "c_l"),
               initial=lambda c: c.mpc, apply=_apply_mpc, configure=lambda c, m: c.replace(mpc=m),
               check=check_config))
for _name, _title in zip(PID_LOOPS, ("Velocity PID", "Depth PID", "Yaw-rate PID")):
    register(_pid(_name, _title))
register(Block("baseline", BaselineConfig, "Baseline", ("frequency",),
               initial=lambda c: c.baseline, apply=lambda loop, b: loop.fins.retune("baseline", b),
               configure=lambda c, b: c.replace(baseline=b)))
