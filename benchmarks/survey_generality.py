"""Generality: the default mission with the rice box placed at random on the furniture's tops.

    python benchmarks/survey_generality.py [--runs 20] [--first-seed 0] [--fusion accumulate]

Each run puts the box on a random level furniture top (``--place-target random --seed i``),
flies the paper's 5-stop mission and scores the estimate: success when it lies within 0.3 m of
the truth. Prints each run, the success rate and the median error.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

from twin.cli import main as twin_main


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument(
        "--first-seed", type=int, default=0, help="placements seeded first-seed .. +runs-1"
    )
    parser.add_argument("--fusion", default="accumulate")
    parser.add_argument("--tolerance", type=float, default=0.3, help="success radius (m)")
    parser.add_argument("--p-fp", type=float, default=0.1, help="logodds: detector P_fp")
    parser.add_argument("--p-fn", type=float, default=0.05, help="logodds: detector P_fn")
    parser.add_argument("--threshold", type=float, default=0.162, help="logodds: threshold")
    args = parser.parse_args()
    errors = []
    sets = ["run.rerun=off", f"grid.fusion={args.fusion}"]
    if args.fusion == "logodds":  # rates from benchmarks/rfch_rendered.py by default
        sets += [f"grid.p_fp={args.p_fp}", f"grid.p_fn={args.p_fn}",
                 f"grid.threshold={args.threshold}"]  # fmt: skip
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        sets.append(f"run.cache={folder / 'cache'}")
        for seed in range(args.first_seed, args.first_seed + args.runs):
            out = folder / f"run-{seed}"
            argv = ["survey", "--out", str(out), "--quiet", "--place-target", "random",
                    "--seed", str(seed), *(a for s in sets for a in ("--set", s))]  # fmt: skip
            if twin_main(argv) != 0:
                raise SystemExit(f"run {seed} failed")
            box = json.loads((out / "result.json").read_text())["objects"]["rice_box"]
            errors.append(box["error_m"])
            ratio = box["peak_ratio"]
            print(
                f"seed {seed:2d}: truth {box['truth_m']} estimate {box['estimate_m']} "
                f"error {box['error_m']:.2f} m, first/second peak "
                f"{'inf' if ratio is None else f'{ratio:.2f}'}",
                flush=True,
            )
    hits = sum(e <= args.tolerance for e in errors)
    print(
        f"success (within {args.tolerance} m): {hits}/{len(errors)} = "
        f"{100 * hits / len(errors):.0f} %; median error {statistics.median(errors):.2f} m"
    )


if __name__ == "__main__":
    main()
