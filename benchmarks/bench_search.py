"""How fast a search decides, how long a search of the default room takes, and how well the
planner's time model predicts the robot's clock.

* **Choosing the next view** (the issue's goal: <= 0.5 s on 2 cores): the seconds from a view's
  end to the next choice: pricing every candidate (one Dijkstra search on the planning map) and
  scoring it over the posterior (``Searcher.situation`` + ``Planner.choose``), per planner,
  over whole searches of a few placements.
* **A search of the default room** (goal: <= 30 s wall): ``twin search`` as a user runs it,
  with the detector and the candidates cached (warm), and the candidates built anew (cold).
* **The time model**: predicted vs measured robot seconds of every move.

    python benchmarks/bench_search.py [--runs 4] [--seed 31]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.app.batch import BatchSpec, MissionWorld, draw_mission
from twin.app.mission import Mission
from twin.app.run import make_grids
from twin.app.search import make_searcher
from twin.app.survey import plan_views

PLANNERS = ("information", "detection", "coverage", "random", "survey")


def decisions(planner: str, runs: int, seed: int) -> tuple[list[float], list[tuple[float, float]]]:
    """Seconds per choice, and (predicted, measured) robot seconds per move, over ``runs``
    searches with the target placed at random."""
    spec = BatchSpec.from_config(
        None, (f"search.planner={planner}",), seed=seed, vary=("target",), mission="search"
    )
    world = MissionWorld(spec)
    config = world.config
    choose_s: list[float] = []
    moves: list[tuple[float, float]] = []
    try:
        for run in range(runs):
            world.reset(spec, draw_mission(spec, run))
            grid, belief = make_grids(config, world.detector, world.rooms)
            mission = Mission(
                world.robot, world.detector, grid, max_range=config.grid.max_range,
                visibility=world.visibility, fuse_visibility=config.grid.visibility,
                belief=belief, confidence_options=config.confidence,
            )  # fmt: skip
            searcher = make_searcher(
                config,
                mission,
                world.sim.world,
                plan_views(config.mission, world.robot.pantilt.limits),
            )
            while searcher.stop_reason() is None:
                tick = time.perf_counter()
                choice = searcher.planner.choose(searcher.situation())
                choose_s.append(time.perf_counter() - tick)
                if choice is None:
                    break
                before = mission.state.robot_time
                mission.observe(choice)
                # the first view's clock starts at connection; a plan's views are not priced
                if mission.views_done > 1 and np.isfinite(choice.seconds):
                    moves.append((choice.seconds, mission.state.robot_time - before))
    finally:
        world.close()
    return choose_s, moves


def search_wall(extra: tuple[str, ...] = ()) -> float:
    out = Path(tempfile.mkdtemp()) / "run"
    argv = [sys.executable, "-m", "twin.cli", "search", "--out", str(out), "--quiet",
            "--rerun", "off", *extra]  # fmt: skip
    subprocess.run(argv, check=True)
    result = json.loads((out / "result.json").read_text())
    shutil.rmtree(out.parent)
    return float(result["timings_s"]["session"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=4, help="searches per planner (4)")
    parser.add_argument("--seed", type=int, default=31, help="batch seed of the placements (31)")
    args = parser.parse_args()
    predicted, measured = [], []
    for planner in PLANNERS:
        choose_s, moves = decisions(planner, args.runs, args.seed)
        a = np.array(choose_s)
        print(f"{planner:12s} choose the next view: median {1000 * np.median(a):.0f} ms, "
              f"p90 {1000 * np.percentile(a, 90):.0f} ms, max {1000 * a.max():.0f} ms "
              f"({len(a)} choices)")  # fmt: skip
        predicted += [p for p, _ in moves]
        measured += [m for _, m in moves]
    p, m = np.array(predicted), np.array(measured)
    print(f"time model over {len(p)} moves: measured / predicted {m.sum() / p.sum():.2f} in "
          f"total, median error {np.median(np.abs(m - p)):.1f} s, 90th percentile "
          f"{np.percentile(np.abs(m - p), 90):.1f} s")  # fmt: skip
    warm = search_wall()
    print(f"twin search of the default room, warm: {warm:.1f} s wall (session)")
    cache = Path(tempfile.mkdtemp())
    shutil.copytree(
        Path("runs/cache"), cache, dirs_exist_ok=True, ignore=shutil.ignore_patterns("search")
    )
    cold = search_wall(("--set", f"run.cache={cache}"))
    shutil.rmtree(cache)
    print(f"twin search, candidates built anew (detector cached): {cold:.1f} s wall (session)")


if __name__ == "__main__":
    main()
