"""The seeker's search: Optuna's ask-and-tell over the configured bounds (docs/seek.md).

A live loop measures one candidate at a time, minutes apart: :class:`Search` asks Optuna's
TPE sampler (seeded, in-memory study) for the next candidate, and is told the candidate's
measured energy per metre, or that it failed (rejected for its tracking, no figures),
which the sampler then never rewards: a failed candidate is told as infeasible (TPE's
constraints: it always ranks below every feasible one, whatever the placeholder value it is
told with; ``Trial.set_constraint``), so that the sampler learns where not to go. Told as a failure instead
(Optuna's FAIL state, which TPE leaves out of its model), the sampler kept drawing gaits
too slow to hold the speed (docs/seek.md). The candidates are always inside the bounds given
(Optuna draws from the distributions made of them); an integer field gets integers.

Optuna is imported when a search is made, never with the console.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from ucat_console.backend.seek.config import SeekParam


#: the constraint every candidate carries (``Trial.set_constraint``): > 0, infeasible (it failed)
CONSTRAINT = "rejected"
#: the value a failed candidate is told with (ranked by its infeasibility, never by this)
FAILED_VALUE = 1e9


@dataclass(frozen=True)
class Dimension:
    """One parameter's bounds, and whether its field takes integers."""

    name: str
    lo: float
    hi: float
    integer: bool = False

    def holds(self, value: float) -> bool:
        return self.lo <= value <= self.hi


def dimensions(params: tuple[SeekParam, ...], integer: Mapping[str, bool] | None = None) -> tuple[Dimension, ...]:
    integer = integer or {}
    return tuple(Dimension(p.name, p.lo, p.hi, bool(integer.get(p.name, False))) for p in params)


class Search:
    """One search: ask a candidate, tell its result (module docstring)."""

    def __init__(self, dims: tuple[Dimension, ...], seed: int, startup: int = 5) -> None:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self._optuna = optuna
        self.dims = dims
        self._dists: dict[str, Any] = {
            d.name: (optuna.distributions.IntDistribution(math.ceil(d.lo), math.floor(d.hi)) if d.integer
                     else optuna.distributions.FloatDistribution(d.lo, d.hi))
            for d in dims}
        sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=startup, multivariate=len(dims) > 1)
        self.study = optuna.create_study(direction="minimize", sampler=sampler)

    def ask(self) -> tuple[Any, dict[str, float]]:
        """The next candidate: (its trial, name -> value), every value inside its bounds."""
        trial = self.study.ask(self._dists)
        return trial, dict(trial.params)

    def tell(self, trial: Any, value: float | None) -> None:
        """The candidate's energy per metre (J/m), or None: it failed (never rewarded)."""
        failed = value is None or not math.isfinite(value)
        trial.set_constraint(CONSTRAINT, 1.0 if failed else 0.0)
        self.study.tell(trial, FAILED_VALUE if failed else value)

    def add(self, values: Mapping[str, float], value: float | None) -> bool:
        """A candidate measured outside the search (the values in force at the start): added
        when every value is inside its bounds, so the search starts from it; whether it was."""
        if value is None or not math.isfinite(value) or set(values) != set(self._dists) or not all(
                d.holds(values[d.name]) for d in self.dims):
            return False
        params = {d.name: (int(values[d.name]) if d.integer else float(values[d.name])) for d in self.dims}
        self.study.add_trial(self._optuna.trial.create_trial(params=params, distributions=self._dists, value=value,
                                                             constraints={CONSTRAINT: 0.0}))
        return True
