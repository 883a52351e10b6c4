"""``twin montecarlo``: the paper's Figure 3 sweep over false-positive and false-negative rates."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from twin.commands._args import comma_list

DEFAULT_OUT = Path("runs/montecarlo")


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
        "maps with the numbers) and DIR/figure3_3d.png (the paper's surfaces). "
        "Finished chunks of trials are journaled in DIR/settings.jsonl as they arrive: a sweep "
        "interrupted in DIR continues where it stopped when run again.",
    )
    rates = comma_list(float, "rates in [0, 1]")
    tenths = ",".join(f"{0.1 * i:.1f}" for i in range(11))
    parser.add_argument("--pfp", type=rates, default=rates(tenths), help="P_fp list (0..1)")
    parser.add_argument("--pfn", type=rates, default=rates(tenths), help="P_fn list (0..1)")
    parser.add_argument(
        "--views", type=comma_list(int, "view counts"), default=(10, 25, 75, 150),
        help="view counts at which each trial is scored (default 10,25,75,150)",
    )  # fmt: skip
    parser.add_argument("--trials", type=int, default=100, help="trials per setting (100)")
    parser.add_argument("--wedges", type=int, default=8, help="wedges per field of view (8)")
    parser.add_argument("--fov-deg", type=float, default=45.0, help="field of view, degrees (45)")
    parser.add_argument("--grid", type=int, default=20, help="grid cells per side (20)")
    parser.add_argument("--supersample", type=int, default=10, help="sub-cells per side (10)")
    parser.add_argument(
        "--fusion", type=comma_list(str, "rule names"),
        default=("accumulate", "normalized", "logodds"),
        help="fusion rules to run (twin.core.fusion's: accumulate, the paper's, normalized, "
        "logodds, or any rule registered there; default: those three)",
    )  # fmt: skip
    parser.add_argument(
        "--min-observed", type=float, default=1.0,
        help="normalized rule: cells seen less than this (in full-cell views) read 0 (1.0)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    add_executor_arguments(parser)
    parser.add_argument(
        "--chunk", type=int, default=None,
        help="trials per task (default 250: ~0.6 s of work, so task overhead stays < 1 %%); "
        "results do not depend on it",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"folder ({DEFAULT_OUT})")
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
    from twin.app.plots import figure3, figure3_3d
    from twin.core.errors import InputError

    config = SweepConfig(
        pfp=args.pfp, pfn=args.pfn, views=args.views, trials=args.trials, wedges=args.wedges,
        fov=math.radians(args.fov_deg), grid=args.grid, supersample=args.supersample,
        fusion=args.fusion, seed=args.seed, min_observed=args.min_observed,
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
        path = write_results_csv(args.out / "results.csv", result_rows(config, finished))
        if not args.quiet:
            print(
                f"stopped with {len(finished)} of {total} settings done; wrote {path}; run the "
                "same command to finish the sweep"
            )
        raise
    finally:
        executor.close()
    rows = result_rows(config, results)
    csv_path = write_results_csv(args.out / "results.csv", rows)
    drawn = (rows, config.fusion, config.pfp, config.pfn, config.checkpoints)
    written = [csv_path, figure3(args.out / "figure3.png", *drawn)]
    surfaces = figure3_3d(args.out / "figure3_3d.png", *drawn)  # None: a single rate varies
    if surfaces is not None:
        written.append(surfaces)
    if not args.quiet:
        print(summary_table(rows, config))
        print(f"wrote {', '.join(str(p) for p in written)}")
    return 0


def summary_table(rows: list[dict[str, object]], config) -> str:
    """Success (%) per rule and view count at the four corners of the low-rate region, and mean.

    The corners pair the lowest rate of each axis with the rate nearest 0.5: the paper's
    statements are about exactly these (noise-free; many false negatives; many false positives).
    """
    table = {(r["fusion"], r["pfp"], r["pfn"], r["views"]): r["success_rate"] for r in rows}
    fp_axis = (min(config.pfp), min(config.pfp, key=lambda p: abs(p - 0.5)))
    fn_axis = (min(config.pfn), min(config.pfn, key=lambda p: abs(p - 0.5)))
    corners = list(dict.fromkeys((fp, fn) for fp in fp_axis for fn in fn_axis))
    head = ["rule", "views"] + [f"fp={fp:g} fn={fn:g}" for fp, fn in corners] + ["mean(all)"]
    lines = [head]
    for rule in config.fusion:
        for views in config.checkpoints:
            rates = [r["success_rate"] for r in rows if r["fusion"] == rule and r["views"] == views]
            cells = [f"{100 * table[(rule, fp, fn, views)]:.0f}%" for fp, fn in corners]
            lines.append([rule, str(views), *cells, f"{100 * sum(rates) / len(rates):.0f}%"])
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    return "\n".join(
        "  ".join(c.rjust(w) for c, w in zip(line, widths, strict=True)) for line in lines
    )
