"""``twin devices``: every device type a config can name, with its options (type, unit, default,
range), as ``twin.app.device_types`` declares them."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "devices",
        help="list the device types a config's [robot.*] tables can name, with their options",
        description="For each role (camera, pantilt, base) the types a config can give, and "
        "each type's options: what they are, their unit, default and range.",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    print(describe())
    return 0


def describe() -> str:
    import dataclasses
    import json

    from twin.app.device_types import DEVICE_TYPES, OPTIONAL_ROLES, ROLES
    from twin.core.options import describe_options

    lines = []
    for role in (*ROLES, *OPTIONAL_ROLES):
        for (r, name), declared in sorted(DEVICE_TYPES.items()):
            if r != role:
                continue
            lines.append(f'[robot.{role}] type = "{name}": {declared.summary}')
            for info in describe_options(declared.options):
                if info.default is dataclasses.MISSING:
                    default = "required"
                elif info.default is None:
                    default = "not set by default"
                else:
                    default = "default " + json.dumps(info.default)
                lines.append(f"    {info.name}: {info.expected()}, {default}. {info.doc}")
            lines.append("")
    return "\n".join(lines).rstrip()
