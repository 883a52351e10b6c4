"""``twin sim``: look through the twin robot's eyes, drive it, and make the contact sheet.

Degrees appear only here, at the command line; everything below takes radians.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from twin.core.errors import InputError
from twin.core.geometry import Pose2D


def parse_pose(text: str, flag: str) -> Pose2D:
    """'X,Y,YAW_DEG' -> Pose2D (metres, radians)."""
    parts = text.split(",")
    try:
        x, y, yaw_deg = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"{flag} {text!r}: expected X,Y,YAW_DEG, e.g. 2.0,3.0,90") from None
    if not all(map(math.isfinite, (x, y, yaw_deg))):
        raise InputError(f"{flag} {text!r}: values must be finite numbers")
    return Pose2D(x, y, math.radians(yaw_deg))


def _degrees(text: str, flag: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{flag} {text!r}: expected an angle in degrees, e.g. 30") from None
    if not math.isfinite(value):
        raise InputError(f"{flag} {text!r}: must be a finite number of degrees")
    return math.radians(value)


def _fmt(pose: Pose2D) -> str:
    return f"x={pose.x:.3f} m  y={pose.y:.3f} m  yaw={math.degrees(pose.yaw):7.2f} deg"


def _error(a: Pose2D, b: Pose2D) -> str:
    return f"{100 * a.distance_to(b):.1f} cm, {abs(math.degrees(a.heading_error_to(b))):.2f} deg"


def _snapshot(args: argparse.Namespace) -> int:
    from twin.app.outputs import check_output_file

    check_output_file(Path(args.out), "--out")
    pose = parse_pose(args.pose, "--pose")
    pan, tilt = _degrees(args.pan, "--pan"), _degrees(args.tilt, "--tilt")
    from twin.sim.render import write_png
    from twin.sim.robot import ROBOT_CLEARANCE, SimRobot
    from twin.sim.world import World

    world = World(args.scene)
    world.check_free(pose.x, pose.y, ROBOT_CLEARANCE, "--pose")
    robot = SimRobot(world, pose)
    with robot.devices() as devices:
        devices.pantilt.move_to(pan, tilt)
        view = devices.capture()
    out = write_png(args.out, view.image)
    print(
        f"{out}: {view.image.shape[1]}x{view.image.shape[0]} from {_fmt(view.pose)}, "
        f"pan {math.degrees(view.pan):.1f} deg, tilt {math.degrees(view.tilt):.1f} deg"
    )
    return 0


def _drive(args: argparse.Namespace) -> int:
    goal = parse_pose(args.to, "--to")
    start = None if args.start is None else parse_pose(args.start, "--from")
    from twin.sim.robot import ROBOT_CLEARANCE, SimBase, SimRobot
    from twin.sim.world import World

    world = World(args.scene)
    world.check_free(goal.x, goal.y, ROBOT_CLEARANCE, "--to")
    if start is not None:
        world.check_free(start.x, start.y, ROBOT_CLEARANCE, "--from")
    robot = SimRobot(world, start)
    print(f"start     {_fmt(robot.truth_pose())}")
    sim0, wall0 = world.time, time.perf_counter()
    with SimBase(robot) as base:  # the base alone: no camera, so no GL context to open
        base.go_to(goal, timeout=args.timeout)
        odometry = base.pose()
    wall = time.perf_counter() - wall0
    truth = robot.truth_pose()
    print(f"goal      {_fmt(goal)}")
    print(f"odometry  {_fmt(odometry)}   off goal {_error(odometry, goal)}")
    print(f"truth     {_fmt(truth)}   off goal {_error(truth, goal)}")
    print(f"odometry vs truth: {_error(odometry, truth)}")
    print(
        f"simulated {world.time - sim0:.2f} s in {wall:.2f} s wall "
        f"({(world.time - sim0) / max(wall, 1e-9):.0f}x real time)"
    )
    return 0


def _contact_sheet(args: argparse.Namespace) -> int:
    from twin.app.outputs import check_output_file

    if not 0.1 <= args.scale <= 1.0:
        raise InputError(f"--scale {args.scale}: must be within [0.1, 1]")
    check_output_file(Path(args.out), "--out")
    from twin.sim.sheet import make_contact_sheet

    out = make_contact_sheet(args.out, args.scene, scale=args.scale)
    print(f"{out}: 8 views from each of 5 stops")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sim", help="the MuJoCo twin: snapshots, driving, contact sheet", description=__doc__
    )
    commands = parser.add_subparsers(dest="sim_command", metavar="SIM_COMMAND", required=True)

    def scene_flag(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--scene",
            default="living_room",
            help="scene name in scenes/ or an MJCF path (default: living_room)",
        )

    snap = commands.add_parser("snapshot", help="render the robot camera's view from a pose")
    snap.add_argument(
        "--pose",
        required=True,
        metavar="X,Y,YAW_DEG",
        help="robot pose: metres and degrees in the map frame",
    )
    snap.add_argument("--pan", default="0", metavar="DEG", help="pan, positive left (default 0)")
    snap.add_argument("--tilt", default="0", metavar="DEG", help="tilt, positive up (default 0)")
    snap.add_argument("--out", required=True, metavar="PNG", help="where to write the image")
    scene_flag(snap)
    snap.set_defaults(handler=_snapshot)

    drive = commands.add_parser("drive", help="drive to a pose; report odometry against truth")
    drive.add_argument("--to", required=True, metavar="X,Y,YAW_DEG", help="goal pose")
    drive.add_argument(
        "--from",
        dest="start",
        metavar="X,Y,YAW_DEG",
        help="start pose (default: the scene's start)",
    )
    drive.add_argument(
        "--timeout", type=float, default=60.0, help="simulated seconds allowed (default 60)"
    )
    scene_flag(drive)
    drive.set_defaults(handler=_drive)

    sheet = commands.add_parser(
        "contact-sheet", help="8 views from each of 5 stops, tiled into one PNG"
    )
    sheet.add_argument("--out", default="docs/contact_sheet.png", metavar="PNG")
    sheet.add_argument("--scale", type=float, default=0.5, help="tile scale, 0.1-1 (default 0.5)")
    scene_flag(sheet)
    sheet.set_defaults(handler=_contact_sheet)
