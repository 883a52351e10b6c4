"""Batch survey on both executors: the same seed gives the same missions; wall time and reuse.

    python benchmarks/bench_batch.py [--runs 40] [--seed 7] [--workers 2]

Runs ``twin batch-survey`` with the shipped mission (5 stops x 8 views) on the local executor
and on a local Ray cluster, asserts every run's draws, estimates and errors are identical, and
prints the success rate, the median error, the mean mission time, the worlds reused and the
wall time of each.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from twin.cli import main as twin_main

DETERMINISTIC = ("run", "lighting", "threshold", "objects", "views")


def runs(out: Path) -> dict[int, dict]:
    lines = (out / "runs.jsonl").read_text().splitlines()[1:]
    return {r["run"]: {k: r[k] for k in DETERMINISTIC} for r in map(json.loads, lines)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        results = {}
        for executor in ("local", "ray"):
            out = folder / executor
            argv = ["batch-survey", "--runs", str(args.runs), "--seed", str(args.seed),
                    "--set", f"run.cache={folder / 'cache'}", "--out", str(out),
                    "--workers", str(args.workers),
                    "--executor", executor, "--quiet"]  # fmt: skip
            if twin_main(argv) != 0:
                raise SystemExit(f"batch-survey on {executor} failed")
            results[executor] = runs(out)
            s = json.loads((out / "summary.json").read_text())
            print(f"{executor:5s}: {s['runs']} runs, success {100 * s['success_rate']:.1f} %, "
                  f"median error {s['error_m']['median']:.2f} m, mission "
                  f"{s['timings_s']['mission']['mean']:.2f} s mean, world setup "
                  f"{s['timings_s']['setup']['total']:.2f} s in all ({s['worlds_reused']} "
                  f"worlds reused), wall {s['wall_s']:.1f} s", flush=True)  # fmt: skip
        assert results["local"] == results["ray"], "local and Ray batches differ"
        print(f"identical: all {args.runs} runs (draws, estimates, errors)")


if __name__ == "__main__":
    main()
