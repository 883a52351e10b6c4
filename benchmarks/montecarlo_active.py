"""Planned views against the paper's random ones, in its abstract world (Figure 3's).

    python benchmarks/montecarlo_active.py [--trials 300] [--workers N] [--seed 4242]

``twin montecarlo --active``'s comparison at three detector settings, (P_fp, P_fn) = (0.1, 0.1),
(0.3, 0.1) (many false positives) and (0.1, 0.5) (many misses): Figure 3's random views, the
paper's kind of survey (40 views: 5 places x 8 headings) and the greedy planners (coverage,
detection, information; travel cost 0.1 per cell), on the same worlds (object cell, detector
draws and tie draws per trial). At 300 trials a success rate's 95 % interval is about +-6 points
near 50 %, +-3 near 10 % or 90 %. Prints a markdown table (success at 5, 10, 20 and 40 views
per planner and rule, the mean path in cells, each planner's wall time over the three settings,
its pool's start included) and writes docs/montecarlo-active.png.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

from twin.app.executors import InlineExecutor, ProcessExecutor
from twin.app.montecarlo_active import (
    PLANNERS,
    ActiveConfig,
    active_figure,
    active_table,
    run_active,
)

SETTINGS = ((0.1, 0.1), (0.3, 0.1), (0.1, 0.5))
COUNTS = (5, 10, 20, 40)
FIGURE = Path(__file__).resolve().parent.parent / "docs" / "montecarlo-active.png"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--figure", type=Path, default=FIGURE)
    args = parser.parse_args()
    executor = ProcessExecutor(args.workers) if args.workers > 1 else InlineExecutor()
    start = time.perf_counter()
    results, walls = [], {}
    for planner in PLANNERS:  # one run per planner, so each one's wall time is its own
        config = ActiveConfig(planners=(planner,), settings=SETTINGS, views=max(COUNTS),
                              trials=args.trials, seed=args.seed)  # fmt: skip
        began = time.perf_counter()
        results += run_active(config, executor)
        walls[planner] = time.perf_counter() - began
    wall = time.perf_counter() - start
    used = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu = sum(u.ru_utime + u.ru_stime for u in used)  # the pools' workers are reaped: counted
    order = {s: i for i, s in enumerate(SETTINGS)}
    results.sort(key=lambda r: (order[r.setting], PLANNERS.index(r.planner)))
    print(active_table(results, COUNTS))
    print()
    print("| planner | wall s, 3 settings |\n|---|---|")
    print("\n".join(f"| {p} | {walls[p]:.0f} |" for p in PLANNERS))
    title = (
        f"Planned vs random views, the paper's abstract world (20 x 20 cells, 45° in 8 wedges); "
        f"{args.trials} trials per planner and setting"
    )
    figure = active_figure(args.figure, results, title)
    print(
        f"\n{args.trials} trials per planner and setting, seed {args.seed}, {args.workers} "
        f"worker(s): {wall:.0f} s wall, {cpu:.0f} s CPU; wrote {figure}"
    )


if __name__ == "__main__":
    main()
