"""The ``twin`` command: one subcommand per job, each registered by a module in ``twin.commands``.

Errors a user can cause (``TwinError``) are printed as one line and exit with status 2; an
interrupt exits with 130 after whatever was already written atomically stays written.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from twin import __version__
from twin.core.errors import TwinError

# Each module defines ``register(subparsers)``; heavy imports happen inside the handlers so
# that ``twin --help`` stays fast.
COMMAND_MODULES: tuple[str, ...] = (
    "twin.commands.montecarlo",
    "twin.commands.rfch",
    "twin.commands.sim",
    "twin.commands.survey",
    "twin.commands.hw",
    "twin.commands.serve_hardware",
    "twin.commands.batch_survey",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="twin",
        description="Bearing-only object localization: the accumulator grid, its Monte Carlo "
        "evaluation, the RFCH detector and the MuJoCo twin of a Peoplebot.",
    )
    parser.add_argument("--version", action="version", version=f"twin {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except TwinError as exc:
        print(f"twin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"twin {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
