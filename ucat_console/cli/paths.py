"""``ucat-console paths``: where the console writes its recordings and its compiled code, and
where the files it ships are (the configurations ``--config`` takes by name and their JSON Schema, the Foxglove
layout).

    ucat-console paths
    ucat-console paths --config my-pool.toml     # the sessions folder that configuration uses
"""

from __future__ import annotations

import argparse
import os


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("paths", help="where recordings and compiled code go; the shipped configurations and Foxglove layout")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="the configuration whose sessions folder to show")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console import compiled_cache, shipped
    from ucat_console.backend.sessions import files
    from ucat_console.config import load_config
    from ucat_console.config_schema import schema_path

    configured = load_config(args.config).console.sessions_dir
    if configured:
        why = f"console.sessions_dir of {args.config}"
    elif os.environ.get(files.SESSIONS_ENV):
        why = f"${files.SESSIONS_ENV}"
    else:
        why = f"the user's data folder; ${files.SESSIONS_ENV} or run --sessions-dir choose another"
    rows = [("sessions", f"{files.sessions_dir(configured or None)}  ({why})")]
    _, base_why = compiled_cache.base_and_reason()
    rows.append(("compiled code", f"{compiled_cache.cache_dir()}  ({base_why})"))
    rows += [(f"config {name}", str(shipped.config_path(name))) for name in shipped.config_names()]
    rows.append(("config schema", str(schema_path())))
    rows.append(("foxglove layout", str(shipped.foxglove_layout())))
    width = max(len(label) for label, _ in rows) + 2
    for label, value in rows:
        print(f"{label:<{width}}{value}")
    return 0
