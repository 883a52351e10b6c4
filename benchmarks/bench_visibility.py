"""Time the visibility model per view: the profiles from depth, and each source of depth.

    MUJOCO_GL=egl python benchmarks/bench_visibility.py

The reference case: 20 patch columns x 160 distance bins (8 m in 5 cm bins), 4 pixel columns
sampled per patch column, from depth of the living room rendered at 12 camera poses around the
room. Supports are either a model-like 3 levels per cell (floor, seat/table, shelf) or
``SupportLevels.anywhere`` (11 levels, 0-2 m: no model). Goal: profiles in <= 5 ms per view.
Also times the depth sources: the twin camera's extra depth pass, ``ModelDepth.render`` and
``depth_from_map`` on the scene's laser map. Prints medians in milliseconds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import partial

import numpy as np

import twin.sim  # noqa: F401  (first: selects headless GL before mujoco loads)
from twin.core.geometry import CameraModel
from twin.core.visibility import SupportLevels, visibility_from_depth
from twin.nav.maps import load_map
from twin.nav.visibility import depth_from_map
from twin.resources import scenes_dir
from twin.sim.model_view import ModelDepth
from twin.sim.robot import make_sim_robot

CAMERA = CameraModel()
COLUMNS = 20
SPANS = np.stack(
    [np.linspace(0, CAMERA.width - 32, COLUMNS), np.linspace(32, CAMERA.width, COLUMNS)], axis=1
)
EXTENT = (0.0, 0.0, 4.5, 6.0)  # the living room's floor, metres


def _median_ms(run: Callable[[], object], repeats: int) -> float:
    run()  # warm up (compiles the kernel on a first run)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def _poses(count: int) -> list[tuple[float, float, float]]:
    """Camera (x, y, axis) spread around the room, each looking across it."""
    rng = np.random.default_rng(0)
    poses = []
    for _ in range(count):
        x, y = rng.uniform(1.0, 3.5), rng.uniform(1.5, 4.5)
        poses.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    return poses


def _profiles(
    depth: np.ndarray, pose: tuple[float, float, float], supports: SupportLevels
) -> object:
    x, y, axis = pose
    return visibility_from_depth(
        depth,
        CAMERA,
        SPANS,
        origin=(x, y),
        axis=axis,
        tilt=0.0,
        camera_height=1.0,
        supports=supports,
        object_height=0.3,
        reach=8.0,
    )


def main() -> None:
    poses = _poses(12)
    model_like = SupportLevels(0.0, 0.0, 0.1, np.broadcast_to([0.0, 0.45, 1.2], (60, 45, 3)).copy())
    anywhere = SupportLevels.anywhere(EXTENT)
    with ModelDepth("living_room", CAMERA, ["rice_box"]) as model:
        depths = [model.render(x, y, 1.0, axis, 0.0) for x, y, axis in poses]
        render_ms = _median_ms(lambda: model.render(*poses[0][:2], 1.0, poses[0][2], 0.0), 20)

    print(f"visibility profiles, {COLUMNS} columns x 160 bins, median over {len(poses)} views (ms)")
    for name, supports in (("3 levels per cell", model_like), ("anywhere, 11 levels", anywhere)):
        per_view = [
            _median_ms(partial(_profiles, depth, pose, supports), 10)
            for depth, pose in zip(depths, poses, strict=True)
        ]
        print(f"  {name:22s} median {np.median(per_view):6.2f}  worst view {max(per_view):6.2f}")

    print("depth sources, one view (ms)")
    print(f"  ModelDepth.render (living room, robot and target hidden): {render_ms:6.2f}")
    occupancy = load_map(scenes_dir() / "living_room_map.yaml")
    x, y, axis = poses[0]
    map_ms = _median_ms(
        lambda: depth_from_map(
            occupancy, CAMERA, origin=(x, y), axis=axis, tilt=0.0, camera_height=1.0
        ),
        20,
    )
    print(f"  depth_from_map (living room laser map): {map_ms:6.2f}")
    _sim, robot = make_sim_robot()
    camera = robot.camera
    camera.connect()
    with_depth = _median_ms(camera.grab, 20)
    camera.depth = False  # type: ignore[attr-defined]
    without = _median_ms(camera.grab, 20)
    camera.close()
    print(f"  SimCamera.grab with depth {with_depth:6.2f}, without {without:6.2f}")


if __name__ == "__main__":
    main()
