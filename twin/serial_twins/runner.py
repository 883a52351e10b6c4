"""Steps the MuJoCo world in wall-clock time, so emulated devices move as real ones would.

The runner thread advances simulated time to ``time_scale`` x the wall time elapsed since it
started (1.0: real time; more for quicker tests) under the robot's lock; emulators command the
sim (wheel speeds, head goals) and read it (odometry, head angles) under the same lock, and so
does the sim camera when it renders a frame.
"""

from __future__ import annotations

import threading
import time

from twin.sim.robot import SimRobot


class WorldRunner:
    """A daemon thread that keeps ``robot``'s world at ``time_scale`` x wall-clock time."""

    def __init__(self, robot: SimRobot, time_scale: float = 1.0, max_lag: float = 0.5) -> None:
        if not time_scale > 0.0:
            raise ValueError(f"time_scale must be positive, got {time_scale!r}")
        self.robot, self.time_scale, self.max_lag = robot, time_scale, max_lag
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="world-runner", daemon=True)

    def start(self) -> WorldRunner:
        self._thread.start()
        return self

    def _run(self) -> None:
        robot = self.robot
        wall0 = time.monotonic()
        with robot.lock:
            sim0 = robot.world.time
        while not self._stop.is_set():
            target = sim0 + (time.monotonic() - wall0) * self.time_scale
            with robot.lock:
                now = robot.world.time
                if target - now > self.max_lag * self.time_scale:
                    # Fell behind (a slow machine): catch up by skipping, not by racing.
                    sim0 += target - now - self.max_lag * self.time_scale
                    target = sim0 + (time.monotonic() - wall0) * self.time_scale
                steps = 0
                while robot.world.time < target and steps < 50:
                    robot.step()
                    steps += 1
            time.sleep(0.001 if steps else 0.002)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def __enter__(self) -> WorldRunner:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
