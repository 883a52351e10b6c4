"""Search vs survey over randomized placements: success, views, path and robot time per planner.

Runs ``twin batch-survey --mission search --planner P`` for every planner, and the paper's
fixed 40-view survey (``--mission survey``), on the same placements (the same batch seed: run i
of every batch puts the target in the same place), then prints one table. Every batch is
resumable (its folder's runs.jsonl): run the same command again to finish an interrupted one.

    python benchmarks/search_generality.py --runs 40 --seed 2026 --out runs/search-report

The seeds used while developing the planners were batch seed 77; report on others.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

PLANNERS = ("information", "detection", "coverage", "random", "survey")


def batch(out: Path, runs: int, seed: int, workers: int, radius: float, *extra: str) -> float:
    started = time.perf_counter()
    argv = [sys.executable, "-m", "twin.cli", "batch-survey", "--runs", str(runs), "--seed",
            str(seed), "--vary", "target", "--tolerance", str(radius), "--out", str(out), "--quiet",
            "--workers", str(workers), *extra]  # fmt: skip
    subprocess.run(argv, check=True)
    return time.perf_counter() - started


def row(name: str, folder: Path) -> dict[str, object]:
    with (folder / "summary.csv").open() as handle:
        runs = list(csv.DictReader(handle))
    error = np.array([float(r["error_m"]) for r in runs])
    views = np.array([float(r["views"]) for r in runs])
    metres = np.array([float(r["path_length_m"]) for r in runs])
    seconds = np.array([float(r["time_s"]) for r in runs])
    found = sum(r["stopped"].startswith("found") for r in runs)
    # sure and wrong: the worst outcome of a search (it stops, and says it found it)
    wrong = sum(r["stopped"].startswith("found") and r["success"] != "1" for r in runs)
    return {
        "planner": name,
        "runs": len(runs),
        # the batch's own success: within the radius, and a mission the robot finished
        "success": f"{100 * np.mean([r['success'] == '1' for r in runs]):.1f} %",
        "failed": sum(r["stopped"].startswith("failed") for r in runs),
        "confident": f"{found}/{len(runs)}" if any(r["stopped"] for r in runs) else "-",
        "confident, wrong": wrong if any(r["stopped"] for r in runs) else "-",
        "views median / p90": f"{np.median(views):.0f} / {np.percentile(views, 90):.0f}",
        "path m median / p90": f"{np.median(metres):.1f} / {np.percentile(metres, 90):.1f}",
        "robot s median / p90": f"{np.median(seconds):.0f} / {np.percentile(seconds, 90):.0f}",
        "error m median": f"{np.median(error):.2f}",
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("runs/search-report"))
    parser.add_argument("--planners", default=",".join(PLANNERS))
    parser.add_argument("--radius", type=float, default=0.2, help="success radius (m)")
    args = parser.parse_args()
    rows, walls = [], {}
    for planner in args.planners.split(","):
        folder = args.out / planner
        walls[planner] = batch(folder, args.runs, args.seed, args.workers, args.radius,
                               "--mission", "search", "--planner", planner)  # fmt: skip
        rows.append(row(planner, folder))
    folder = args.out / "fixed-survey"
    walls["fixed survey"] = batch(folder, args.runs, args.seed, args.workers, args.radius)
    rows.append(row("fixed 40-view survey", folder))
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(str(r[k]) for k in keys) + " |")
    print("wall s per batch: " + ", ".join(f"{k} {v:.0f}" for k, v in walls.items()))


if __name__ == "__main__":
    main()
