"""The ``twin`` command: one subcommand per job, each registered by a module in ``twin.commands``.

Errors a user can cause (``TwinError``, or a file the system refuses) are printed as one line
and exit with status 2. Ctrl-C exits with 130 and SIGTERM with 143, both after the command has
written what it had (a survey its results so far, a batch its summary).
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
from collections.abc import Sequence

from twin import __version__
from twin.core.errors import Terminated, TwinError

# Each module defines ``register(subparsers)``; heavy imports happen inside the handlers so
# that ``twin --help`` stays fast.
COMMAND_MODULES: tuple[str, ...] = (
    "twin.commands.montecarlo",
    "twin.commands.rfch",
    "twin.commands.sim",
    "twin.commands.survey",
    "twin.commands.search",
    "twin.commands.hw",
    "twin.commands.serve_hardware",
    "twin.commands.batch_survey",
    "twin.commands.devices",
    "twin.commands.map",
    "twin.commands.calibrate",
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
    previous = _stop_on_sigterm()
    try:
        return int(args.handler(args) or 0)
    except TwinError as exc:
        print(f"twin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Terminated:
        print(f"twin {args.command}: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print(f"twin {args.command}: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT
    except OSError as exc:  # a file or folder the user named: no traceback, the path and why
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"twin {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _stop_on_sigterm():
    """Make SIGTERM unwind like Ctrl-C (``Terminated``), in the main thread only."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def terminate(signum, frame) -> None:
        raise Terminated()

    return signal.signal(signal.SIGTERM, terminate)


if __name__ == "__main__":
    sys.exit(main())
