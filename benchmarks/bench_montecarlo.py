"""Wall and CPU time and peak memory of the full default Monte Carlo sweep (the paper's Figure 3).

    python benchmarks/bench_montecarlo.py [--workers N] [--trials T]

121 settings (P_fp, P_fn in 0, 0.1, ..., 1) x 100 trials x up to 150 views, the default fusion
rules, as ``twin montecarlo`` runs it, into a temporary folder (no resume). Also prints the cost
of one trial, so the per-view cost can be read off. CPU time (this process and its reaped
workers) is printed beside wall time: on a shared machine the wall time says how busy the others
were, the CPU time what the sweep cost.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

from twin.app.montecarlo import SweepConfig, run_trials
from twin.cli import main as twin_main


def peak_rss_mib(who: int) -> float:
    return resource.getrusage(who).ru_maxrss / 1024.0


def cpu_seconds() -> float:
    """User + system CPU of this process and of its children that have ended."""
    used = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(u.ru_utime + u.ru_stime for u in used)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--trials", type=int, default=100)
    args = parser.parse_args()

    config = SweepConfig()
    rules = len(config.fusion)
    run_trials(config, 0.1, 0.1, 0, 1)  # load or compile the kernels outside the timing
    start, cpu = time.perf_counter(), time.process_time()
    n = 250  # one default chunk, batched as the sweep runs it
    run_trials(config, 0.3, 0.3, 0, n)
    per_trial = (time.perf_counter() - start) / n
    per_trial_cpu = (time.process_time() - cpu) / n
    print(
        f"one trial of 150 views, {rules} rules: {1e3 * per_trial:.2f} ms wall, "
        f"{1e3 * per_trial_cpu:.2f} ms CPU ({1e6 * per_trial_cpu / 150:.1f} us CPU per view)"
    )

    with tempfile.TemporaryDirectory() as folder:
        argv = [
            "montecarlo",
            "--trials",
            str(args.trials),
            "--workers",
            str(args.workers),
            "--out",
            str(Path(folder) / "mc"),
            "--quiet",
        ]
        start, cpu = time.perf_counter(), cpu_seconds()
        code = twin_main(argv)
        wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    if code:
        sys.exit(code)
    print(
        f"full default sweep (121 settings x {args.trials} trials, 150 views, {rules} rules), "
        f"{args.workers} worker(s): {wall:.1f} s wall, {cpu:.1f} s CPU"
    )
    print(
        f"peak memory: this process {peak_rss_mib(resource.RUSAGE_SELF):.0f} MiB, "
        f"largest worker {peak_rss_mib(resource.RUSAGE_CHILDREN):.0f} MiB"
    )


if __name__ == "__main__":
    main()
