"""RFCH speed on a photograph nobody tuned to: train on one view of a stereo pair, score the other.

scikit-image's ``stereo_motorcycle`` is a real stereo pair of a garage. Objects are masked in
the LEFT view (the motorcycle's tank, wheels, engine, lamp, seat, and two boxes on the shelf),
both views are cropped to 4:3 and resized to 320×240, and every patch of the RIGHT view (which
no parameter was chosen on) is scored. Shown: one object, then 2 / 4 / 8 objects on one shared
codebook (``Detector.train``, what a user writes) and on own codebooks per object; per stage
(descriptor, labelling, pairs + intersection) for each. Prints figures, asserts nothing.

Timings are medians over ``--repeats`` runs after a warm-up, on a 2-core machine shared with
other jobs: read them as upper bounds. Also shown: the fastest run (the cost when the core was
free) and the median CPU time of the calling thread (time spent computing, not waiting for the
core; OpenCV's blur may add a little on a second thread).

    .venv/bin/python benchmarks/bench_rfch_heldout.py [--repeats 60]
"""

from __future__ import annotations

import argparse
import statistics
import time

import cv2
import numpy as np
import skimage.data

from twin.rfch import RFCH, Detector
from twin.rfch.descriptor import raw_descriptors

FRAME_W, FRAME_H = 320, 240
CROP_X0 = 37  # px of the 741×500 views: a 667×500 (4:3) window keeping both wheels


def _polygon(points) -> np.ndarray:
    mask = np.zeros((500, 741), np.uint8)
    cv2.fillPoly(mask, [np.array(points, np.int32)], 1)
    return mask.astype(bool)


def _ellipse(centre, axes) -> np.ndarray:
    mask = np.zeros((500, 741), np.uint8)
    cv2.ellipse(mask, centre, axes, 0, 0, 360, 1, -1)
    return mask.astype(bool)


# Object masks in the left view's full-resolution pixels, in the order they are added.
OBJECTS = {
    "tank": lambda: _polygon([(330, 170), (500, 150), (505, 240), (420, 250), (330, 250)]),
    "rear_wheel": lambda: _ellipse((200, 330), (80, 70)),
    "engine": lambda: _polygon([(330, 250), (480, 250), (470, 370), (330, 370)]),
    "front_wheel": lambda: _ellipse((595, 370), (85, 80)),
    "lamp": lambda: _ellipse((540, 155), (30, 32)),
    "seat": lambda: _polygon([(150, 165), (330, 175), (330, 215), (150, 200)]),
    "red_box": lambda: _polygon([(550, 185), (615, 185), (615, 250), (550, 250)]),
    "carton": lambda: _polygon([(615, 190), (690, 190), (690, 275), (615, 275)]),
}


def _frame(view: np.ndarray) -> np.ndarray:
    crop = view[:, CROP_X0 : CROP_X0 + 667]
    return cv2.resize(crop, (FRAME_W, FRAME_H), interpolation=cv2.INTER_AREA)


def _mask(mask: np.ndarray) -> np.ndarray:
    crop = mask[:, CROP_X0 : CROP_X0 + 667].astype(np.uint8)
    return cv2.resize(crop, (FRAME_W, FRAME_H), interpolation=cv2.INTER_NEAREST).astype(bool)


def held_out_pair() -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """(left 320×240 training frame, {object: its mask there}, right 320×240 test frame)."""
    left, right, _ = skimage.data.stereo_motorcycle()
    return _frame(left), {name: _mask(make()) for name, make in OBJECTS.items()}, _frame(right)


def median_ms(function, repeats: int) -> float:
    return timings_ms(function, repeats)[0]


def timings_ms(function, repeats: int) -> tuple[float, float, float]:
    """(median wall, fastest wall, median thread CPU) milliseconds per call."""
    function()
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.thread_time()
        function()
        wall.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - start_cpu)
    return 1000 * statistics.median(wall), 1000 * min(wall), 1000 * statistics.median(cpu)


def stage_ms(detector: Detector, frame: np.ndarray, repeats: int) -> dict[str, float]:
    """Median ms per stage (each stage's median over the runs)."""
    detector.scores(frame)
    runs: dict[str, list[float]] = {}
    for _ in range(repeats):
        timing: dict[str, float] = {}
        detector.scores(frame, timing)
        for key, value in timing.items():
            runs.setdefault(key, []).append(1000.0 * value)
    return {key: statistics.median(values) for key, values in runs.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=60)
    args = parser.parse_args()
    train_frame, masks, test_frame = held_out_pair()
    names = list(OBJECTS)
    own = {name: RFCH.train(name, [train_frame], [masks[name]]) for name in names}
    print(
        f"held-out stereo pair: trained on the left view, scoring the right one "
        f"({FRAME_W}×{FRAME_H}, {Detector([own['tank']]).grid.shape((FRAME_H, FRAME_W))} "
        f"patches); medians of {args.repeats} runs (2-core machine shared with other jobs)\n"
    )
    header = (
        f"{'objects':>8s}{'codebook':>10s}{'total':>8s}{'fastest':>8s}{'cpu':>7s}{'descr':>7s}"
        f"{'label':>7s}{'pairs+∩':>9s}{'labelled':>10s}{'extra/obj':>11s}"
    )
    print(header)
    first: dict[str, float] = {}
    for count in (1, 2, 4, 8):
        chosen = names[:count]
        shared = Detector.train({n: ([train_frame], [masks[n]]) for n in chosen})
        for kind, detector in (("shared", shared), ("own", Detector([own[n] for n in chosen]))):
            if count == 1 and kind == "own":
                continue  # one object alone: its own codebook is the shared one
            total, fastest, cpu = timings_ms(lambda d=detector: d.scores(test_frame), args.repeats)
            stages = stage_ms(detector, test_frame, args.repeats)
            model = detector.models[0]
            desc = raw_descriptors(test_frame, model.params, model.params.sample_step)
            labelled = float((model.label(desc) >= 0).mean())
            first.setdefault(kind, first.get("shared", total))
            extra = "" if count == 1 else f"{(total - first[kind]) / (count - 1) / first[kind]:.0%}"
            print(
                f"{count:8d}{kind:>10s}{total:8.2f}{fastest:8.2f}{cpu:7.2f}"
                f"{stages['descriptor']:7.2f}{stages['labelling']:7.2f}"
                f"{stages['pairs+intersection']:9.2f}{labelled:10.0%}{extra:>11s}"
            )
    tank_alone = Detector([own["tank"]])
    tank_in_eight = Detector.train({n: ([train_frame], [masks[n]]) for n in names})
    tank_in_eight = Detector([tank_in_eight.models[0]])
    print(
        f"\ntank alone on its own codebook {median_ms(lambda: tank_alone.scores(test_frame), args.repeats):.2f} ms; "  # noqa: E501
        f"tank alone on the 8-object codebook "
        f"{median_ms(lambda: tank_in_eight.scores(test_frame), args.repeats):.2f} ms"
    )
    best = np.unravel_index(np.argmax(tank_alone.scores(test_frame)[0]), (14, 19))
    box = tank_alone.patch_boxes(test_frame.shape)[best]
    print(f"tank's best patch in the right view: x {box[0]}–{box[2]}, y {box[1]}–{box[3]} px")


if __name__ == "__main__":
    main()
