"""Every fusion rule on the same random placements: fly each once, fuse its views every way.

    python benchmarks/fusion_generality.py --seeds 5000-5023 --out runs/generality
    python benchmarks/fusion_generality.py --seeds 5000-5023 --out runs/generality-4 \\
        --set mission.views_per_stop=4 --set mission.view_step_deg=90
    python benchmarks/fusion_generality.py --seeds 1000-1023 --out runs/dev --fit-temperature

Each seed puts the target on a random furniture top (``twin survey --place-target random``)
and flies the configured mission once (two at a time); a finished run folder is reused, so an
interrupted benchmark resumes. Every run's ``views.npz`` (``twin.app.view_log``) is then fused
again with each rule, with and without the visibility model and the direction bins, so the
rules are compared on identical frames: the only difference is the rule. Prints per variant
the success within 0.3 and 0.2 m and the median error; the reliability table of the
``confidence`` (the calibrated belief's probability that the target lies within 0.2 m of the
estimate); and with ``--fit-temperature`` the temperature that makes the confidence honest
on these runs (fit it on development seeds, report on others).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

DEFAULT_CONFIG = "living_room_survey"
RADIUS = 0.2


def seeds_from(text: str) -> list[int]:
    """ "5000-5023" or "1,2,3"."""
    if "-" in text:
        first, last = (int(v) for v in text.split("-"))
        return list(range(first, last + 1))
    return [int(v) for v in text.split(",")]


def fly(args: tuple[int, Path, str, tuple[str, ...]]) -> Path:
    """One survey with the target at random placement ``seed`` (skipped when already done)."""
    from twin.cli import main as twin_main

    seed, out, config, sets = args
    folder = out / f"seed-{seed}"
    result = folder / "result.json"
    if result.is_file() and json.loads(result.read_text())["status"] == "complete":
        return folder
    argv = ["survey", "--config", config, "--out", str(folder), "--quiet",
            "--place-target", "random", "--seed", str(seed),
            *(a for s in ("run.rerun=off", *sets) for a in ("--set", s))]  # fmt: skip
    if folder.exists():
        argv = ["survey", "--resume", str(folder), "--quiet"]
    if twin_main(argv) != 0:
        raise SystemExit(f"seed {seed}: the survey failed; see {folder}")
    return folder


def variants(config, detector) -> dict[str, dict]:
    """Name -> how to fuse: the rule, visibility on/off, direction bins."""
    from twin.core.fusion import make_rule

    calibrated = {m.name: m.calibration.rule() for m in detector.models}
    rules = {
        "accumulate": make_rule("accumulate"),
        "normalized": make_rule("normalized"),
        "logodds": make_rule("logodds", p_fp=0.10, p_fn=0.05, threshold=0.162),
        "calibrated": calibrated,
    }
    out = {}
    for name, rule in rules.items():
        for seen in (False, True):
            for bins in (1, 8):
                label = f"{name}{' +vis' if seen else ''}{f' +dir{bins}' if bins > 1 else ''}"
                out[label] = {"rule": rule, "visibility": seen, "bins": bins}
    return out


def estimate(grid, name: str, separation: float) -> tuple[float, float]:
    best = grid.peaks(name, k=1, min_separation=separation).best
    return best.x, best.y


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="5000-5023", help="e.g. 5000-5023 or 1,2,3")
    parser.add_argument("--out", type=Path, required=True, help="run folders (reused)")
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--set", action="append", default=[], help="KEY=VALUE for the survey")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--fit-temperature", action="store_true")
    parser.add_argument("--temperature", type=float, help="confidence temperature (config's)")
    args = parser.parse_args()

    from twin.app.config import load_config, resolve_config
    from twin.app.detection import prepare_detector
    from twin.app.view_log import ViewLog
    from twin.core.confidence import confidence_within, fit_temperature, posterior
    from twin.core.grid import AccumulatorGrid

    seeds = seeds_from(args.seeds)
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(seed, args.out, args.config, tuple(args.set)) for seed in seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        folders = list(pool.map(fly, jobs))

    config = load_config(folders[0] / "config.toml", base_dir=Path.cwd(),
                         folder=resolve_config(args.config).parent)  # fmt: skip
    detector = prepare_detector(config.objects, config.detector, config.cache, lambda _: None,
                                calibration_scene=str(config.scene))  # fmt: skip
    name = config.objects[0].name
    spec, sep = config.grid.spec, config.grid.peak_separation
    temperature = args.temperature or config.confidence.temperature
    table = variants(config, detector)
    errors: dict[str, list[float]] = {label: [] for label in table}
    beliefs, truths, confidences, hits = [], [], [], []
    for seed, folder in zip(seeds, folders, strict=True):
        log = ViewLog.load(folder / "views.npz")
        result = json.loads((folder / "result.json").read_text())
        truth = result["objects"][name]["truth_m"]
        row = []
        for label, how in table.items():
            grid = AccumulatorGrid(
                [name], spec, how["rule"], config.grid.supersample, direction_bins=how["bins"]
            )
            log.fuse_into(grid, visibility=how["visibility"])
            x, y = estimate(grid, name, sep)
            errors[label].append(math.hypot(x - truth[0], y - truth[1]))
            row.append(f"{errors[label][-1]:.2f}")
        belief = AccumulatorGrid([name], spec, table["calibrated +vis"]["rule"],
                                 config.grid.supersample)  # fmt: skip
        log.fuse_into(belief, visibility=True)
        beliefs.append(belief.layer(name))
        truths.append(truth)
        default = result["objects"][name]
        cells, _ = posterior(beliefs[-1], temperature, config.confidence.p_absent)
        est = default["estimate_m"]
        confidences.append(float(confidence_within(cells, spec, tuple(est), RADIUS)))
        hits.append(math.hypot(est[0] - truth[0], est[1] - truth[1]) <= RADIUS)
        print(f"seed {seed}: truth {truth} errors " + " ".join(row), flush=True)

    print(f"\n{len(seeds)} placements, seeds {args.seeds}, config {args.config} {args.set}")
    print(f"{'variant':32s} {'<= 0.3 m':>9s} {'<= 0.2 m':>9s} {'median':>8s}")
    for label, errs in errors.items():
        e = np.array(errs)
        print(f"{label:32s} {100 * np.mean(e <= 0.3):8.0f}% {100 * np.mean(e <= 0.2):8.0f}% "
              f"{statistics.median(errs):7.2f} m")  # fmt: skip
    print(f"\nconfidence (temperature {temperature:g}) against 'the estimate is within 0.2 m':")
    bins = [0.0, 0.5, 0.7, 0.8, 0.9, 0.95, 1.0001]
    c, h = np.array(confidences), np.array(hits)
    print(f"{'confidence':>14s} {'runs':>5s} {'mean conf':>10s} {'right':>7s}")
    for lo, hi in itertools.pairwise(bins):
        inside = (c >= lo) & (c < hi)
        if inside.any():
            print(f"  [{lo:.2f}, {min(hi, 1):.2f}) {inside.sum():5d} {c[inside].mean():10.3f} "
                  f"{h[inside].mean():7.2f}")  # fmt: skip
    if args.fit_temperature:
        fitted = fit_temperature(beliefs, truths, spec, RADIUS)
        print(f"\nfitted temperature: {fitted:g}")


if __name__ == "__main__":
    main()
