"""``twin hw arcos``: read the PeopleBot base's status or drive it briefly, over ARCOS.

Degrees and millimetres appear only here (flags as on the robot's own tools); the driver below
takes metres and radians. Works the same against the serial twin's pseudo-terminal.
"""

from __future__ import annotations

import argparse
import math

from twin.core.errors import InputError


def register(hw_subparsers: argparse._SubParsersAction) -> None:
    parser = hw_subparsers.add_parser(
        "arcos",
        help="ARCOS base (PeopleBot/Pioneer): status, or drive for a few seconds",
        description="Connect to the robot's base over its ARCOS serial protocol (SYNC handshake, "
        "OPEN), then print its status or drive it at a fixed speed and stop. CLOSE on exit.",
    )
    parser.add_argument("--port", required=True, help="serial port, e.g. /dev/ttyS0 or a twin pty")
    parser.add_argument("--baud", type=int, default=9600, help="baud rate (default 9600)")
    actions = parser.add_subparsers(dest="arcos_action", metavar="ACTION", required=True)
    status = actions.add_parser("status", help="handshake identity and one decoded SIP")
    status.set_defaults(handler=_status)
    drive = actions.add_parser("drive", help="drive at --vel and --rvel for --seconds, then stop")
    drive.add_argument("--vel", type=float, default=0.0, help="forward speed, mm/s")
    drive.add_argument("--rvel", type=float, default=0.0, help="turn rate, deg/s (CCW positive)")
    drive.add_argument("--seconds", type=float, required=True, help="how long, s")
    drive.set_defaults(handler=_drive)


def _describe(base: object) -> list[str]:
    from hardware.arcos import ArcosBase

    assert isinstance(base, ArcosBase)
    sip = base.last_sip
    assert sip is not None
    name, kind, subclass = base.identity or ("?", "?", "?")
    flags = [
        label
        for label, on in (
            ("motors enabled", sip.motors_enabled),
            ("sonar on", bool(sip.flags & 0x1E)),
            ("STOP button pressed", sip.estop),
            ("moving", sip.moving),
        )
        if on
    ]
    return [
        f"robot: {name}  class: {kind}  subclass: {subclass}",
        f"odometry: x={sip.x} mm  y={sip.y} mm (15-bit, wrapping)  "
        f"heading={math.degrees(sip.heading):.1f} deg",
        f"wheels: left {sip.left_vel} mm/s  right {sip.right_vel} mm/s",
        f"battery: {sip.battery:.1f} V",
        f"flags: 0x{sip.flags:04X} ({', '.join(flags) or 'none'})",
        f"stall/bumpers: {sip.fault() or 'clear'}",
    ]


def _status(args: argparse.Namespace) -> int:
    from hardware.arcos import ArcosBase

    with ArcosBase.open(args.port, args.baud, enable_motors=False) as base:
        print("\n".join(_describe(base)))
    return 0


def _drive(args: argparse.Namespace) -> int:
    from hardware.arcos import ArcosBase

    if not all(map(math.isfinite, (args.vel, args.rvel, args.seconds))) or args.seconds < 0:
        raise InputError(
            "twin hw arcos drive: --vel, --rvel and --seconds must be finite, "
            "--seconds not negative"
        )
    with ArcosBase.open(args.port, args.baud) as base:
        start = base.pose()
        pose = base.drive(args.vel / 1000.0, math.radians(args.rvel), args.seconds)
        print(
            f"drove {1000 * start.distance_to(pose):.0f} mm, turned "
            f"{math.degrees(start.heading_error_to(pose)):.1f} deg (odometry)"
        )
        print("\n".join(_describe(base)))
    return 0
