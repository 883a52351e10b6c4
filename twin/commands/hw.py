"""``twin hw``: talk to the real robot's devices (or to their serial twins) from the shell.

Each device's subcommand lives in its own module with ``register(hw_subparsers)``.
"""

from __future__ import annotations

import argparse
import importlib

HW_MODULES: tuple[str, ...] = (
    "twin.commands.hw_probe",
    "twin.commands.hw_vcc4",
    "twin.commands.hw_arcos",
    "twin.commands.hw_lms",
)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "hw",
        help="probe and drive the real devices (VC-C4 head, ARCOS base, SICK laser, cameras)",
        description="Commands for users at the robot: probe serial ports and cameras, move the "
        "VC-C4 head, drive the ARCOS base, read the SICK LMS200 laser. They work the same "
        "against the serial twins (twin serve-hardware).",
    )
    hw = parser.add_subparsers(dest="hw_command", metavar="DEVICE", required=True)
    for module_name in HW_MODULES:
        importlib.import_module(module_name).register(hw)
