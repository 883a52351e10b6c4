"""``twin montecarlo``: the paper's Figure 3 sweep over false-positive and false-negative rates."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from twin.commands._args import comma_list, numbers

DEFAULT_OUT = Path("runs/montecarlo")
DEFAULT_ACTIVE_OUT = Path("runs/montecarlo-active")
DEFAULT_VIEWS = (10, 25, 75, 150)
# With --active every count 1..max is scored; these are the counts the table shows.
DEFAULT_ACTIVE_VIEWS = (5, 10, 20, 40)
DEFAULT_FUSION = ("accumulate", "normalized", "logodds")
DEFAULT_ACTIVE_FUSION = ("accumulate", "logodds")
ACTIVE_RATE = 0.1  # --active's P_fp and P_fn when not given: one setting, not 121


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """--executor, --address and --workers, shared by the commands that fan tasks out."""
    parser.add_argument(
        "--executor", choices=("local", "ray"), default="local",
        help="local: processes on this machine (default); ray: a Ray cluster "
        "(pip install '.[cluster]'); the same seed gives the same results with either",
    )  # fmt: skip
    parser.add_argument(
        "--address", default=None,
        help="ray only: join the running cluster at this address (e.g. 10.0.0.5:6379, or "
        "'auto'); without it a local Ray cluster is started and stopped",
    )  # fmt: skip
    parser.add_argument(
        "--workers", type=int, default=None,
        help="concurrent tasks (default: this machine's cores; with --address, the cluster's)",
    )  # fmt: skip


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "montecarlo",
        help="reproduce the paper's Monte Carlo evaluation (Figure 3)",
        description="Monte Carlo over detector false-positive (P_fp) and false-negative (P_fn) "
        "rates in the paper's abstract world; writes DIR/results.csv, DIR/figure3.png (heat "
        "maps with the numbers) and DIR/figure3_3d.png (the paper's surfaces); with --scores "
        "beta DIR/thresholds.png (success over the threshold) instead. "
        "Finished chunks of trials are journaled in DIR/settings.jsonl as they arrive: a sweep "
        "interrupted in DIR continues where it stopped when run again. "
        "With --active, planners choose the views instead (see --active); writes "
        "DIR/active.csv and DIR/active.png.",
    )
    rates = comma_list(float, "rates in [0, 1]")
    # None: not given (the tenths 0..1), so --scores beta can refuse rates it would not use.
    parser.add_argument("--pfp", type=rates, default=None, help="P_fp list (0..1; 0,0.1,..,1)")
    parser.add_argument("--pfn", type=rates, default=None, help="P_fn list (0..1; 0,0.1,..,1)")
    parser.add_argument(
        "--views", type=comma_list(int, "view counts"), default=None,
        help="view counts at which each trial is scored (default 10,25,75,150); with --active "
        "every count up to the largest is scored and these are the table's (5,10,20,40)",
    )  # fmt: skip
    parser.add_argument("--trials", type=int, default=100, help="trials per setting (100)")
    parser.add_argument("--wedges", type=int, default=8, help="wedges per field of view (8)")
    parser.add_argument("--fov-deg", type=float, default=45.0, help="field of view, degrees (45)")
    parser.add_argument("--grid", type=int, default=20, help="grid cells per side (20)")
    parser.add_argument("--supersample", type=int, default=10, help="sub-cells per side (10)")
    parser.add_argument(
        "--fusion", type=comma_list(str, "rule names"), default=None,
        help="fusion rules to run (twin.core.fusion's: accumulate, the paper's, normalized, "
        "logodds, or any rule registered there; default: those three, with --active "
        "accumulate,logodds)",
    )  # fmt: skip
    parser.add_argument(
        "--min-observed", type=float, default=1.0,
        help="normalized rule: cells seen less than this (in full-cell views) read 0 (1.0)",
    )  # fmt: skip
    parser.add_argument(
        "--occluders", type=float, default=0.0,
        help="fraction of the cells that block the view, placed at random per trial (0: the "
        "paper's open world); each rule is then scored blind and knowing what was in view",
    )  # fmt: skip
    parser.add_argument(
        "--scores", choices=("binary", "beta"), default="binary",
        help="binary: wedges fire or not (the paper; settings --pfp x --pfn); beta: continuous "
        "wedge scores from --score-on/--score-off, settings --threshold",
    )  # fmt: skip
    parser.add_argument(
        "--score-on", type=numbers(2, "Beta shape parameters A,B"), default=(4.0, 8.0),
        help="--scores beta: Beta(A,B) of a wedge's score when it sees the object (4,8)",
    )  # fmt: skip
    parser.add_argument(
        "--score-off", type=numbers(2, "Beta shape parameters A,B"), default=(2.0, 20.0),
        help="--scores beta: Beta(A,B) of a wedge's score elsewhere (2,20)",
    )  # fmt: skip
    parser.add_argument(
        "--threshold", type=comma_list(float, "thresholds in (0, 1)"), default=(0.16,),
        help="--scores beta: logodds fires at score >= threshold, with the rates it has under "
        "the two distributions; one setting per threshold (0.16)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    parser.add_argument(
        "--active", type=comma_list(str, "planner names"), default=None, metavar="PLANNERS",
        help="the active mode: views chosen by these planners (comma list of random, the "
        "paper's random views; survey, 40 planned views from 5 places; coverage, detection, "
        "information: greedy per unit cost from lattice views), compared on the same worlds; "
        "settings --pfp x --pfn (default 0.1 each)",
    )  # fmt: skip
    parser.add_argument(
        "--travel-cost", type=float, default=None,
        help="--active: a greedy planner's gain is divided by 1 + this x the cells travelled "
        "(0.1)",
    )  # fmt: skip
    add_executor_arguments(parser)
    parser.add_argument(
        "--chunk", type=int, default=None,
        help="trials per task (default 250: ~0.6 s of work, so task overhead stays < 1 %%; "
        "with --active 25); results do not depend on it",
    )  # fmt: skip
    parser.add_argument(
        "--out", type=Path, default=None,
        help=f"folder ({DEFAULT_OUT}; with --active {DEFAULT_ACTIVE_OUT})",
    )  # fmt: skip
    parser.add_argument("--fresh", action="store_true", help="discard a previous sweep in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no table")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from twin.app.executors import make_executor
    from twin.app.montecarlo import (
        DEFAULT_CHUNK_TRIALS,
        JOURNAL_NAME,
        SweepConfig,
        SweepJournal,
        result_rows,
        run_sweep,
        write_results_csv,
    )
    from twin.app.outputs import check_output_folder, make_output_folder
    from twin.app.plots import figure3, figure3_3d, threshold_figure
    from twin.core.errors import InputError

    if args.active is not None:
        return run_active_mode(args)
    if args.travel_cost is not None:
        raise InputError("--travel-cost weighs the active mode's planners; give --active too")
    args.views = args.views or DEFAULT_VIEWS
    args.fusion = args.fusion or DEFAULT_FUSION
    args.out = args.out or DEFAULT_OUT
    if args.scores == "beta" and (args.pfp is not None or args.pfn is not None):
        raise InputError(
            "--pfp/--pfn set a binary detector's rates; with --scores beta the rates follow "
            "from --threshold, so leave them out"
        )
    tenths = tuple(round(0.1 * i, 1) for i in range(11))
    config = SweepConfig(
        pfp=args.pfp or tenths, pfn=args.pfn or tenths, views=args.views, trials=args.trials,
        wedges=args.wedges, fov=math.radians(args.fov_deg), grid=args.grid,
        supersample=args.supersample, fusion=args.fusion, seed=args.seed,
        min_observed=args.min_observed, occluders=args.occluders, scores=args.scores,
        score_on=args.score_on, score_off=args.score_off, thresholds=args.threshold,
    )  # fmt: skip
    chunk = args.chunk if args.chunk is not None else DEFAULT_CHUNK_TRIALS
    if chunk < 1:
        raise InputError(f"--chunk must be at least 1 trial, got {chunk}")
    check_output_folder(
        args.out, "--out", lambda p: (p / JOURNAL_NAME).is_file(), "a twin montecarlo sweep"
    )
    make_output_folder(args.out, "--out")
    journal = SweepJournal(args.out / JOURNAL_NAME, config, fresh=args.fresh)
    total = len(config.settings())
    trials_done = sum(b - a for r in journal.ranges().values() for a, b in r)
    if trials_done and not args.quiet:
        print(
            f"resuming the sweep in {args.out}: {len(journal.done)} of {total} settings done"
            f" ({trials_done} of {total * config.trials} trials)"
        )
    executor = make_executor(args.workers, args.executor, args.address)
    bar = tqdm(
        total=total * config.trials, initial=trials_done, unit="trial", desc="montecarlo",
        disable=args.quiet or not sys.stderr.isatty(),
    )  # fmt: skip
    try:
        with bar:
            results = run_sweep(
                config, executor, journal, chunk_trials=chunk,
                on_chunk=lambda c: bar.update(c.chunk.stop - c.chunk.start),
            )  # fmt: skip
    except KeyboardInterrupt:
        # The settings that finished are results: write them; the journal keeps the rest.
        finished = [journal.done[s] for s in config.settings() if s in journal.done]
        path = write_results_csv(
            args.out / "results.csv", result_rows(config, finished), config.result_columns
        )
        if not args.quiet:
            print(
                f"stopped with {len(finished)} of {total} settings done; wrote {path}; run the "
                "same command to finish the sweep"
            )
        raise
    finally:
        executor.close()
    rows = result_rows(config, results)
    csv_path = write_results_csv(args.out / "results.csv", rows, config.result_columns)
    # The figures draw one panel row per (rule, visibility), named as the table names them.
    named = [{**row, "fusion": label(row["fusion"], row["visibility"])} for row in rows]
    labels = [label(rule, visibility) for rule, visibility in config.evaluations]
    written = [csv_path]
    if config.scored:
        written.append(
            threshold_figure(args.out / "thresholds.png", named, labels, config.checkpoints)
        )
    else:
        drawn = (named, labels, config.pfp, config.pfn, config.checkpoints)
        written.append(figure3(args.out / "figure3.png", *drawn))
        surfaces = figure3_3d(args.out / "figure3_3d.png", *drawn)  # None: one rate varies
        if surfaces is not None:
            written.append(surfaces)
    if not args.quiet:
        print(summary_table(rows, config))
        print(f"wrote {', '.join(str(p) for p in written)}")
    return 0


def label(rule: str, visibility: str) -> str:
    """A (rule, visibility) pair's name in tables and figures: the rule, marked when it knew
    which cells were in view."""
    return rule if visibility == "none" else f"{rule}+visibility"


def summary_table(rows: list[dict[str, object]], config) -> str:
    """Success (%) per rule and view count at the four corners of the low-rate region, and mean.

    The corners pair the lowest rate of each axis with the rate nearest 0.5: the paper's
    statements are about exactly these (noise-free; many false negatives; many false positives).
    With scores the columns are the thresholds instead (each with its rates).
    """
    table = {
        (r["fusion"], r["visibility"], r["pfp"], r["pfn"], r["views"]): r["success_rate"]
        for r in rows
    }
    if config.scored:
        corners = config.settings()
        names = [
            f"t={t:g} (fp={fp:.2f} fn={fn:.2f})"
            for t, (fp, fn) in zip(config.thresholds, corners, strict=True)
        ]
    else:
        fp_axis = (min(config.pfp), min(config.pfp, key=lambda p: abs(p - 0.5)))
        fn_axis = (min(config.pfn), min(config.pfn, key=lambda p: abs(p - 0.5)))
        corners = list(dict.fromkeys((fp, fn) for fp in fp_axis for fn in fn_axis))
        names = [f"fp={fp:g} fn={fn:g}" for fp, fn in corners]
    head = ["rule", "views", *names, "mean(all)"]
    lines = [head]
    for rule, visibility in config.evaluations:
        for views in config.checkpoints:
            rates = [
                r["success_rate"]
                for r in rows
                if (r["fusion"], r["visibility"], r["views"]) == (rule, visibility, views)
            ]
            cells = [f"{100 * table[(rule, visibility, *c, views)]:.0f}%" for c in corners]
            mean = f"{100 * sum(rates) / len(rates):.0f}%"
            lines.append([label(rule, visibility), str(views), *cells, mean])
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    return "\n".join(
        "  ".join(c.rjust(w) for c, w in zip(line, widths, strict=True)) for line in lines
    )


def run_active_mode(args: argparse.Namespace) -> int:
    """``--active``: planners against random views, every count of views 1..max(--views)."""
    from tqdm import tqdm

    from twin.app.executors import make_executor
    from twin.app.montecarlo import JOURNAL_NAME
    from twin.app.montecarlo_active import (
        DEFAULT_CHUNK_TRIALS,
        DEFAULT_TRAVEL_COST,
        ActiveConfig,
        active_figure,
        active_rows,
        active_table,
        run_active,
        write_active_csv,
    )
    from twin.app.outputs import check_output_folder, make_output_folder
    from twin.core.errors import InputError

    if args.occluders != 0.0 or args.scores != "binary":
        raise InputError(
            "--active runs the paper's open world with a binary detector; leave out "
            "--occluders and --scores"
        )
    views = args.views or DEFAULT_ACTIVE_VIEWS
    if any(v < 1 for v in views):
        raise InputError(f"--views must be positive view counts, got {views!r}")
    pfp, pfn = args.pfp or (ACTIVE_RATE,), args.pfn or (ACTIVE_RATE,)
    config = ActiveConfig(
        planners=args.active, settings=tuple((fp, fn) for fp in pfp for fn in pfn),
        views=max(views), trials=args.trials, grid=args.grid, wedges=args.wedges,
        fov=math.radians(args.fov_deg), supersample=args.supersample,
        fusion=args.fusion or DEFAULT_ACTIVE_FUSION, seed=args.seed,
        min_observed=args.min_observed,
        travel_cost=DEFAULT_TRAVEL_COST if args.travel_cost is None else args.travel_cost,
    )  # fmt: skip
    chunk = args.chunk if args.chunk is not None else DEFAULT_CHUNK_TRIALS
    if chunk < 1:
        raise InputError(f"--chunk must be at least 1 trial, got {chunk}")
    out = args.out or DEFAULT_ACTIVE_OUT
    check_output_folder(
        out, "--out",
        lambda p: (p / "active.csv").is_file() or (p / JOURNAL_NAME).is_file(),
        "a twin montecarlo run",
    )  # fmt: skip
    make_output_folder(out, "--out")
    executor = make_executor(args.workers, args.executor, args.address)
    bar = tqdm(
        total=len(config.settings) * len(config.planners) * config.trials, unit="trial",
        desc="montecarlo --active", disable=args.quiet or not sys.stderr.isatty(),
    )  # fmt: skip
    try:
        with bar:
            results = run_active(
                config, executor, chunk, on_chunk=lambda c: bar.update(c.stop - c.start)
            )
    finally:
        executor.close()
    csv_path = write_active_csv(out / "active.csv", active_rows(results))
    figure = active_figure(out / "active.png", results)
    if not args.quiet:
        print(active_table(results, views))
        print(f"wrote {csv_path}, {figure}")
    return 0
