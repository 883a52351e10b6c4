"""twin/ObjectSearch-v0 under a masked random policy, and the information planner for comparison.

    python benchmarks/env_random_policy.py [--episodes 20] [--seed 1000] [--policy both]
                                           [--config NAME] [--set KEY=VALUE ...]

Episode ``i`` resets with seed ``seed + i`` (the default 1000.. is used by no test), so both
policies search for the object in the same places. ``random`` samples uniformly among the
views the action mask allows (reachable, not taken; the action space is seeded per episode);
``greedy`` takes what the config's planner (``search.planner``, information gain per second by
default) chooses, ``env.unwrapped.searcher.planner.choose(env.unwrapped.situation)``, i.e.
``twin search``'s own choice. Printed per episode and summarized: steps, views, robot time (s),
path length (m), the estimate's error (m), success (error within 0.2 m), the return, how it
ended, and the steps per second of wall time (MuJoCo rendering, detection and fusion included).
Relative paths resolve in the working directory: run it from the repository's top.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import gymnasium

import twin.envs

SUCCESS_M = 0.2  # an estimate within this of the truth is a success (the confidence radius)


def run_episode(env: gymnasium.Env, seed: int, policy: str) -> dict[str, Any]:
    """One episode; returns its statistics."""
    _, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    search = env.unwrapped
    total, steps, wall = 0.0, 0, 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        if policy == "random":
            action = int(env.action_space.sample(mask=info["action_mask"]))
        else:
            choice = search.searcher.planner.choose(search.situation)
            action = choice.index
        started = time.perf_counter()
        _, reward, terminated, truncated, info = env.step(action)
        wall += time.perf_counter() - started
        total += float(reward)
        steps += 1
    errors = [o["error_m"] for o in info["objects"].values()]
    return {
        "seed": seed,
        "steps": steps,
        "views": info["views"],
        "invalid": info["invalid_actions"],
        "time_s": info["robot_time_s"],
        "path_m": info["path_length_m"],
        "error_m": max(e if e is not None else float("inf") for e in errors),
        "found": len(info.get("found", [])),
        "return": total,
        "ended": "terminated" if terminated else "truncated",
        "stopped": info["stopped"],
        "step_wall_s": wall,
    }


def summary(policy: str, rows: list[dict[str, Any]]) -> str:
    def med(key: str) -> float:
        return statistics.median(r[key] for r in rows)

    def mean(key: str) -> float:
        return statistics.fmean(r[key] for r in rows)

    success = sum(r["error_m"] <= SUCCESS_M for r in rows) / len(rows)
    declared = sum(r["found"] > 0 for r in rows) / len(rows)
    steps = sum(r["steps"] for r in rows)
    wall = sum(r["step_wall_s"] for r in rows)
    return (
        f"{policy:6s}: {len(rows)} episodes; views mean {mean('views'):.1f} (median "
        f"{med('views'):g}); robot time mean {mean('time_s'):.1f} s (median {med('time_s'):.1f});"
        f" path mean {mean('path_m'):.2f} m; success within {SUCCESS_M} m "
        f"{100 * success:.0f} %; declared found and right {100 * declared:.0f} %; mean return "
        f"{mean('return'):.3f}; terminated {sum(r['ended'] == 'terminated' for r in rows)}, "
        f"robot could not go on {sum(r['stopped'].startswith('the robot could') for r in rows)}; "
        f"{steps / wall:.2f} steps/s wall"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1000, help="episode i resets with seed+i")
    parser.add_argument("--policy", choices=("random", "greedy", "both"), default="both")
    parser.add_argument("--config", default="living_room_survey")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    policies = ("random", "greedy") if args.policy == "both" else (args.policy,)
    started = time.perf_counter()
    env = gymnasium.make(twin.envs.OBJECT_SEARCH, config=args.config, overrides=tuple(args.set))
    print(
        f"{twin.envs.OBJECT_SEARCH}: {env.action_space.n} candidate views, at most "
        f"{env.unwrapped.max_views} steps; made in {time.perf_counter() - started:.1f} s",
        flush=True,
    )
    results: dict[str, list[dict[str, Any]]] = {}
    try:
        for policy in policies:
            rows = results.setdefault(policy, [])
            for i in range(args.episodes):
                row = run_episode(env, args.seed + i, policy)
                rows.append(row)
                print(
                    f"{policy:6s} seed {row['seed']}: {row['steps']:2d} steps ({row['views']} "
                    f"views, {row['invalid']} invalid), {row['time_s']:6.1f} s robot, "
                    f"{row['path_m']:5.2f} m path, error {row['error_m']:.2f} m, return "
                    f"{row['return']:+.3f}, {row['ended']} ({row['stopped'][:100]}), "
                    f"{row['steps'] / row['step_wall_s']:.2f} steps/s",
                    flush=True,
                )
    finally:
        env.close()
    for policy, rows in results.items():
        print(summary(policy, rows))
    if len(results) == 2:
        pairs = list(zip(results["random"], results["greedy"], strict=True))
        quicker = sum(g["time_s"] < r["time_s"] for r, g in pairs)
        better = sum(g["return"] > r["return"] for r, g in pairs)
        print(
            f"same seeds: greedy spent less robot time in {quicker} of {len(pairs)} episodes "
            f"and earned more return in {better}"
        )
    print(f"wall {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
