"""``ucat-console config``: the configuration's JSON Schema, for editors (docs/configuration.md,
Editor support).

    ucat-console config schema                    # print it
    ucat-console config schema --out FILE         # write it (the shipped one: below)

After a change of the configuration's fields, the shipped schema is written again with
``ucat-console config schema --out ucat_console/configs/ucat-console.schema.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help="the configuration's JSON Schema (for editors)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    schema = actions.add_parser("schema", help="print the configuration's JSON Schema, or write it to a file")
    schema.add_argument("--out", default=None, metavar="FILE", help="write it to this file instead of printing it")
    schema.set_defaults(func=run_schema)


def run_schema(args: argparse.Namespace) -> int:
    from ucat_console.config_schema import schema_text

    text = schema_text()
    if args.out is None:
        print(text, end="")
        return 0
    out = Path(args.out)
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}")
    return 0
