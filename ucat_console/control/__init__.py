"""The functional core: fin model, Strouhal-aware MPC, baseline, body-frame layer.

No threads, clocks or I/O here: time is an argument.
"""

from ucat_console.control.params import (
    BaselineConfig,
    BodyConfig,
    ExecutorConfig,
    MpcConfig,
    PidGains,
    PowerConfig,
)

__all__ = [
    "BaselineConfig",
    "BodyConfig",
    "ExecutorConfig",
    "MpcConfig",
    "PidGains",
    "PowerConfig",
]

from ucat_console.control.cost import CostBreakdown  # noqa: E402
from ucat_console.control.mpc import FinMpc, Plan  # noqa: E402

__all__ += ["CostBreakdown", "FinMpc", "Plan"]
