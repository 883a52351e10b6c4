"""RFCH per stage, before and after the step-11 speed work, interleaved on the held-out frame.

The "before" kernels and descriptor are the repository's own at commit ``BEFORE`` (read with
``git show``, compiled beside today's), so both run in one process, alternating call by call:
on a machine shared with other jobs the load then falls on both alike, which separate runs
cannot promise. Frame and objects are ``bench_rfch_heldout``'s (trained on the left view of the
stereo pair, scoring the right); every object shares one codebook. Also printed: how far the
scores moved (the descriptor's float rounding moved, so a few near-tie labels flip).

    .venv/bin/python benchmarks/bench_rfch_before_after.py [--repeats 150]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from bench_rfch_heldout import OBJECTS, held_out_pair

from twin.rfch import Detector, kernels
from twin.rfch.descriptor import raw_descriptors, sample_bounds

BEFORE = "91a444a"  # the last commit before the step-11 detector work
STAGES = ("descriptor", "labelling", "pairs+∩", "total")


def old_kernels(folder: Path):
    source = subprocess.run(
        ["git", "show", f"{BEFORE}:twin/rfch/kernels.py"],
        capture_output=True, text=True, check=True, cwd=Path(__file__).parent,
    ).stdout  # fmt: skip
    path = folder / "rfch_kernels_before.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("rfch_kernels_before", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def old_descriptors(image, params, step):
    """The descriptor as it was at ``BEFORE``: OpenCV derivative filters over the whole frame."""
    picked = image[::step, ::step]
    planes = cv2.split(picked.astype(np.float32))
    total = planes[0] + planes[1] + planes[2]
    dark = total <= 0.0
    inverse = 1.0 / np.where(dark, np.float32(1.0), total)
    third = np.float32(1.0 / 3.0)
    channels = [
        np.where(dark, third, planes[0] * inverse),
        np.where(dark, third, planes[1] * inverse),
    ]
    full = cv2.split(image.astype(np.float32))
    intensity = np.log((full[0] + full[1] + full[2]) * third + np.float32(params.intensity_offset))
    for sigma in params.sigmas:
        smooth = cv2.GaussianBlur(intensity, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)[::step, ::step]
        gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)[::step, ::step]
        channels.append(cv2.magnitude(gx, gy) * np.float32(sigma))
        lap = cv2.Laplacian(smooth, cv2.CV_32F, ksize=1)[::step, ::step]
        channels.append(lap * np.float32(sigma * sigma))
    return cv2.merge(channels)


def pipeline(detector: Detector, frame: np.ndarray, kernel_module, describe):
    """A function running the three stages once, appending seconds per stage to a dict."""
    model, params = detector.models[0], detector.models[0].params
    step, grid = params.sample_step, detector.grid
    widths = kernels.half_widths(params.d_max, step)
    rows = sample_bounds(grid.starts(frame.shape[0]), grid.size, step)
    cols = sample_bounds(grid.starts(frame.shape[1]), grid.size, step)
    cell, span, row_cells, col_cells = kernels.cell_layout(rows, cols, len(widths) - 1)
    members, histograms, owners = detector._groups[0]

    def run(times: dict[str, list[float]]) -> np.ndarray:
        t0 = time.perf_counter()
        desc = describe(frame, params, step)
        t1 = time.perf_counter()
        labels = kernel_module.label_samples(
            desc, model.offset, model.scale, model.centres, model.radius**2
        )
        t2 = time.perf_counter()
        out = kernel_module.cell_patch_scores(
            labels, widths, cell, span, row_cells, col_cells, histograms, owners, len(members)
        )
        t3 = time.perf_counter()
        for stage, seconds in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2, t3 - t0), strict=True):
            times[stage].append(seconds)
        return out

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=150)
    args = parser.parse_args()
    train, masks, frame = held_out_pair()
    with tempfile.TemporaryDirectory() as folder:
        before_kernels = old_kernels(Path(folder))
        print(f"ms per 320×240 frame, median (fastest) of {args.repeats} interleaved runs")
        for count in (1, 4, 8):
            names = list(OBJECTS)[:count]
            detector = Detector.train({n: ([train], [masks[n]]) for n in names})
            runs = {
                "before": pipeline(detector, frame, before_kernels, old_descriptors),
                "after": pipeline(detector, frame, kernels, raw_descriptors),
            }
            times = {k: {s: [] for s in STAGES} for k in runs}
            first = {k: run({s: [] for s in STAGES}) for k, run in runs.items()}
            moved = np.abs(first["before"] - first["after"])
            print(
                f"\n{count} object(s) on one codebook: scores moved by at most {moved.max():.4f} "
                f"({int((moved > 0).sum())} of {moved.size} patches)"
            )
            for i in range(args.repeats):
                for kind in ("before", "after") if i % 2 else ("after", "before"):
                    runs[kind](times[kind])
            for kind, stages in times.items():
                print(
                    f"  {kind:7s}"
                    + "".join(
                        f"  {s} {1000 * statistics.median(v):5.2f} ({1000 * min(v):5.2f})"
                        for s, v in stages.items()
                    )
                )


if __name__ == "__main__":
    main()
