"""``twin serve-hardware``: the robot's serial twins on pseudo-terminals, for any client.

The emulated ARCOS base and Canon VC-C4 speak their wire protocols byte for byte and drive the
MuJoCo world, which steps in wall-clock time; with ``--laser`` an emulated SICK LMS200 scans the
world too. Point the drivers (``twin hw …``, a survey config with those ports) or your own tools
(ARIA, minicom) at the printed paths.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "serve-hardware",
        help="run the serial twins (ARCOS base, VC-C4, SICK laser) on pseudo-terminals",
        description="Start the MuJoCo twin and the emulated ARCOS base and VC-C4 (and with "
        "--laser a SICK LMS200) on pseudo-terminals, print their paths, and serve until Ctrl-C "
        "(or --seconds).",
    )
    parser.add_argument("--scene", default="living_room", help="scene name or MJCF path")
    parser.add_argument(
        "--time-scale",
        type=float,
        default=1.0,
        help="simulated seconds per wall-clock second (1.0: real time)",
    )
    parser.add_argument(
        "--vcc4-wiring",
        choices=("direct", "aux"),
        default="direct",
        help="the VC-C4 on its own line, or behind the base's AUX1 port",
    )
    parser.add_argument(
        "--link-dir",
        type=Path,
        default=Path("runs/twins"),
        help="stable symlinks 'arcos', 'vcc4' and 'lms2xx' to the pseudo-terminals",
    )
    parser.add_argument(
        "--laser",
        action="store_true",
        help="also offer an emulated SICK LMS200 ('lms2xx'); its ranges are ray-cast in the "
        "scene's floor plan (walls, furniture outlines) from the robot's true pose",
    )
    parser.add_argument("--seconds", type=float, default=None, help="stop after this long")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from twin.core.errors import InputError
    from twin.serial_twins.session import SerialTwins
    from twin.sim import SimRobot, World
    from twin.sim.laser import SimLaser

    if not 0.0 < args.time_scale <= 20.0:
        raise InputError(f"--time-scale must be in (0, 20], got {args.time_scale}")
    sim = SimRobot(World(args.scene))
    # the emulated scanner reads the MuJoCo laser: what stands at 0.30 m, with the LMS200's noise
    laser = SimLaser(sim).ranges_at if args.laser else None
    with SerialTwins(
        sim, args.time_scale, args.vcc4_wiring, args.link_dir, laser_source=laser
    ) as twins:
        print(f"ARCOS base:  {twins.arcos_path} -> {Path(twins.arcos_path).resolve()}")
        if twins.vcc4_path is not None:
            print(f"VC-C4 head:  {twins.vcc4_path} -> {Path(twins.vcc4_path).resolve()}")
        else:
            print("VC-C4 head:  on the base's AUX1 port (twin hw vcc4 --via-aux --port ARCOS)")
        if twins.lms2xx_path is not None:
            print(f"SICK LMS200: {twins.lms2xx_path} -> {Path(twins.lms2xx_path).resolve()}")
        print(f"world at {args.time_scale:g}x real time; serving until Ctrl-C", flush=True)
        deadline = None if args.seconds is None else time.monotonic() + args.seconds
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.2)
    return 0
