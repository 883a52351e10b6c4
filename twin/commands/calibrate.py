"""``twin calibrate``: the camera's intrinsics and lens distortion from views of a chessboard,
written into the config's ``[robot.camera]`` table (see ``twin.app.calibrate``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from twin.commands._args import add_config_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="calibrate the camera from chessboard views (OpenCV) into the config",
        description="Grab --frames frames from the config's camera (in the twin's calibration "
        "stage, --config calibration_board, the board moves itself; with a real camera, move "
        "the board between grabs) or read every image in --images, find the chessboard's "
        "inner corners, fit the lens (fx, fy, cx, cy, k1, k2, p1, p2) and report the RMS "
        "reprojection error and field of view. The intrinsics and distortion are written into "
        "[robot.camera] of --into (default: the --config file), keeping its comments; a "
        "shipped config is never written: give --into a copy.",
    )
    add_config_arguments(parser)
    parser.add_argument("--images", type=Path, help="calibrate from this folder of images")
    parser.add_argument(
        "--pattern", default="9x6", help="the board's inner corners, COLSxROWS (9x6)"
    )
    parser.add_argument(
        "--square", type=float, default=0.06, help="side of a square, m (0.06; poses only)"
    )
    parser.add_argument("--frames", type=int, default=20, help="frames to grab (20)")
    parser.add_argument(
        "--interval", type=float, default=2.0, help="seconds between grabs, real camera (2)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the twin's board poses")
    parser.add_argument("--into", type=Path, help="the config file to write the result into")
    parser.add_argument("--dry-run", action="store_true", help="report only, write nothing")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from twin.app.calibrate import (
        calibrate,
        frames_from_camera,
        frames_from_folder,
        parse_pattern,
        write_calibration,
    )
    from twin.app.config import load_config, resolve_config
    from twin.core.errors import InputError
    from twin.resources import scenes_dir

    pattern = parse_pattern(args.pattern)
    if not 0.0 < args.square <= 1.0:
        raise InputError(f"--square must be in (0, 1] m, got {args.square}")
    if not 5 <= args.frames <= 500:
        raise InputError(f"--frames must be in [5, 500], got {args.frames}")
    if args.interval < 0.0:
        raise InputError(f"--interval must be >= 0 s, got {args.interval}")
    target = _target(args, resolve_config, scenes_dir(), InputError)
    if args.images is not None:
        frames, source = frames_from_folder(args.images), f"{args.images}"
    else:
        config = load_config(args.config, overrides=tuple(args.set))
        frames, source = _grab(config, args, frames_from_camera), f"{args.frames} frames grabbed"
    result = calibrate(frames, pattern, args.square)
    print(result.summary())
    if target is None:
        print("nothing written (--dry-run, or --images without --config/--into)")
        return 0
    write_calibration(target, result, source)
    print(f"wrote intrinsics and distortion into [robot.camera] of {target}")
    camera_type = _camera_type(target)
    if camera_type == "sim":
        print('the twin uses them once [robot.camera] says lens_model = "calibrated"')
    return 0


def _target(args: argparse.Namespace, resolve_config, shipped: Path, error) -> Path | None:
    """The config file the result goes into, or None (report only)."""
    if args.dry_run:
        return None
    if args.into is not None:
        if not args.into.is_file():
            raise error(f"--into {args.into}: no such file; give an existing config to write into")
        return args.into
    if args.images is not None and args.config is None:
        return None
    path = resolve_config(args.config).resolve()
    if path.parent == shipped.resolve():
        raise error(
            f"--config {args.config}: is a shipped config, which calibrate never edits; copy it "
            "and give the copy as --into (or use --dry-run)"
        )
    return path


def _grab(config, args: argparse.Namespace, frames_from_camera) -> list:
    from twin.app.factory import build_camera

    camera, context = build_camera(config)  # the camera alone: no base or head port opened
    try:
        with camera:
            return frames_from_camera(
                camera, context.sim_in_use, args.frames, args.interval, args.seed, print
            )
    finally:
        context.close()


def _camera_type(path: Path) -> str | None:
    import tomllib

    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))["robot"]["camera"].get("type")
    except (OSError, tomllib.TOMLDecodeError, KeyError, AttributeError):
        return None
