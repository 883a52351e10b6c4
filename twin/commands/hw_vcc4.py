"""``twin hw vcc4``: initialise, move, zoom and read the Canon VC-C4 head from the shell.

Degrees here (the user's unit), pan positive LEFT as everywhere in the project; the driver
converts to the camera's right-positive counts. ``--via-aux`` reaches a camera on the robot's
AUX1 port through the ARCOS base on ``--port``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Iterator
from typing import Any

from twin.core.errors import InputError


def register(hw_subparsers: argparse._SubParsersAction) -> None:
    parser = hw_subparsers.add_parser(
        "vcc4",
        help="Canon VC-C4 pan-tilt-zoom head: init, goto, zoom, position",
        description="Talk to a Canon VC-C4 on a serial port (or on the robot's AUX1 port with "
        "--via-aux). Angles in degrees, pan positive to the left, tilt positive up.",
    )
    parser.add_argument(
        "--port",
        required=True,
        help="serial port (e.g. /dev/ttyUSB0, or a path printed by 'twin serve-hardware')",
    )
    parser.add_argument(
        "--via-aux",
        action="store_true",
        help="the camera hangs off the robot's AUX1: open the ARCOS base on PORT",
    )
    parser.add_argument(
        "--baud",
        type=int,
        default=9600,
        help="baud rate of PORT (the camera, or the base with --via-aux; 9600)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=20.0,
        help="seconds to wait for a move or zoom (default 20)",
    )
    sub = parser.add_subparsers(dest="vcc4_action", metavar="ACTION", required=True)
    sub.add_parser("init", help="host control, camera on, pedestal calibration, speeds, range")
    goto = sub.add_parser("goto", help="move to PAN TILT (degrees) and wait until there")
    goto.add_argument("pan", type=float, help="degrees, positive left")
    goto.add_argument("tilt", type=float, help="degrees, positive up")
    goto.add_argument("--speed", type=float, default=None, help="degrees/s (default: top speed)")
    zoom = sub.add_parser("zoom", help="zoom to Z (0 = wide end .. the unit's maximum)")
    zoom.add_argument("z", type=int)
    sub.add_parser("position", help="print pan and tilt (degrees) and the zoom")
    parser.set_defaults(handler=run)


@contextlib.contextmanager
def _camera(args: argparse.Namespace) -> Iterator[Any]:
    from hardware.vcc4 import VCC4

    if not args.via_aux:
        camera = VCC4.open(args.port, baudrate=args.baud)
        with camera:
            yield camera
        return
    try:
        from hardware.arcos import ArcosBase
    except ImportError:
        ArcosBase = None
    if ArcosBase is None or not hasattr(ArcosBase, "aux_transport"):
        raise InputError(
            "--via-aux needs the ARCOS driver (hardware/arcos.py with "
            "ArcosBase.aux_transport), which this installation lacks; wire the "
            "camera to a serial port and drop --via-aux"
        )
    base = ArcosBase.open(args.port, baudrate=args.baud)
    with base:
        camera = VCC4(base.aux_transport(1), answer_timeout=1.0)
        with camera:
            yield camera


def run(args: argparse.Namespace) -> int:
    with _camera(args) as camera:
        action = args.vcc4_action
        if action == "init":
            camera.initialize(pedestal=True)
            print(
                "initialised: host control, camera on, pedestal calibrated, top speeds, "
                "tilt range -30..+90 deg"
            )
        elif action == "goto":
            speed = None if args.speed is None else math.radians(args.speed)
            pan, tilt = camera.move_to(
                math.radians(args.pan), math.radians(args.tilt), speed=speed, timeout=args.timeout
            )
            print(f"pan {math.degrees(pan):.2f} deg, tilt {math.degrees(tilt):.2f} deg")
        elif action == "zoom":
            print(f"zoom {camera.zoom_to(args.z, timeout=args.timeout)}")
        else:
            pan, tilt = camera.position()
            print(
                f"pan {math.degrees(pan):.2f} deg, tilt {math.degrees(tilt):.2f} deg "
                f"(pan positive left), zoom {camera.zoom()}"
            )
    return 0
