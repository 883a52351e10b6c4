"""``twin survey``: the paper's mission end to end — the project's main job.

A fresh run writes into a new time-stamped folder (below ``run.out``, or ``--out DIR``
exactly); the config it ran with is copied there, so ``twin survey --resume DIR`` continues
exactly that run after an interruption.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import uuid
from datetime import datetime
from pathlib import Path

RUN_CONFIG = "config.toml"
RUN_OPTIONS = "run.json"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "survey",
        help="run the survey mission (default: the paper's, in the simulated living room)",
        description="Visit the mission's stops, look around, score every frame with RFCH and "
        "fuse the bearing wedges into the accumulator grid; write result.json, grid PNGs and a "
        "Rerun recording. Without --config, runs the shipped living-room mission in the twin.",
    )
    parser.add_argument("--config", type=Path, help="survey config (TOML); default: shipped")
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
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from twin.core.errors import InputError

    started = time.perf_counter()
    if args.resume is not None:
        if args.config is not None or args.out is not None:
            raise InputError(
                "--resume DIR continues a run with its own config and folder; "
                "drop --config and --out"
            )
        out, options = _resume_options(args.resume)
    else:
        out, options = _fresh_options(args)
    from twin.app.run import run_mission

    run_mission(
        out,
        options,
        resume=args.resume is not None,
        started=started,
        quiet=args.quiet,
        on_result=None if args.quiet else lambda result: _print_summary(out, result),
    )
    return 0


def _fresh_options(args: argparse.Namespace) -> tuple[Path, dict]:
    from twin.app.config import default_config_path, load_config
    from twin.core.errors import InputError
    from twin.core.store import write_text_atomic

    source = args.config or default_config_path()
    config = load_config(source)
    if args.out is not None:
        out = args.out
        if (out / RUN_OPTIONS).exists():
            raise InputError(
                f"{out} holds a survey already; continue it with --resume {out}, "
                "or choose another --out"
            )
    else:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out = config.out / stamp
        suffix = 1
        while out.exists():
            suffix += 1
            out = config.out / f"{stamp}-{suffix}"
    options = {
        "config_source": str(Path(source).resolve()),
        "place_target": args.place_target,
        "seed": args.seed,
        "rerun": args.rerun or config.rerun,
        "rerun_bind": args.rerun_bind,
        "working_dir": str(Path.cwd()),
        "recording_id": str(uuid.uuid4()),  # a resumed run's recording joins this one
    }
    write_text_atomic(out / RUN_CONFIG, Path(source).read_text(encoding="utf-8"))
    write_text_atomic(out / RUN_OPTIONS, json.dumps(options, indent=1))
    return out, options


def _resume_options(folder: Path) -> tuple[Path, dict]:
    from twin.core.errors import InputError

    try:
        options = json.loads((folder / RUN_OPTIONS).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"{folder} holds no survey to resume (no {RUN_OPTIONS}); check the folder"
        ) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{folder / RUN_OPTIONS} is corrupt ({exc}); start a new run") from None
    return folder, options


def _print_summary(out: Path, result: dict) -> None:
    for name, entry in result["objects"].items():
        x, y = entry["estimate_m"]
        line = f"{name}: estimate ({x:.2f}, {y:.2f}) m, peak {entry['peak']:.2f}"
        ratio = entry["peak_ratio"]
        line += f", first/second peak {ratio:.2f}" if ratio is not None else ""
        if "error_m" in entry:
            line += f", truth ({entry['truth_m'][0]:.2f}, {entry['truth_m'][1]:.2f}) m, "
            line += f"error {entry['error_m']:.2f} m"
        print(line)
    timings = result["timings_s"]
    print("time (s): " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items() if not math.isnan(v)))
    print(f"wrote {out}", file=sys.stdout)
