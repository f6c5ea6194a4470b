"""Speed of the simulated plant: ``python -m ucat_console.backend.sim.bench [seconds]``."""

from __future__ import annotations

import sys

from ucat_console.backend.sim.plant import measure_realtime_factor


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    seconds = float(args[0]) if args else 20.0
    for chunk, sensors in ((0.01, True), (0.01, False), (1.0, False)):
        factor = measure_realtime_factor(seconds, chunk_s=chunk, sensors=sensors)
        label = f"chunks of {chunk * 1000:.0f} ms, sensors {'on' if sensors else 'off'}"
        print(f"plant alone, {label}: {factor:,.0f}x real time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
