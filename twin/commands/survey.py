"""``twin survey``: the paper's mission end to end — the project's main job.

A fresh run writes into a new time-stamped folder (below ``run.out``, or ``--out DIR``
exactly); the config it really runs with (``--set`` overrides included) is written there, so
``twin survey --resume DIR`` continues exactly that run after an interruption.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from twin.commands._args import add_config_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "survey",
        help="run the survey mission (default: the paper's, in the simulated living room)",
        description="Visit the mission's stops, look around, score every frame with RFCH and "
        "fuse the bearing wedges into the accumulator grid; write result.json, grid PNGs and a "
        "Rerun recording. Without --config, runs the shipped living-room mission in the twin.",
    )
    add_run_arguments(parser)
    parser.set_defaults(handler=run, mission="survey")


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of a mission run (``twin survey`` and ``twin search``)."""
    add_config_arguments(parser)
    parser.add_argument("--out", type=Path, help="output folder (default: a new one in run.out)")
    parser.add_argument("--resume", type=Path, metavar="DIR", help="continue the run in DIR")
    parser.add_argument(
        "--place-target",
        choices=("config", "random"),
        default="config",
        help="random: put the target on a random furniture top (simulation only)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed for --place-target random")
    parser.add_argument(
        "--rerun",
        choices=("save", "spawn", "serve", "off"),
        help="Rerun mode (default: the config's run.rerun)",
    )
    parser.add_argument(
        "--rerun-bind",
        default="127.0.0.1",
        help="address the 'serve' mode listens on (default: localhost only)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no summary")


def run(args: argparse.Namespace) -> int:
    from twin.app.run import resume_run, run_mission, start_run
    from twin.core.errors import InputError

    started = time.perf_counter()
    if args.resume is not None:
        if args.config is not None or args.out is not None or args.set:
            also = ", --planner" if args.mission == "search" else ""
            raise InputError(
                "--resume DIR continues a run with its own config and folder; "
                f"drop --config, --set{also} and --out"
            )
        prepared = resume_run(args.resume)
        if isinstance(prepared, dict):
            print(
                f"{args.resume} is a finished run ({prepared.get('views', '?')} views); "
                "nothing to resume, nothing changed. Start a new run to survey again."
            )
            return 0
    else:
        prepared = start_run(
            args.config,
            tuple(args.set),
            args.out,
            args.place_target,
            args.seed,
            args.rerun,
            args.rerun_bind,
            args.mission,
        )
    out = prepared.folder
    run_mission(
        prepared,
        resume=args.resume is not None,
        started=started,
        quiet=args.quiet,
        on_result=None if args.quiet else lambda result: print_summary(out, result),
    )
    return 0


def print_summary(out: Path, result: dict) -> None:
    for name, entry in result["objects"].items():
        x, y, *z = entry["estimate_m"]
        height = f", {z[0]:.2f}" if z and z[0] is not None else ""
        line = f"{name}: estimate ({x:.2f}, {y:.2f}{height}) m, peak {entry['peak']:.2f}"
        ratio = entry["peak_ratio"]
        line += f", first/second peak {ratio:.2f}" if ratio is not None else ""
        if "confidence" in entry:
            line += f", confidence {entry['confidence']:.2f} (absent {entry['p_absent']:.2f})"
        if "error_m" in entry:
            truth = ", ".join(f"{v:.2f}" for v in entry["truth_m"])
            line += f", truth ({truth}) m, error {entry['error_m']:.2f} m"
            if "height_error_m" in entry:
                line += f" in the plan, {entry['height_error_m']:.2f} m in height"
        print(line)
    if "search" in result:
        search = result["search"]
        print(
            f"{search['planner']} search: {result['views']} views, "
            f"{result.get('path_length_m', float('nan')):.1f} m driven, "
            f"{result['time_s']:.0f} s of robot time; stopped: {search['stopped']}"
        )
    if "follow_up" in result:
        followed = result["follow_up"]
        print(
            f"after the plan, {followed['views']} {followed['planner']} views; "
            f"stopped: {followed['stopped']}"
        )
    timings = result["timings_s"]
    print("time (s): " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items() if not math.isnan(v)))
    print(f"wrote {out}")
