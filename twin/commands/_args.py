"""Argument types shared by the subcommands: argparse reports their errors in one line."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def comma_list(kind: Callable[[str], T], what: str) -> Callable[[str], tuple[T, ...]]:
    """An argparse type for 'a,b,c' lists of ``kind`` (e.g. float), named ``what`` in errors."""

    def parse(text: str) -> tuple[T, ...]:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}")
        try:
            return tuple(kind(p) for p in parts)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a comma-separated list of {what}, got {text!r}"
            ) from None

    return parse


def numbers(count: int, what: str) -> Callable[[str], tuple[float, ...]]:
    """An argparse type for exactly ``count`` comma-separated numbers, e.g. 'X,Y,YAW'."""
    parse_list = comma_list(float, what)

    def parse(text: str) -> tuple[float, ...]:
        values = parse_list(text)
        if len(values) != count:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return values

    return parse


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """--config and --set, for every command that runs a mission config."""
    parser.add_argument(
        "--config",
        help="mission config: a TOML file, or the name of a shipped one (e.g. "
        "living_room_serial_twins); default: the shipped living-room survey",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one config key; VALUE is TOML, e.g. --set grid.fusion=normalized "
        "--set mission.views_per_stop=4 --set 'grid.extent=[0, 0, 4.5, 6]' (repeatable)",
    )
