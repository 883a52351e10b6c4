"""``twin hw lms``: the SICK LMS200 laser scanner from the shell: what it is, or one scan.

Degrees appear only here (the scanner's own unit): -90 is the rightmost beam, +90 the leftmost,
counter-clockwise as in the project's API. ``scan --json`` prints exactly one JSON object,
``{"angles_deg": [...], "ranges_m": [...]}``, with ``null`` where a beam saw nothing, for other
tools to read. Works the same against the serial twin's pseudo-terminal.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np


def register(hw_subparsers: argparse._SubParsersAction) -> None:
    parser = hw_subparsers.add_parser(
        "lms",
        help="SICK LMS200 laser scanner: status, or one scan",
        description="Connect to a SICK LMS200 (LMS2xx) laser scanner on a serial port: find its "
        "baud rate, switch it to --baud, set the variant and units, start its scan stream; then "
        "print what it is or one scan. On exit the stream is stopped and the scanner put back "
        "at 9600 baud.",
    )
    parser.add_argument(
        "--port", required=True, help="serial port, e.g. /dev/ttyUSB0 or a twin pty"
    )
    parser.add_argument(
        "--baud",
        type=int,
        default=38400,
        choices=(9600, 19200, 38400, 500000),
        help="rate to stream at (default 38400: 10 scans/s at 1 deg)",
    )
    parser.add_argument(
        "--resolution",
        type=float,
        default=1.0,
        choices=(1.0, 0.5),
        help="degrees between beams over 180 deg: 1 (181 beams, default) or 0.5 (361)",
    )
    parser.add_argument("--units", choices=("mm", "cm"), default="mm", help="range units (mm)")
    parser.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for a scan")
    actions = parser.add_subparsers(dest="lms_action", metavar="ACTION", required=True)
    actions.add_parser("status", help="type, variant, units, baud rate and mode")
    scan = actions.add_parser("scan", help="one fresh scan")
    scan.add_argument(
        "--json",
        action="store_true",
        help='print {"angles_deg": [...], "ranges_m": [...]} (null: no return)',
    )
    parser.set_defaults(handler=run)


def _status_lines(laser: object) -> list[str]:
    from hardware.lms2xx import LMS2xx

    assert isinstance(laser, LMS2xx) and laser.info is not None
    info = laser.info
    units = laser.units.name.lower()
    return [
        f"type: {info.type}",
        f"software: {info.status.software_version}, boot PROM {info.status.boot_version}, "
        f"serial {info.status.serial}",
        f"variant: {laser.variant}",
        f"units: {units} (measuring mode {laser.measuring_mode:02X}, ranges up to "
        f"{laser.max_range:.2f} m)",
        f"baud: {laser.baud} (found at {info.found_baud})",
        "mode: continuous output (20 24)",
    ]


def _summary(angles_deg: np.ndarray, ranges: np.ndarray) -> str:
    hit = np.isfinite(ranges)
    text = (
        f"{len(ranges)} beams from {angles_deg[0]:+.1f} to {angles_deg[-1]:+.1f} deg: "
        f"{int(hit.sum())} returns"
    )
    if hit.any():
        near, far = np.nanargmin(ranges), np.nanargmax(ranges)
        text += (
            f", nearest {ranges[near]:.3f} m at {angles_deg[near]:+.1f} deg, farthest "
            f"{ranges[far]:.3f} m at {angles_deg[far]:+.1f} deg"
        )
    return text + f"; no return at {int((~hit).sum())} beams"


def run(args: argparse.Namespace) -> int:
    from hardware.lms2xx import LMS2xx
    from twin.core.errors import InputError

    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise InputError(f"twin hw lms: --timeout must be a positive number, got {args.timeout}")
    laser = LMS2xx.open(args.port, baud=args.baud, resolution=args.resolution, units=args.units)
    with laser:
        if args.lms_action == "status":
            print("\n".join(_status_lines(laser)))
            return 0
        scan = laser.scan(timeout=args.timeout)
    angles = np.round(np.degrees(scan.angles), 6)
    if args.json:
        ranges = [round(float(r), 4) if math.isfinite(r) else None for r in scan.ranges]
        print(json.dumps({"angles_deg": [float(a) for a in angles], "ranges_m": ranges}))
    else:
        print(_summary(angles, scan.ranges))
    return 0
