"""How the pose source decides the survey: exact pose, odometry, and the laser, on random targets.

    python benchmarks/localization_generality.py [--runs 8] [--first-seed 100]
        [--wheel-error 0.01] [--sources ideal,odometry,laser]

Each run puts the rice box on a random furniture top (``--place-target random --seed S``) and
flies the default mission once per pose source: ``ideal`` is the exact pose on a base without
errors (the reference the paper assumed), ``odometry`` and ``laser`` fly a base whose right
wheel is ``--wheel-error`` larger than its odometry assumes (nothing else miscalibrated, so
those two differ only in where the pose comes from). Prints, per source: the pose error the
fused views were projected from (max, mean, heading; from result.json's pose_error), how many
runs found the box within 0.2 m, how many ended early (a contact, a refused path) and the wall
time. Pick seeds no test uses.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from twin.cli import main as twin_main


def run(folder: Path, seed: int, source: str, wheel_error: float) -> tuple[dict, float]:
    out = folder / f"{source}-{seed}"
    if source == "ideal":
        source, wheel_error = "truth", 0.0
    sets = [
        "run.rerun=off",
        f"run.cache={folder / 'cache'}",
        f"robot.base.pose_source={source}",
        f"robot.base.wheel_radius_error=[0.0, {wheel_error}]",
        "robot.base.track_error=0.0",
        "robot.base.slip_noise=0.0",
    ]
    argv = ["survey", "--out", str(out), "--quiet", "--place-target", "random", "--seed", str(seed)]
    argv += [a for s in sets for a in ("--set", s)]
    started = time.perf_counter()
    twin_main(argv)
    wall = time.perf_counter() - started
    result_path = out / "result.json"
    if not result_path.exists():  # stopped before its first view
        return {"status": "failed before the first view", "objects": {}}, wall
    return json.loads(result_path.read_text()), wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--wheel-error", type=float, default=0.01)
    parser.add_argument("--sources", default="ideal,odometry,laser")
    parser.add_argument("--found-within", type=float, default=0.2, help="metres")
    args = parser.parse_args()
    sources = args.sources.split(",")
    rows: dict[str, list] = {s: [] for s in sources}
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        for seed in range(args.first_seed, args.first_seed + args.runs):
            for source in sources:
                result, wall = run(folder, seed, source, args.wheel_error)
                box = result.get("objects", {}).get("rice_box", {})
                pose = result.get("pose_error") or {}
                rows[source].append((result["status"], box.get("error_m"), pose, wall))
                print(
                    f"seed {seed} {source:8s}: {result['status'][:60]:60s} "
                    f"box error {box.get('error_m', float('nan')):.2f} m, pose error max "
                    f"{100 * pose.get('max_m', float('nan')):.1f} cm "
                    f"{pose.get('max_deg', float('nan')):.1f} deg, {wall:.1f} s",
                    flush=True,
                )
    print(f"\nright wheel {100 * args.wheel_error:g} % larger than odometry assumes, "
          f"{args.runs} random placements (seeds {args.first_seed}..)")  # fmt: skip
    print(
        "source    | pose error max / mean      | max heading | found within "
        f"{args.found_within} m | ended early | wall (median)"
    )
    for source in sources:
        done = [r for r in rows[source] if r[2]]
        found = sum(
            1
            for status, error, _, _ in rows[source]
            if status == "complete" and error is not None and error <= args.found_within
        )
        early = sum(1 for status, *_ in rows[source] if status != "complete")
        if done:
            worst = max(p["max_m"] for _, _, p, _ in done)
            mean = statistics.mean(p["mean_m"] for _, _, p, _ in done)
            heading = max(p["max_deg"] for _, _, p, _ in done)
            pose = f"{100 * worst:5.1f} cm / {100 * mean:4.1f} cm      | {heading:5.1f} deg  "
        else:
            pose = "(no pose truth)                   |            "
        wall = statistics.median(r[3] for r in rows[source])
        print(f"{source:9s} | {pose} | {found}/{args.runs}{' ' * 16}| {early}/{args.runs}"
              f"{' ' * 8}| {wall:.1f} s")  # fmt: skip


if __name__ == "__main__":
    main()
