"""``twin batch-survey``: many randomized survey missions in the twin, one summary.

Runs are appended to ``DIR/runs.jsonl`` as they finish; running the same batch into the same
folder again runs only the missing runs (a larger ``--runs`` adds runs).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from twin.app.planner_names import BATCH_FACTORS, PLANNERS
from twin.commands._args import add_config_arguments, comma_list, numbers
from twin.commands.montecarlo import add_executor_arguments

DEFAULT_OUT = Path("runs/batch")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "batch-survey",
        help="run many randomized survey missions (target, lighting, threshold, camera) into a "
        "summary",
        description="Fly the survey mission --runs times in the twin, each run seeded from "
        "(--seed, run index), varying the targets' places on the furniture, the scene's "
        "light intensities, the detector's threshold and the camera's noise; write "
        "DIR/runs.jsonl as runs finish, "
        "then DIR/summary.csv, DIR/summary.json, DIR/errors.png and DIR/success_vs_*.png. "
        "No Rerun recording is made.",
    )
    parser.add_argument("--runs", type=int, default=20, help="missions (20)")
    parser.add_argument("--seed", type=int, default=0, help="batch seed (0)")
    parser.add_argument(
        "--vary", type=comma_list(str, "factors"), default=BATCH_FACTORS,
        help=f"factors to randomize: {','.join(BATCH_FACTORS)} (default: all)",
    )  # fmt: skip
    parser.add_argument(
        "--lighting", type=numbers(2, "LOW,HIGH light scales"), default=(0.5, 1.5),
        help="range of the light-intensity scale (default 0.5,1.5; 1 is the scene's)",
    )  # fmt: skip
    parser.add_argument(
        "--threshold", type=numbers(2, "LOW,HIGH thresholds"), default=(0.0, 0.25),
        help="range of the detector threshold: patch scores below it read 0 (default 0,0.25)",
    )  # fmt: skip
    parser.add_argument(
        "--tolerance", type=float, default=0.3, help="success radius in the plan, metres (0.3)"
    )
    parser.add_argument(
        "--height-tolerance", type=float, default=None,
        help="success also needs the height within this many metres (default: the plan only)",
    )  # fmt: skip
    parser.add_argument(
        "--mission", choices=("survey", "search"), default="survey",
        help="survey: the config's fixed plan (default); search: views chosen as it goes "
        "(twin search), by the config's search.planner or --planner",
    )  # fmt: skip
    parser.add_argument(
        "--planner", choices=PLANNERS,
        help="with --mission search: how the next view is chosen (sets search.planner)",
    )  # fmt: skip
    add_config_arguments(parser)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"folder ({DEFAULT_OUT})")
    add_executor_arguments(parser)
    parser.add_argument("--fresh", action="store_true", help="discard a previous batch in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress and no summary")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from twin.app.batch import JOURNAL_NAME, BatchJournal, BatchSpec, prepare, run_batch
    from twin.app.batch_report import write_summary
    from twin.app.executors import make_executor
    from twin.app.outputs import check_output_folder, make_output_folder
    from twin.core.errors import InputError

    started = time.perf_counter()
    if args.runs < 1:
        raise InputError(f"--runs must be at least 1, got {args.runs}")
    overrides = tuple(args.set)
    if args.planner is not None:
        if args.mission != "search":
            raise InputError("--planner chooses a search's views; add --mission search")
        overrides += (f"search.planner={args.planner}",)
    spec = BatchSpec.from_config(
        args.config, overrides, seed=args.seed, vary=tuple(dict.fromkeys(args.vary)),
        lighting=args.lighting, threshold=args.threshold, tolerance=args.tolerance,
        mission=args.mission, height_tolerance=args.height_tolerance,
    )  # fmt: skip
    check_output_folder(
        args.out, "--out", lambda p: (p / JOURNAL_NAME).is_file(), "a twin batch-survey"
    )
    say = (lambda _: None) if args.quiet else print
    prepare(spec, say)
    make_output_folder(args.out, "--out")
    journal = BatchJournal(args.out / JOURNAL_NAME, spec, fresh=args.fresh)
    done = sum(1 for i in journal.done if i < args.runs)
    if done:
        say(f"resuming the batch in {args.out}: {done} of {args.runs} runs done")
    executor = make_executor(args.workers, args.executor, args.address)
    bar = tqdm(
        total=args.runs, initial=done, unit="run", desc="batch-survey",
        disable=args.quiet or not sys.stderr.isatty(),
    )  # fmt: skip
    try:
        with bar:
            results = run_batch(spec, args.runs, executor, journal, lambda _: bar.update())
    except KeyboardInterrupt:
        finished = [journal.done[i] for i in sorted(journal.done) if i < args.runs]
        if finished:  # the runs that finished are results too: summarize them
            _, paths = write_summary(args.out, spec, finished, time.perf_counter() - started)
            wrote = ", ".join(str(p) for p in paths)
            say(f"stopped after {len(finished)} of {args.runs} runs; wrote {wrote}; "
                "run the same command to finish")  # fmt: skip
        raise
    finally:
        executor.close()
    summary, paths = write_summary(args.out, spec, results, time.perf_counter() - started)
    within = f"{spec.tolerance} m" + (
        f" and {spec.height_tolerance} m in height" if spec.height_tolerance is not None else ""
    )
    say(f"{summary['runs']} runs, {summary['timings_s']['mission']['mean']:.1f} s per mission")
    for name, scored in summary["objects"].items():
        error, height = scored["error_m"], scored["height_error_m"]
        line = (
            f"{name}: {scored['successes']}/{summary['runs']} within {within} "
            f"({100 * scored['success_rate']:.0f} %); plan error median {error['median']:.2f} m, "
            f"p90 {error['p90']:.2f} m, max {error['max']:.2f} m"
        )
        if height is not None:
            line += f"; height error median {height['median']:.2f} m, p90 {height['p90']:.2f} m"
        say(line)
    say("wrote " + ", ".join(str(p) for p in paths))
    return 0
