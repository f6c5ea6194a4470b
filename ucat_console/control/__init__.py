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
