"""Test-wide setup: headless rendering must be chosen before any test module imports mujoco."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
