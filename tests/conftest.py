"""Test-wide setup: headless rendering must be chosen before any test module imports mujoco."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")


import pytest


@pytest.fixture(scope="session")
def model_cache(tmp_path_factory):
    """One cache of trained detectors, calibrations and search candidates for every test that
    runs a mission in the twin: each trains once per session, not once per module."""
    return tmp_path_factory.mktemp("rfch-cache")
