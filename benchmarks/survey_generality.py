"""Generality: the default mission with the rice box placed at random on the furniture's tops.

    python benchmarks/survey_generality.py [--runs 20] [--fusion accumulate]

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

from twin.app.config import default_config_path
from twin.cli import main as twin_main


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--fusion", default="accumulate")
    parser.add_argument("--tolerance", type=float, default=0.3, help="success radius (m)")
    parser.add_argument("--p-fp", type=float, default=0.1, help="logodds: detector P_fp")
    parser.add_argument("--p-fn", type=float, default=0.05, help="logodds: detector P_fn")
    parser.add_argument("--threshold", type=float, default=0.162, help="logodds: threshold")
    args = parser.parse_args()
    errors = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        text = default_config_path().read_text()
        text = text.replace('rerun = "save"', 'rerun = "off"')
        rule = f'fusion = "{args.fusion}"'
        if args.fusion == "logodds":  # rates from benchmarks/rfch_rendered.py by default
            rule += f"\np_fp = {args.p_fp}\np_fn = {args.p_fn}\nthreshold = {args.threshold}"
        text = text.replace('fusion = "accumulate"', rule)
        text = text.replace(
            'file = "living_room.xml"',
            f'file = "{default_config_path().parent / "living_room.xml"}"',
        )
        text = text.replace('cache = "runs/cache"', f'cache = "{folder / "cache"}"')
        config = folder / "survey.toml"
        config.write_text(text)
        for seed in range(args.runs):
            out = folder / f"run-{seed}"
            argv = [
                "survey",
                "--config",
                str(config),
                "--out",
                str(out),
                "--quiet",
                "--place-target",
                "random",
                "--seed",
                str(seed),
            ]
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
