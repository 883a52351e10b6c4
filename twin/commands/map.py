"""``twin map``: the map a robot localizes on, built from its laser while it drives, or (in the
twin) cut from the scene at the laser's height; written in the ROS map_server format."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from twin.commands._args import add_config_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "map",
        help="build the occupancy map the laser localizes on (map_server YAML + PGM)",
        description="Drive the config's robot along the mission's stops on its raw odometry, "
        "scanning in short steps and turning on the spot at each stop, match every scan to the "
        "map so far and write the map (OUT.yaml beside OUT.pgm, and OUT.report.json). In the "
        "twin the report scores the map against the scene's own and the drive's drift. With "
        "--from-scene, cut the map from the twin's scene at the laser's height instead.",
    )
    add_config_arguments(parser)
    parser.add_argument("--out", type=Path, required=True, help="the map to write (NAME.yaml)")
    parser.add_argument(
        "--from-scene", action="store_true", help="cut the map from the scene (the twin only)"
    )
    parser.add_argument("--resolution", type=float, default=0.05, help="cell size, m (0.05)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from twin.app.config import load_config
    from twin.app.make_map import (
        build_map,
        map_extent,
        mapping_config,
        route_of,
        score_against_scene,
        write_map,
    )
    from twin.app.outputs import check_output_file
    from twin.core.errors import InputError

    if args.out.suffix != ".yaml":
        raise InputError(f"--out {args.out}: give the map's YAML file name, e.g. living_room.yaml")
    check_output_file(args.out, "--out")
    for existing in (args.out, args.out.with_suffix(".pgm")):
        if existing.exists():
            raise InputError(
                f"--out {args.out}: {existing} exists; a map is never overwritten, choose "
                "another name or remove it"
            )
    if not (0.01 <= args.resolution <= 0.5):
        raise InputError(f"--resolution must be in [0.01, 0.5] m, got {args.resolution}")
    say = (lambda _: None) if args.quiet else print
    config = load_config(args.config, overrides=tuple(args.set))
    if args.from_scene:
        return _from_scene(config, args, say)
    config = mapping_config(config)
    from twin.app.factory import build_robot

    robot, context = build_robot(config)
    try:
        sim = None
        with robot:
            sim = context.sim_in_use
            truth = sim.truth_pose if sim is not None else None
            built, report = build_map(
                robot, route_of(config), map_extent(config), args.resolution, truth, say
            )
        if sim is not None:
            from twin.sim.scene_map import scene_map

            reference = scene_map(sim.world, robot.laser.mount.z, args.resolution)
            report.agreement = score_against_scene(built, reference)
    finally:
        context.close()
    path = write_map(args.out, built, report)
    say(json.dumps(report.to_json()))
    say(f"wrote {path} and {path.with_suffix('.pgm')}")
    return 0


def _from_scene(config, args: argparse.Namespace, say) -> int:
    from twin.app.make_map import write_map
    from twin.core.errors import InputError
    from twin.sim import World
    from twin.sim.scene_map import scene_map

    laser = config.devices.get("laser")
    if not config.uses_sim_world:
        raise InputError("--from-scene cuts the twin's scene; this config drives the real robot")
    height = 0.30
    if laser is not None and laser.type == "lms2xx":
        height = laser.options.mount[2]
    path = write_map(args.out, scene_map(World(config.scene), height, args.resolution))
    say(f"wrote {path} and {path.with_suffix('.pgm')} (the scene cut at {height:.2f} m)")
    return 0
