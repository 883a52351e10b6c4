"""RFCH on the twin's rendered frames: ROC over patch columns, with exact segmentation masks.

    python benchmarks/rfch_rendered.py [--random-views 160] [--seed 0]

Frames come from the robot's camera in the living room: the default mission's 40 views and
``--random-views`` more from random free poses with random headings. Each frame's rice-box mask
is MuJoCo's segmentation rendering, so a column's truth is exact (``twin.rfch.roc``). Prints the
ROC AUC, the threshold minimizing P_fp + P_fn and its rates (what the grid's ``logodds`` rule
takes), how often the best column is the box when it is in view, and the mean column score over
the chair (coloured like the box) against other furniture.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from twin.app.config import load_config
from twin.app.detection import prepare_detector
from twin.app.survey import column_values, plan_views
from twin.core.geometry import Pose2D
from twin.rfch.roc import column_truth, roc_curve
from twin.sim import SimRobot, World
from twin.sim.render import FrameRenderer
from twin.sim.robot import CAMERA_NAME, ROBOT_CLEARANCE


def body_mask(world: World, segment: np.ndarray, body: str) -> np.ndarray:
    geoms = np.nonzero(world.model.geom_bodyid == world.body_id(body))[0]
    return np.isin(segment, geoms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random-views", type=int, default=160)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
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
