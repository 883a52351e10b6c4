"""RFCH on the twin's rendered frames: ROC over patch columns, with exact segmentation masks.

    python benchmarks/rfch_rendered.py [--random-views 160] [--seed 0]
    python benchmarks/rfch_rendered.py --views-table [--placements 12] [--table-seed 700000]

Frames come from the robot's camera in the living room: the default mission's 40 views and
``--random-views`` more from random free poses with random headings. Each frame's rice-box mask
is MuJoCo's segmentation rendering, so a column's truth is exact (``twin.rfch.roc``). Prints the
ROC AUC, the threshold minimizing P_fp + P_fn and its rates (what the grid's ``logodds`` rule
takes), how often the best column is the box when it is in view, and the mean column score over
the chair (coloured like the box) against other furniture.

``--views-table``: one view vs several views per object. Every object of the training stage
is trained (all on one shared codebook, as the survey trains them) from today's single camera
drop (0.4 m) or from four elevations (``ELEVATION_DROPS``), each as one merged histogram or
with its views clustered into a few models (``views="clustered"``). Each is scored on
head-camera frames of the object's own scene with the object at random furniture tops
(``calibration_views``; seeds from ``--table-seed``, outside the reserved calibration range and
the 500000s used while developing), clean and through the VC-C4 camera effects
(``twin.sim.camera_effects``, lens included). Per object and variant:
column AUC, TPR at a 5 % FPR, and how often the frame's best column is on the object.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from twin.app.config import load_config
from twin.app.detection import prepare_detector
from twin.app.survey import plan_views
from twin.core.geometry import Pose2D
from twin.rfch.roc import column_truth, roc_curve
from twin.sim import SimRobot, World
from twin.sim.render import FrameRenderer
from twin.sim.robot import CAMERA_NAME, ROBOT_CLEARANCE
from twin.sim.training import calibration_views


def column_values(scores: np.ndarray) -> np.ndarray:
    """(objects, cols): each patch column's best score, what the grid update uses."""
    return scores.max(axis=1)


def body_mask(world: World, segment: np.ndarray, body: str) -> np.ndarray:
    geoms = np.nonzero(world.model.geom_bodyid == world.body_id(body))[0]
    return np.isin(segment, geoms)


# The scene each training-stage object is sought in (where its random placements are drawn).
OBJECT_SCENES = {
    "rice_box": "living_room",
    "tea_tin": "apartment",
    "game_box": "apartment",
    "toy_crate": "apartment",
}
TABLE_FPR = 0.05


def views_table(placements: int, seed: int, effects: bool) -> None:
    """Print the one-view vs several-views ROC table (module docstring)."""
    import time

    from twin.rfch import Detector
    from twin.sim.camera_effects import CameraEffects, EffectSettings, vcc4_lens
    from twin.sim.robot import PAPER_CAMERA
    from twin.sim.training import CALIBRATION_SEED, ELEVATION_DROPS, training_views

    if CALIBRATION_SEED <= seed < CALIBRATION_SEED + 1000 + placements:
        raise SystemExit(f"--table-seed {seed} overlaps the reserved calibration seeds")
    targets = [t for t in World("training_stage").targets() if t in OBJECT_SCENES]
    start = time.perf_counter()
    frames = {}
    camera = CameraEffects(
        EffectSettings(lens=vcc4_lens(PAPER_CAMERA.width, PAPER_CAMERA.height)),
        PAPER_CAMERA.width,
        PAPER_CAMERA.height,
    )
    for k, target in enumerate(targets):
        common = dict(
            scene=OBJECT_SCENES[target],
            target=target,
            n_placements=placements,
            views_per_placement=16,
            seed=seed + 1000 * k,
            aimed_fraction=0.5,
        )
        frames[target, "clean"] = calibration_views(**common)
        if effects:
            camera.reset()
            frames[target, "VC-C4"] = calibration_views(**common, effects=camera)
    print(f"rendered the test frames in {time.perf_counter() - start:.0f} s")
    recipes = {
        "merged, 1 elevation": ({"views": "merged"}, (0.4,)),
        "merged, 4 elevations": ({"views": "merged"}, ELEVATION_DROPS),
        "clustered, 1 elevation": ({"views": "clustered"}, (0.4,)),
        "clustered, 4 elevations": ({"views": "clustered"}, ELEVATION_DROPS),
    }
    views = {
        drops: {t: training_views(target=t, camera_drop=drops) for t in targets}
        for drops in {d for _, d in recipes.values()}
    }
    print(
        f"\n{'object':10s} {'training':26s} {'frames':6s} {'models':>6s} {'AUC':>6s} "
        f"{'TPR@5%':>7s} {'best col':>9s}"
    )
    for target in targets:
        for name, (params, drops) in recipes.items():
            detector = Detector.train(
                {t: (list(i), list(m)) for t, (i, m) in views[drops].items()}, **params
            )
            index = detector.names.index(target)
            for kind in ("clean", "VC-C4") if effects else ("clean",):
                data = frames[target, kind]
                scores, truths, hits, visible = [], [], 0, 0
                for image, mask in zip(data.images, data.masks, strict=True):
                    values = column_values(detector.scores(image))[index]
                    truth = column_truth(mask, detector.grid)
                    scores.append(values)
                    truths.append(truth)
                    if (truth == 1).any():
                        visible += 1
                        hits += int(truth[int(np.argmax(values))] == 1)
                roc = roc_curve(np.concatenate(scores), np.concatenate(truths))
                _, _, p_fn = roc.choose(max_fp=TABLE_FPR)
                print(
                    f"{target:10s} {name:26s} {kind:6s} "
                    f"{len(detector.models[index].histograms):6d} {roc.auc:6.3f} "
                    f"{1.0 - p_fn:7.2f} {hits:4d}/{visible:<4d}"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random-views", type=int, default=160)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--views-table", action="store_true", help="one vs several views")
    parser.add_argument("--placements", type=int, default=12, help="per object (table)")
    parser.add_argument("--table-seed", type=int, default=700_000, help="first seed (table)")
    parser.add_argument(
        "--no-effects", action="store_true", help="table: clean frames only (no VC-C4 row)"
    )
    args = parser.parse_args()
    if args.views_table:
        views_table(args.placements, args.table_seed, not args.no_effects)
        return
    config = load_config()
    detector = prepare_detector(config.objects, config.detector, config.cache)
    grid = detector.grid
    world = World(config.scene)
    robot = SimRobot(world)
    views = [(v.base, v.pan) for v in plan_views(config.mission, robot.head_limits)]
    rng = np.random.default_rng(args.seed)
    while len(views) < 40 + args.random_views:
        x, y = rng.uniform(0.3, 4.2), rng.uniform(0.3, 5.7)
        try:
            world.check_free(x, y, ROBOT_CLEARANCE, "view")
        except Exception:
            continue
        views.append((Pose2D(x, y, rng.uniform(-math.pi, math.pi)), 0.0))
    renderer = FrameRenderer(world.model, 320, 240, CAMERA_NAME)
    scores, truths, chair, other, hits, visible = [], [], [], [], 0, 0
    for base, pan in views:
        robot.place(base, pan)
        image = renderer.render(world.data)
        segment = renderer.segment(world.data)
        values = column_values(detector.scores(image))[0]
        truth = column_truth(body_mask(world, segment, "rice_box"), grid)
        scores.append(values)
        truths.append(truth)
        if (truth == 1).any():
            visible += 1
            hits += int(truth[int(np.argmax(values))] == 1)
        chair_cols = column_truth(body_mask(world, segment, "chair"), grid) == 1
        chair += list(values[chair_cols & (truth == 0)])
        other += list(values[~chair_cols & (truth == 0)])
    roc = roc_curve(np.concatenate(scores), np.concatenate(truths))
    threshold, p_fp, p_fn = roc.choose()
    print(f"{len(views)} rendered frames, {roc.positives} box columns, {roc.negatives} others")
    print(
        f"ROC AUC {roc.auc:.3f}; threshold {threshold:.3f} gives P_fp {p_fp:.3f}, P_fn {p_fn:.3f}"
    )
    print(
        f"best column is the box in {hits}/{visible} frames where the box is in view "
        f"({100 * hits / max(visible, 1):.0f} %)"
    )
    print(
        f"mean column score: chair {np.mean(chair):.3f} ({len(chair)} columns), "
        f"other non-box columns {np.mean(other):.3f}"
    )
    renderer.close()


if __name__ == "__main__":
    main()
