"""RFCH speed: one 320×240 frame, every patch scored; per extra object; where the time goes.

Frames and models are those of ``benchmarks/rfch_quality.py`` (objects cut out of real
photographs, pasted into others). Prints figures; nothing is asserted. Timings are medians over
repeated runs after a warm-up (numba compiles, or loads its cache, on the first call).

    /tmp/venv/bin/python benchmarks/bench_rfch.py
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from rfch_quality import cut_outs, photographs, test_frames

from twin.rfch import RFCH, Detector
from twin.rfch.descriptor import raw_descriptors
from twin.rfch.reference import reference_scores


def median_ms(function, repeats: int) -> float:
    function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return 1000.0 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--frames", type=int, default=8, help="frames averaged over (8)")
    args = parser.parse_args()
    cuts = cut_outs()
    photos = photographs()
    frames = [f for f, _ in test_frames(cuts[0], cuts[1:], photos, args.frames, seed=3)]

    def train(cut, **params) -> RFCH:
        images, masks = zip(*cut.views, strict=True)
        return RFCH.train(cut.name, images, masks, **params)

    start = time.perf_counter()
    models = [train(cut) for cut in cuts]
    print(f"training {len(models)} models: {time.perf_counter() - start:.2f} s in all")
    print(
        f"frame 320×240, grid {Detector(models[:1]).grid.shape((240, 320))} patches, "
        f"{models[0].n_clusters} clusters; medians of {args.repeats} runs, mean over "
        f"{len(frames)} frames (machine shared with other jobs: figures are upper bounds)\n"
    )

    # ---- one object, every patch: total and stages
    print("one object (each model alone), ms per frame:")
    print(
        f"{'object':12s}{'total':>8s}{'check':>8s}{'descr':>8s}{'label':>8s}"
        f"{'pairs+∩':>9s}{'labelled':>10s}"
    )
    for model in models:
        detector = Detector([model])
        totals, stages, labelled = [], {}, []
        for frame in frames:
            totals.append(median_ms(lambda d=detector, f=frame: d.scores(f), args.repeats))
            timing: dict[str, float] = {}
            for _ in range(args.repeats):
                detector.scores(frame, timing)
            for key, value in timing.items():
                stages[key] = stages.get(key, 0.0) + 1000.0 * value / args.repeats / len(frames)
            desc = raw_descriptors(frame, model.params, model.params.sample_step)
            labelled.append(float((model.label(desc) >= 0).mean()))
        print(
            f"{model.name:12s}{np.mean(totals):8.2f}{stages['check']:8.2f}"
            f"{stages['descriptor']:8.2f}{stages['labelling']:8.2f}"
            f"{stages['pairs+intersection']:9.2f}{np.mean(labelled):10.0%}"
        )

    # ---- several objects: own codebooks (descriptor shared) vs one shared codebook
    images_masks = {cut.name: tuple(zip(*cut.views, strict=True)) for cut in cuts}
    shared = RFCH.train_shared(images_masks)
    for title, pool in (
        ("own codebook per object (descriptor pass shared)", models),
        ("one shared codebook (labelling and pair counting shared too)", shared),
    ):
        print(f"\nseveral objects in one Detector, {title}, ms per frame:")
        first = None
        for count in range(1, len(pool) + 1):
            detector = Detector(pool[:count])
            total = float(
                np.mean(
                    [median_ms(lambda d=detector, f=f: d.scores(f), args.repeats) for f in frames]
                )
            )
            first = first or total
            if count == 1:
                print(f"  1 object:  {total:6.2f} ms")
            else:
                extra = (total - first) / (count - 1)
                print(
                    f"  {count} objects: {total:6.2f} ms, each extra object {extra:.2f} ms"
                    f" = {extra / first:.0%} of the first"
                )

    # ---- pair counting once per cell group vs once per patch
    detector, per_patch = Detector(models[:1]), Detector(models[:1], share_cells=False)
    cell_ms = np.mean([median_ms(lambda f=f: detector.scores(f), args.repeats) for f in frames])
    patch_ms = np.mean([median_ms(lambda f=f: per_patch.scores(f), args.repeats) for f in frames])
    print(
        f"\n{cuts[0].name}: pairs counted once per cell group {cell_ms:.2f} ms, "
        f"once per patch {patch_ms:.2f} ms (whole frame)"
    )

    # ---- the spec verbatim (sample step 1) and the literal NumPy transcription
    exact = train(cuts[0], sample_step=1)
    frame = frames[0]
    print(
        f"\n{cuts[0].name}, sample step 1 (every pixel, spec verbatim), compiled: "
        f"{median_ms(lambda: exact.scores(frame), max(args.repeats // 3, 3)):.1f} ms"
    )
    start = time.perf_counter()
    reference_scores(models[0], frame)
    print(
        f"{cuts[0].name}, literal NumPy reference, sample step 2: "
        f"{1000 * (time.perf_counter() - start):.0f} ms"
    )
    start = time.perf_counter()
    reference_scores(exact, frame)
    print(
        f"{cuts[0].name}, literal NumPy reference, sample step 1: "
        f"{1000 * (time.perf_counter() - start):.0f} ms"
    )


if __name__ == "__main__":
    main()
