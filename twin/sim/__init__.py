"""The MuJoCo twin: scenes, the Peoplebot-like robot, its sim devices, and training views.

Importing this package selects headless rendering (``MUJOCO_GL=egl``) unless the user chose a
backend already; it must happen before anything imports ``mujoco``, hence here, first.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
