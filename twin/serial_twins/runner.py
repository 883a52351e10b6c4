"""Steps the MuJoCo world in step with a clock, so emulated devices move as real ones would.

The runner thread advances simulated time to ``time_scale`` x the clock time elapsed since it
started (1.0 on the system clock: real time; more for quicker runs) under the robot's lock;
emulators command the sim (wheel speeds, head goals) and read it (odometry, head angles) under
the same lock, and so does the sim camera when it renders a frame. On a test's ``ManualClock``
the world keeps exact pace with virtual time, however slow the machine.
"""

from __future__ import annotations

import threading

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.sim.robot import SimRobot


class WorldRunner:
    """A daemon thread that keeps ``robot``'s world at ``time_scale`` x ``clock`` time."""

    def __init__(
        self,
        robot: SimRobot,
        time_scale: float = 1.0,
        max_lag: float = 0.5,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        if not time_scale > 0.0:
            raise ValueError(f"time_scale must be positive, got {time_scale!r}")
        self.robot, self.time_scale, self.max_lag, self.clock = robot, time_scale, max_lag, clock
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> WorldRunner:
        self._thread = self.clock.start_thread(self._run, name="world-runner")
        return self

    def _run(self) -> None:
        robot, clock, scale = self.robot, self.clock, self.time_scale
        clock0 = clock.now()
        with robot.lock:
            sim0 = robot.world.time
            timestep = float(robot.world.model.opt.timestep)
        while not self._stop.is_set():
            target = sim0 + (clock.now() - clock0) * scale
            with robot.lock:
                now = robot.world.time
                if target - now > self.max_lag * scale:
                    # Fell behind (a slow machine): catch up by skipping, not by racing.
                    sim0 += target - now - self.max_lag * scale
                    target = sim0 + (clock.now() - clock0) * scale
                steps = 0
                while robot.world.time < target and steps < 50:
                    robot.step()
                    steps += 1
                # the clock time until the next step is due (a little, if still behind)
                wait = (robot.world.time + timestep - target) / scale
            clock.sleep(max(wait, 0.0005))

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self.clock.join(self._thread, 2.0)

    def __enter__(self) -> WorldRunner:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
