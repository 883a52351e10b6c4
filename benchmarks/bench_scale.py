"""How a view's cost and a mission's memory grow with the floor's area and the objects sought.

    python benchmarks/bench_scale.py [--views 40] [--objects 1,4,16]

Areas: the living room and the apartment (their scenes' floors, as ``grid.extent = "scene"``
gives them) and a synthetic 30 m x 30 m open floor, all in 0.1 m cells with the paper's 10x
supersampling. For each area and number of objects it runs what a mission does per view, with
the mission's own code, on views from random poses inside the floor:

- detect: RFCH scores of one 320 x 240 frame for every object, all on one shared codebook;
- visibility: the columns' visibility profiles out to the grid's diagonal (the default reach),
  every height possible (no scene model: the worst case);
- fuse: the view into the mission's grid (the paper's rule) and its belief grid (log-odds
  ratios, standing in for the calibrated rule: same coverage pass);
- results: every object's peaks, confidence (posterior within 0.2 m) and height (twin.core.height
  over the views so far), which a mission computes after each view for the viewer;
- checkpoint: the grid and the view log written atomically, as after every view.

Prints medians in ms per view over the later half of the views (the view log grows), the
grids' memory and the view log's per view. Nothing is asserted: the machine is shared, the
figures are upper bounds.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.app.config import scene_extent
from twin.app.view_log import LoggedView, ViewLog
from twin.app.visibility_models import default_reach
from twin.core.confidence import confidence_within, posterior
from twin.core.fusion import make_rule
from twin.core.geometry import CameraModel, Pose2D
from twin.core.grid import AccumulatorGrid, GridSpec
from twin.core.height import best_patch_elevations
from twin.core.visibility import SupportLevels, visibility_from_depth
from twin.resources import scenes_dir
from twin.rfch import RFCH, Detector
from twin.rfch.synthetic import cloudy_background, paste, striped_object

CAMERA = CameraModel()
CELL = 0.1


def areas() -> list[tuple[str, tuple[float, float, float, float]]]:
    found = [("living room", scene_extent(scenes_dir() / "living_room.xml"))]
    apartment = scenes_dir() / "apartment.xml"
    if apartment.is_file():
        found.append(("apartment", scene_extent(apartment)))
    else:
        found.append(("10 x 8 m (no apartment scene)", (0.0, 0.0, 10.0, 8.0)))
    found.append(("open floor 30 x 30 m", (0.0, 0.0, 30.0, 30.0)))
    return found


def detector_for(n: int, rng: np.random.Generator) -> Detector:
    """n objects on one shared codebook: striped discs recoloured per object, trained from
    their pasted views."""
    base, mask = striped_object(48)
    objects = {}
    for k in range(n):
        image = np.roll(base, k, axis=2) if k % 2 else base[..., ::-1]
        image = np.clip(image.astype(int) * (0.6 + 0.4 * ((k * 7) % 5) / 4), 0, 255).astype(
            np.uint8
        )
        views, masks = [], []
        for _ in range(2):
            frame = cloudy_background(rng, 240, 320)
            centre = (rng.uniform(60, 260), rng.uniform(60, 180))
            placed, placed_mask = paste(frame, image, mask, centre, angle_deg=rng.uniform(0, 360))
            views.append(placed)
            masks.append(placed_mask)
        objects[f"object{k}"] = (views, masks)
    return Detector(RFCH.train_shared(objects))


def run_case(extent, n_objects: int, n_views: int, detector: Detector, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    spec = GridSpec(*extent, CELL)
    names = list(detector.names)
    grid = AccumulatorGrid(names, spec, make_rule("accumulate"), supersample=10)
    belief = AccumulatorGrid(
        names, spec, make_rule("logodds", p_fp=0.1, p_fn=0.05, threshold=0.16), supersample=10
    )
    reach = default_reach(extent, None)
    supports = SupportLevels.anywhere(extent, CELL)
    log = ViewLog(names, None)
    spans = detector.column_spans(CAMERA.width)
    depth = np.full((CAMERA.height, CAMERA.width), np.nan, dtype=np.float32)
    frames = [cloudy_background(rng, 240, 320) for _ in range(4)]
    stages: dict[str, list[float]] = {
        k: [] for k in ("detect", "visibility", "fuse", "results", "checkpoint")
    }
    clock = time.perf_counter
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        for i in range(n_views):
            x0, y0, x1, y1 = extent
            pose = Pose2D(rng.uniform(x0 + 0.5, x1 - 0.5), rng.uniform(y0 + 0.5, y1 - 0.5),
                          rng.uniform(-math.pi, math.pi))  # fmt: skip
            t = clock()
            image = frames[i % len(frames)]
            scores = detector.scores(image)
            values = scores.max(axis=1)
            wedges = CAMERA.wedges(pose, 0.0, spans)
            elevations = best_patch_elevations(
                scores, detector.patch_boxes(image.shape), CAMERA, 0.0
            )
            stages["detect"].append(clock() - t)
            t = clock()
            seen = visibility_from_depth(
                depth, CAMERA, spans, origin=(pose.x, pose.y), axis=pose.yaw, tilt=0.0,
                camera_height=1.0, supports=supports, object_height=0.2, reach=reach,
            )  # fmt: skip
            stages["visibility"].append(clock() - t)
            t = clock()
            per_object = {name: values[k] for k, name in enumerate(names)}
            grid.fuse_all((pose.x, pose.y), wedges, per_object, None, seen)
            belief.fuse_all((pose.x, pose.y), wedges, per_object, None, seen)
            stages["fuse"].append(clock() - t)
            log.append(
                LoggedView((pose.x, pose.y), wedges, per_object, seen, True,
                           {name: elevations[k] for k, name in enumerate(names)}, 1.0)
            )  # fmt: skip
            t = clock()
            for name in names:
                best = grid.peaks(name, k=3, min_separation=0.5).best
                cells, _ = posterior(belief.layer(name), 2.0, 0.1)
                confidence_within(cells, spec, (best.x, best.y), 0.2)
                log.height(name, (best.x, best.y))
            stages["results"].append(clock() - t)
            t = clock()
            grid.save(out / "grid.npz", compress=False)  # as Checkpoint.save does
            log.save(out / "views.npz", compress=False)
            stages["checkpoint"].append(clock() - t)
        log_bytes = (out / "views.npz").stat().st_size
    later = n_views // 2
    medians = {k: 1000.0 * statistics.median(v[later:]) for k, v in stages.items()}
    medians["total"] = sum(medians.values())
    grid_bytes = sum(a.nbytes for a in (grid._evidence, grid._observed, grid._prior))
    grid_bytes += grid._baseline.nbytes
    return {
        "cells": spec.nx * spec.ny,
        "ms": medians,
        "grids_mb": 2 * grid_bytes / 1e6,  # the grid and its belief
        "log_kb_per_view": log_bytes / n_views / 1e3,
        "reach": reach,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=40)
    parser.add_argument("--objects", default="1,4,16")
    args = parser.parse_args()
    counts = [int(n) for n in args.objects.split(",")]
    rng = np.random.default_rng(1)
    detectors = {n: detector_for(n, rng) for n in counts}
    for detector in detectors.values():
        detector.scores(cloudy_background(rng, 240, 320))  # compile / load the kernels
    print(f"{args.views} views per case; ms per view, medians of the later half\n")
    header = (
        f"{'area':28s}{'cells':>8s}{'objects':>8s}{'detect':>8s}{'visib.':>8s}{'fuse':>8s}"
        f"{'results':>9s}{'ckpt':>8s}{'total':>8s}{'grids MB':>10s}{'log kB/view':>12s}"
    )
    print(header)
    for label, extent in areas():
        for n in counts:
            r = run_case(extent, n, args.views, detectors[n])
            ms = r["ms"]
            print(
                f"{label:28s}{r['cells']:8d}{n:8d}{ms['detect']:8.1f}{ms['visibility']:8.1f}"
                f"{ms['fuse']:8.1f}{ms['results']:9.1f}{ms['checkpoint']:8.1f}{ms['total']:8.1f}"
                f"{r['grids_mb']:10.1f}{r['log_kb_per_view']:12.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
