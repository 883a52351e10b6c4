"""The MuJoCo twin: scenes, the Peoplebot-like robot, its sim devices, and training views.

Importing this package selects headless rendering (``MUJOCO_GL=egl``) unless the user chose a
backend already; it must happen before anything imports ``mujoco``, hence here, first.

Typical use (units: metres, radians)::

    from twin.core.geometry import Pose2D
    from twin.sim import make_sim_robot
    sim, robot = make_sim_robot("living_room")      # SimRobot (truth, world) + devices.Robot
    with robot:
        robot.base.go_to(Pose2D(2.5, 3.3, 0.0))
        robot.pantilt.move_to(math.radians(30))
        view = robot.capture()                      # image, odometry pose, pan, tilt, time
    sim.truth_pose(); sim.world.body_position("rice_box"); sim.world.footprints()
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

# Imported after the line above on purpose: each of these imports mujoco.
from twin.core.geometry import Footprint
from twin.sim.robot import SimRobot, make_sim_robot
from twin.sim.training import training_views
from twin.sim.world import World

__all__ = ["Footprint", "SimRobot", "World", "make_sim_robot", "training_views"]
