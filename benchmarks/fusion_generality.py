"""Every fusion rule on the same random placements: fly each once, fuse its views every way.

    python benchmarks/fusion_generality.py --seeds 5000-5023 --out runs/generality
    python benchmarks/fusion_generality.py --seeds 5000-5023 --out runs/generality-4 \\
        --set mission.views_per_stop=4 --set mission.view_step_deg=90
    python benchmarks/fusion_generality.py --seeds 1000-1023 --out runs/dev4 \
        --set mission.views_per_stop=4 --set mission.view_step_deg=90
    python benchmarks/fusion_generality.py --seeds 1000-1023 --out runs/dev \
        --fit-temperature runs/dev4

Each seed puts the target on a random furniture top (``twin survey --place-target random``)
and flies the configured mission once (two at a time); a finished run folder is reused, so an
interrupted benchmark resumes. Every run's ``views.npz`` (``twin.app.view_log``) is then fused
again with each rule, with and without the visibility model and the direction bins, so the
rules are compared on identical frames: the only difference is the rule. Prints per variant
the success within 0.3 and 0.2 m and the median error; the reliability table of the
``confidence`` (the calibrated belief's probability that the target lies within 0.2 m of the
estimate), at the end of each run and after every stop; and with ``--fit-temperature`` the
temperature that makes the confidence honest on these runs and those of other benchmarks
(fit it on development seeds, report on others).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

DEFAULT_CONFIG = "living_room_survey"
RADIUS = 0.2
RELIABILITY_BINS = [0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 1.0]


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


def variants(detector) -> dict[str, dict]:
    """Name -> how to fuse: the rule, visibility on/off, direction bins."""
    from twin.core.fusion import make_rule

    calibrations = {m.name: m.calibration for m in detector.models}
    rules = {
        "accumulate": make_rule("accumulate"),
        "normalized": make_rule("normalized"),
        "logodds": make_rule("logodds", p_fp=0.10, p_fn=0.05, threshold=0.162),
        "calibrated": {name: c.rule() for name, c in calibrations.items()},
        "calibrated by distance": {
            name: c.rule(by_distance=True) for name, c in calibrations.items()
        },
    }
    out = {}
    for name, rule in rules.items():
        for seen in (False, True):
            for bins in (1, 8):
                for room in (False, True):
                    label = (f"{name}{' +vis' if seen else ''}{f' +dir{bins}' if bins > 1 else ''}"
                             f"{' +room' if room else ''}")  # fmt: skip
                    out[label] = {"rule": rule, "visibility": seen, "bins": bins, "room": room}
    return out


def estimate(grid, name: str, separation: float) -> tuple[float, float]:
    best = grid.peaks(name, k=1, min_separation=separation).best
    return float(best.x), float(best.y)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="5000-5023", help="e.g. 5000-5023 or 1,2,3")
    parser.add_argument("--out", type=Path, required=True, help="run folders (reused)")
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--set", action="append", default=[], help="KEY=VALUE for the survey")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--fit-temperature", nargs="*", type=Path, metavar="DIR",
        help="fit the confidence's temperature on these runs and the --out folders of others",
    )  # fmt: skip
    parser.add_argument("--temperature", type=float, help="confidence temperature (config's)")
    parser.add_argument(
        "--default",
        default="accumulate +vis +room",
        help="the variant whose estimate the confidence is about (the shipped config's rule)",
    )
    parser.add_argument("--belief", default="calibrated +vis +room", help="the variant that is the "
                        "belief the confidence is read from")  # fmt: skip
    args = parser.parse_args()

    from twin.app.config import load_config, resolve_config
    from twin.app.detection import mission_detector
    from twin.app.room import room_baselines
    from twin.app.view_log import ViewLog
    from twin.core.confidence import (
        confidence_within,
        fit_temperature,
        posterior,
        reliability_table,
    )
    from twin.core.grid import AccumulatorGrid

    seeds = seeds_from(args.seeds)
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(seed, args.out, args.config, tuple(args.set)) for seed in seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        folders = list(pool.map(fly, jobs))

    config = load_config(folders[0] / "config.toml", base_dir=Path.cwd(),
                         folder=resolve_config(args.config).parent)  # fmt: skip
    detector, rooms = mission_detector(config, lambda _: None)
    name = config.objects[0].name
    spec, sep = config.grid.spec, config.grid.peak_separation
    temperature = args.temperature or config.confidence.temperature
    table = variants(detector)

    baselines: dict[str, dict | None] = {}  # per variant, measured once

    def new_grid(label: str) -> AccumulatorGrid:
        how = table[label]
        rules = how["rule"] if isinstance(how["rule"], dict) else {name: how["rule"]}
        if label not in baselines:
            room = how["room"] and room_baselines(rooms, rules, spec, config.grid.supersample)
            baselines[label] = room or None
        return AccumulatorGrid([name], spec, rules, config.grid.supersample,
                               direction_bins=how["bins"], baseline=baselines[label])  # fmt: skip

    errors: dict[str, list[float]] = {label: [] for label in table}
    finals: list[tuple] = []  # (belief layer, truth, estimate, confidence, hit) per run
    checkpoints: list[tuple] = []  # the same after every stop of every run
    for seed, folder in zip(seeds, folders, strict=True):
        log = ViewLog.load(folder / "views.npz")
        result = json.loads((folder / "result.json").read_text())
        truth = result["objects"][name]["truth_m"]
        row, estimates = [], {}
        for label, how in table.items():
            grid = new_grid(label)
            log.fuse_into(grid, visibility=how["visibility"])
            x, y = estimate(grid, name, sep)
            estimates[label] = (x, y)
            errors[label].append(math.hypot(x - truth[0], y - truth[1]))
            row.append(f"{errors[label][-1]:.2f}")
        # The confidence after every stop (checkpoints of the mission), and at its end.
        default, belief = (new_grid(label) for label in (args.default, args.belief))
        per_stop = max(1, len(log) // len(config.mission.stops))
        for first in range(0, len(log), per_stop):
            part = ViewLog(log.objects, log.max_range)
            part.views = log.views[first : first + per_stop]
            part.fuse_into(default, visibility=table[args.default]["visibility"])
            part.fuse_into(belief, visibility=table[args.belief]["visibility"])
            est = estimate(default, name, sep)
            layer = belief.layer(name)
            cells, _ = posterior(layer, temperature, config.confidence.p_absent)
            final = first + per_stop >= len(log)
            samples = [(layer, truth, est,
                        float(confidence_within(cells, spec, est, RADIUS)),
                        math.hypot(est[0] - truth[0], est[1] - truth[1]) <= RADIUS)]  # fmt: skip
            checkpoints += samples
            if final:
                finals += samples
        print(f"seed {seed}: truth {truth} errors " + " ".join(row), flush=True)

    print(f"\n{len(seeds)} placements, seeds {args.seeds}, config {args.config} {args.set}")
    print(f"{'variant':32s} {'<= 0.3 m':>9s} {'<= 0.2 m':>9s} {'median':>8s}  missed (> 0.2 m)")
    for label, errs in errors.items():
        e = np.array(errs)
        missed = " ".join(str(seed) for seed, err in zip(seeds, errs, strict=True) if err > 0.2)
        print(f"{label:32s} {100 * np.mean(e <= 0.3):8.0f}% {100 * np.mean(e <= 0.2):8.0f}% "
              f"{statistics.median(errs):7.2f} m  {missed}")  # fmt: skip
    print(f"\nconfidence of the {args.default!r} estimate from the {args.belief!r} belief "
          f"(temperature {temperature:g}, p_absent {config.confidence.p_absent:g}) against "
          "'the estimate is within 0.2 m':")  # fmt: skip
    for label, samples in (("at the end of each run", finals),
                           ("after every stop of every run", checkpoints)):  # fmt: skip
        c = np.array([sample[3] for sample in samples])
        h = np.array([sample[4] for sample in samples])
        print(f"{label}: {len(c)} estimates, {h.mean():.0%} right, mean confidence {c.mean():.2f}")
        print(f"{'confidence':>14s} {'n':>5s} {'mean conf':>10s} {'right':>7s}")
        for row in reliability_table(c, h, RELIABILITY_BINS):
            if row.n:
                print(f"  [{row.lo:.2f}, {min(row.hi, 1):.2f}) {row.n:5d} "
                      f"{row.mean_confidence:10.3f} {row.hit_rate:7.2f}")  # fmt: skip
        np.savez(args.out / f"confidence-{'final' if samples is finals else 'stops'}.npz",
                 confidence=c, hit=h)  # fmt: skip
    # Every stop's belief, truth and estimate, so a temperature can be fitted on several
    # benchmarks' runs together (--fit-temperature DIR ...).
    np.savez_compressed(
        args.out / "beliefs.npz",
        layers=np.array([sample[0] for sample in checkpoints]),
        truths=np.array([sample[1] for sample in checkpoints]),
        estimates=np.array([sample[2] for sample in checkpoints]),
    )
    if args.fit_temperature is not None:
        folders = [args.out, *args.fit_temperature]
        saved = [np.load(folder / "beliefs.npz") for folder in folders]
        fitted = fit_temperature(
            [layer for data in saved for layer in data["layers"]],
            [tuple(truth) for data in saved for truth in data["truths"]],
            spec,
            RADIUS,
            p_absent=config.confidence.p_absent,
            estimates=[tuple(e) for data in saved for e in data["estimates"]],
        )
        runs = ", ".join(str(folder) for folder in folders)
        print(f"\nfitted temperature (every stop of the runs in {runs}): {fitted.temperature:g}")


if __name__ == "__main__":
    main()
