"""``ucat-console manoeuvres``: the scripted manoeuvres (docs/manoeuvres.md).

    ucat-console manoeuvres list                  # the shipped ones, each with its plan
    ucat-console manoeuvres show my-ladder.toml   # a file checked, and its plan
    ucat-console run --headless --manoeuvre e4_ladder

A manoeuvre is checked against the configuration's limits (``--config``: the loop's
envelope and modes) as a run would check it.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("manoeuvres", help="list the shipped scripted manoeuvres, or check one")
    p.add_argument("action", choices=("list", "show"), help="list: the shipped ones; show: one, checked")
    p.add_argument("manoeuvre", nargs="?", default=None, metavar="NAME|FILE", help="with show: the manoeuvre")
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help="check against this configuration's limits (a shipped one's name or a TOML file)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ucat_console import shipped
    from ucat_console.backend.manoeuvre_files import load_script, shipped_plans
    from ucat_console.config import load_config
    from ucat_console.control.scripted import plan

    loop = load_config(args.config).loop
    if args.action == "show":
        if args.manoeuvre is None:
            raise ValueError("manoeuvres show: name a manoeuvre (a shipped one's name or a TOML file)")
        print(plan(load_script(args.manoeuvre, loop)))
        return 0
    if args.manoeuvre is not None:
        raise ValueError("manoeuvres list: takes no manoeuvre (use `manoeuvres show NAME|FILE`)")
    print(f"shipped manoeuvres ({shipped.manoeuvres_dir()}):")
    for name, text in shipped_plans(loop):
        print(f"\n[{name}]  ucat-console run --headless --manoeuvre {name}\n{text}")
    return 0
