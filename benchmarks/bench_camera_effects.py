"""Time the twin's imperfect camera per 320 x 240 frame: each effect alone, the whole chain, and
the rendering it adds (a wider undistorted canvas, 350 x 264, instead of 320 x 240).

    MUJOCO_GL=egl python benchmarks/bench_camera_effects.py

Frames are the living room rendered from the golden pose of tests/test_sim.py; the effects are
the defaults of ``twin.sim.camera_effects`` (the sim camera's ``effects = "realistic"``). Motion
blur is timed at the VC-C4's top pan speed (90 deg/s: a 10 px streak). Also times the
tilt-aware wedges through the lens (first call: the undistortion of every edge pixel; then the
cache a survey hits at every view). Prints medians in milliseconds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

import twin.sim  # noqa: F401  (first: selects headless GL before mujoco loads)
from twin.core.geometry import CameraModel, Pose2D
from twin.sim.camera_effects import CameraEffects, EffectSettings, vcc4_lens
from twin.sim.robot import SimCamera, SimRobot
from twin.sim.world import World

POSE = Pose2D(2.5, 3.3, math.radians(134.0))
PAN_RATE = math.radians(90.0)
SPANS = np.array([[u, u + 32.0] for u in range(0, 289, 16)])


def _median_ms(run: Callable[[], object], repeats: int = 50) -> float:
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def main() -> None:
    lens = vcc4_lens()
    model = CameraModel.with_lens(320, 240, lens)
    robot = SimRobot(World("living_room"), POSE)
    full = CameraEffects(EffectSettings(lens=lens), 320, 240)
    camera = SimCamera(robot, model, effects=full)
    with camera:
        canvas, depth = camera._render_canvas(robot.world.data)
        realistic_grab = _median_ms(camera.grab, 20)
    plain = SimCamera(robot)
    with plain:
        plain_grab = _median_ms(plain.grab, 20)
        frame = plain.grab().image

    rng = np.random.default_rng(0)
    ideal = EffectSettings.ideal()
    lens_only = CameraEffects(replace(ideal, lens=lens), 320, 240)
    flat = {
        "auto exposure": replace(ideal, auto_exposure=True),
        "white balance": replace(ideal, white_balance=True),
        "noise (shot + read)": replace(ideal, noise=True),
        "analog chroma": replace(ideal, analog=True),
        "JPEG q80": replace(ideal, jpeg_quality=80),
    }
    print(f"per 320 x 240 frame, median ms (canvas {full.canvas_size[0]} x {full.canvas_size[1]})")
    print(f"  {'lens (remap colour + depth)':30s} "
          f"{_median_ms(lambda: lens_only.apply(canvas, depth, rng)):6.2f}")  # fmt: skip
    blur = CameraEffects(replace(ideal, motion_blur=True), 320, 240)
    print(f"  {'motion blur at 90 deg/s':30s} "
          f"{_median_ms(lambda: blur.apply(frame, None, rng, (PAN_RATE, 0.0))):6.2f}")  # fmt: skip
    for name, settings in flat.items():
        effects = CameraEffects(settings, 320, 240)
        print(f"  {name:30s} {_median_ms(lambda e=effects: e.apply(frame, None, rng)):6.2f}")
    print(f"  {'whole chain (still head)':30s} "
          f"{_median_ms(lambda: full.apply(canvas, depth, rng)):6.2f}")  # fmt: skip
    panning = _median_ms(lambda: full.apply(canvas, depth, rng, (PAN_RATE, 0.0)))
    print(f"  {'whole chain (panning)':30s} {panning:6.2f}")
    print("grab with depth, median ms")
    print(f"  {'plain renderer (ideal)':30s} {plain_grab:6.2f}")
    print(f"  {'realistic (canvas + chain)':30s} {realistic_grab:6.2f}")
    print("wedges of 19 patch columns through the lens, tilted 10 deg, ms")
    start = time.perf_counter()
    model.wedges(POSE, 0.0, SPANS, tilt=math.radians(10.0))
    print(f"  {'first call (fills the cache)':30s} {1000 * (time.perf_counter() - start):6.2f}")
    cached = _median_ms(lambda: model.wedges(POSE, 0.3, SPANS, tilt=math.radians(10.0)))
    print(f"  {'cached':30s} {cached:6.3f}")


if __name__ == "__main__":
    main()
