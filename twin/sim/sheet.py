"""The contact sheet: 8 views, 45 degrees apart, from each of five stops spread over the room.

It shows what the survey's detector will see. At each stop the robot is placed (the start of a
leg) and then turns physically, by its wheels, to each heading with the pan at zero.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from twin.core.geometry import Pose2D
from twin.sim.render import write_png
from twin.sim.robot import ROBOT_CLEARANCE, SimRobot
from twin.sim.world import DEFAULT_SCENE, World

# Five stops spread over the living room, clear of the furniture (x, y in metres).
LIVING_ROOM_STOPS: tuple[tuple[float, float], ...] = (
    (1.1, 1.2),
    (3.0, 2.0),
    (2.5, 3.3),
    (1.2, 3.2),
    (2.7, 4.4),
)


def survey_views(
    robot: SimRobot,
    stops: Sequence[tuple[float, float]],
    views: int = 8,
) -> list[list[tuple[Pose2D, np.ndarray]]]:
    """For each stop, the (odometry pose, image) of ``views`` headings 360/views degrees apart."""
    rows = []
    with robot.devices() as devices:
        for x, y in stops:
            robot.place(Pose2D(x, y, 0.0))
            row = []
            for k in range(views):
                devices.base.go_to(Pose2D(x, y, 2.0 * math.pi * k / views))
                view = devices.capture()
                row.append((view.pose, view.image))
            rows.append(row)
    return rows


def contact_sheet(rows: list[list[tuple[Pose2D, np.ndarray]]], scale: float = 1.0) -> np.ndarray:
    """Tile the views (RGB) with a caption under each: stop number, position, heading."""
    tiles = []
    for s, row in enumerate(rows):
        line = []
        for pose, image in row:
            tile = (
                image
                if scale == 1.0
                else cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
            )
            caption = np.full((18, tile.shape[1], 3), 255, np.uint8)
            text = f"stop {s + 1} ({pose.x:.1f}, {pose.y:.1f})  yaw {math.degrees(pose.yaw):.0f}"
            cv2.putText(
                caption, text, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA
            )
            framed = np.concatenate([tile, caption], axis=0)
            line.append(np.pad(framed, ((2, 2), (2, 2), (0, 0)), constant_values=255))
        tiles.append(np.concatenate(line, axis=1))
    return np.concatenate(tiles, axis=0)


def make_contact_sheet(
    out: str | Path,
    scene: str = DEFAULT_SCENE,
    stops: Sequence[tuple[float, float]] = LIVING_ROOM_STOPS,
    scale: float = 1.0,
) -> Path:
    world = World(scene)
    for k, (x, y) in enumerate(stops):
        world.check_free(x, y, ROBOT_CLEARANCE, f"stop {k + 1}")
    robot = SimRobot(world)
    return write_png(out, contact_sheet(survey_views(robot, stops), scale))
