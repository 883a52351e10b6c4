"""Executors compared: a 10x Monte Carlo sweep on local processes and on a local Ray cluster.

    python benchmarks/bench_executors.py [--trials 1000] [--workers 2] [--parts 1,2,3]

1. The paper's sweep (11 x 11 settings) with 10x its trials (1,000 per setting), once on the
   local process pool and once on a local Ray cluster, both with ``--workers`` workers; the two
   results are asserted identical, and the wall times printed (cluster start excluded, printed
   apart).
2. Speed-up against workers (1, 2) for each executor on a 3 x 3 corner of the sweep.
3. Per-task overhead: wall time per empty task, and the worker time a task costs beyond its
   trials (1,000 trials as 1,000 one-trial tasks against the same as one task per worker).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from twin.app.executors import Executor, ProcessExecutor, RayExecutor
from twin.app.montecarlo import SweepConfig, run_sweep


def _ray(workers: int) -> tuple[RayExecutor, float]:
    started = time.perf_counter()
    executor = RayExecutor(workers)
    return executor, time.perf_counter() - started


def _sweep(config: SweepConfig, executor: Executor, chunk: int) -> tuple[list, float]:
    started = time.perf_counter()
    results = run_sweep(config, executor, chunk_trials=chunk)
    return results, time.perf_counter() - started


def _identical(a: list, b: list) -> bool:
    return all(
        (x.pfp, x.pfn) == (y.pfp, y.pfn) and np.array_equal(x.successes, y.successes)
        for x, y in zip(a, b, strict=True)
    )


def _warm(executor: Executor) -> None:
    """Let every worker import the project and load the compiled kernels before timing."""
    config = SweepConfig(pfp=(0.0,), pfn=(0.0,), trials=4 * executor.workers)
    run_sweep(config, executor, chunk_trials=1)


def full_sweep(trials: int, workers: int, chunk: int) -> None:
    config = SweepConfig(trials=trials)
    n = len(config.settings()) * trials
    print(f"1. sweep: {len(config.settings())} settings x {trials} trials = {n} trials, "
          f"{workers} workers, chunks of {chunk}")  # fmt: skip
    local = ProcessExecutor(workers)
    _warm(local)
    local_results, local_time = _sweep(config, local, chunk)
    print(f"   local: {local_time:7.1f} s ({1e3 * local_time / n:.2f} ms per trial)", flush=True)
    ray, start_time = _ray(workers)
    try:
        _warm(ray)
        ray_results, ray_time = _sweep(config, ray, chunk)
    finally:
        ray.close()
    print(f"   ray:   {ray_time:7.1f} s ({1e3 * ray_time / n:.2f} ms per trial; "
          f"cluster start {start_time:.1f} s, not counted)")  # fmt: skip
    assert _identical(local_results, ray_results), "Ray and local results differ"
    rate = sum(int(r.successes[0, 0]) for r in local_results) / n
    print(
        f"   identical: all {len(local_results)} settings x rules x view counts "
        f"(e.g. accumulate at 10 views, mean over settings: {100 * rate:.1f} %)",
        flush=True,
    )


def speedup(trials: int, chunk: int) -> None:
    config = SweepConfig(pfp=(0.0, 0.1, 0.2), pfn=(0.0, 0.1, 0.2), trials=trials)
    n = len(config.settings()) * trials
    print(f"2. speed-up: {len(config.settings())} settings x {trials} trials, chunks of {chunk}")
    for name in ("local", "ray"):
        times = {}
        results = {}
        for workers in (1, 2):
            if name == "local":
                executor: Executor = ProcessExecutor(workers)
            else:
                executor, _ = _ray(workers)
            try:
                _warm(executor)
                results[workers], times[workers] = _sweep(config, executor, chunk)
            finally:
                executor.close()
        assert _identical(results[1], results[2]), f"{name}: 1 and 2 workers differ"
        print(f"   {name:5s}: 1 worker {times[1]:6.1f} s, 2 workers {times[2]:6.1f} s, "
              f"speed-up {times[1] / times[2]:.2f}x ({n} trials)", flush=True)  # fmt: skip


def _noop(item: int) -> int:
    return item


def overhead(tasks: int, workers: int) -> None:
    """Empty tasks' wall time each, and the worker time a task costs beyond its trials: the
    same trials as one-trial chunks and as ``workers`` big chunks, the difference per task."""
    print(f"3. per-task overhead: {tasks} tasks, {workers} workers")
    config = SweepConfig(pfp=(0.0,), pfn=(0.0,), trials=tasks)
    for name in ("local", "ray"):
        executor: Executor = ProcessExecutor(workers) if name == "local" else _ray(workers)[0]
        try:
            _warm(executor)
            started = time.perf_counter()
            for _ in executor.map_unordered(_noop, list(range(tasks))):
                pass
            empty = (time.perf_counter() - started) / tasks
            _, small = _sweep(config, executor, 1)
            _, big = _sweep(config, executor, -(-tasks // workers))
        finally:
            executor.close()
        per_task = (small - big) * workers / (tasks - workers)
        print(f"   {name:5s}: empty task {1e3 * empty:.2f} ms of wall time each; a task costs "
              f"{1e3 * per_task:.2f} ms of worker time beyond its trials' "
              f"({1e3 * big * workers / tasks:.2f} ms per trial)", flush=True)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000, help="trials per setting (1000)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--chunk", type=int, default=250, help="trials per task (250)")
    parser.add_argument("--parts", default="1,2,3", help="which parts to run (1,2,3)")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    if "1" in parts:
        full_sweep(args.trials, args.workers, args.chunk)
    if "2" in parts:
        speedup(args.trials, args.chunk)
    if "3" in parts:
        overhead(1000, args.workers)


if __name__ == "__main__":
    main()
