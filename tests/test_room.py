"""The room's own look without the object: a per-cell baseline that a look-alike cannot hide in."""

from __future__ import annotations

import math

import numpy as np

from twin.app.room import fill_unseen, room_baselines, room_log
from twin.core.fusion import make_rule
from twin.core.geometry import CameraModel
from twin.core.grid import AccumulatorGrid, GridSpec
from twin.core.visibility import SupportLevels

CAMERA = CameraModel()
SPANS = np.array([[u, u + 32] for u in range(0, 320, 32)], dtype=float)
SPEC = GridSpec(0.0, 0.0, 14.0, 14.0, 0.1)  # its far corner beyond every view's 8 m reach
BOWL = (3.0, 3.0)  # a look-alike in the middle of the room


def _views(n: int, rng: np.random.Generator):
    """Views from random spots on a ring round the bowl, facing it: the columns that see it
    score 0.6, the rest 0.05; one column of every fifth view is on the sought object."""
    poses, scores, truth = [], [], []
    for k in range(n):
        angle = rng.uniform(0, 2 * math.pi)
        x, y = BOWL[0] + 2 * math.cos(angle), BOWL[1] + 2 * math.sin(angle)
        yaw = math.atan2(BOWL[1] - y, BOWL[0] - x) + rng.uniform(-0.3, 0.3)
        bearing = math.atan2(BOWL[1] - y, BOWL[0] - x) - yaw
        column = int(np.clip(CAMERA.bearing_column(bearing) // 32, 0, 9))
        values = np.full(10, 0.05)
        values[column] = 0.6
        labels = np.zeros(10, int)
        if k % 5 == 0:
            labels[(column + 3) % 10] = 1
            values[(column + 3) % 10] = 0.9
        poses.append((x, y, yaw))
        scores.append(values)
        truth.append(labels)
    return np.array(poses), scores, truth


def test_the_room_baseline_marks_the_look_alike_and_leaves_the_object_out():
    poses, scores, truth = _views(40, np.random.default_rng(4))
    depths = np.full((40, CAMERA.height, CAMERA.width), np.nan, np.float32)  # nothing hides
    supports = SupportLevels.anywhere((0, 0, 6, 6))
    log = room_log("box", poses, depths, scores, truth, CAMERA, SPANS, supports, 0.2, 8.0)
    assert len(log) == 40
    # The object's columns are seen nowhere: they say nothing about the room.
    first = log.views[0]
    on_object = int(np.argmax(truth[0]))
    assert not first.visibility.profiles[on_object].any()
    assert first.visibility.profiles[(on_object + 1) % 10].any()
    baseline = room_baselines({"box": log}, {"box": make_rule("accumulate")}, SPEC, 4)["box"]
    bowl = (int(BOWL[1] / 0.1), int(BOWL[0] / 0.1))
    assert baseline[bowl] > 0.3  # the bowl's cell: seen from every side, always scoring high
    assert np.median(baseline[baseline > 0]) < 0.2  # elsewhere the room's usual is low
    # A corner no view reached takes the room's usual look, not a free pass.
    assert 0.0 < baseline[-1, -1] < 0.2


def test_a_cell_the_room_never_saw_is_no_hole_for_a_look_alike():
    baseline = np.full((9, 9), 0.2)
    baseline[4, 6] = 0.5  # a look-alike's cell, trusted
    trusted = np.ones((9, 9), bool)
    trusted[3:6, 3:6] = False  # a 0.3 m patch the room's views missed, next to it
    trusted[0, 0] = False
    filled = fill_unseen(np.where(trusted, baseline, 0.0), trusted)
    assert filled[4, 5] == 0.5  # the look-alike's neighbour takes its value
    assert filled[4, 3] == 0.2  # the patch's far side, its own neighbours'
    assert (filled[~trusted] > 0).all()
    np.testing.assert_array_equal(filled[trusted], baseline[trusted])
    far = np.zeros((20, 20), bool)
    far[:2, :2] = True  # a whole region never seen, farther than the fill reaches
    lone = fill_unseen(np.where(far, 0.3, 0.0), far, cells=3)
    assert lone[19, 19] == 0.3  # the room's median
    assert not fill_unseen(np.zeros((3, 3)), np.zeros((3, 3), bool)).any()  # nothing to go on


def test_a_look_alike_loses_its_hold_on_the_estimate():
    rng = np.random.default_rng(5)
    poses, scores, truth = _views(40, rng)
    depths = np.full((40, CAMERA.height, CAMERA.width), np.nan, np.float32)
    supports = SupportLevels.anywhere((0, 0, 6, 6))
    log = room_log("box", poses, depths, scores, truth, CAMERA, SPANS, supports, 0.2, 8.0)
    rule = make_rule("accumulate")
    baseline = room_baselines({"box": log}, {"box": rule}, SPEC, 4)
    # A mission that sees the bowl (0.6) from three sides and the box at (1.5, 4.5) (0.7) from
    # two: the paper's rule goes to the bowl, the baseline hands it to the box.
    from twin.core.geometry import Pose2D
    from twin.core.visibility import ColumnVisibility

    box = (int(4.5 / 0.1), int(1.5 / 0.1))
    bowl = (int(BOWL[1] / 0.1), int(BOWL[0] / 0.1))
    margins = []
    for base in (None, baseline):
        grid = AccumulatorGrid(["box"], SPEC, rule, 4, baseline=base)
        for origin, target, value in [((3.0, 1.0), BOWL, 0.6), ((5.0, 3.0), BOWL, 0.6),
                                      ((3.0, 5.0), BOWL, 0.6), ((0.5, 2.5), (1.5, 4.5), 0.7),
                                      ((3.5, 4.5), (1.5, 4.5), 0.7)]:  # fmt: skip
            yaw = math.atan2(target[1] - origin[1], target[0] - origin[0])
            wedges = CAMERA.wedges(Pose2D(*origin, yaw), 0.0, SPANS)
            values = np.full(10, 0.05)
            values[4:6] = value
            seen = ColumnVisibility.everywhere(10, 8.0)
            grid.fuse_all(origin, wedges, {"box": values}, None, seen)
        layer = grid.layer("box")
        margins.append(layer[box] - layer[bowl])
    assert margins[0] < 0 < margins[1]
