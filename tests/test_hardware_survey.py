"""The survey flown by the real drivers against the serial twins, and the hardware commands."""

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from twin.cli import main

REDUCED = "mission.stops=[[1.1, 1.2], [2.5, 3.3], [2.7, 4.4]]"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


def reduced(cache: Path, *sets: str) -> list[str]:
    """--set arguments: the reduced mission, no recording, a shared model cache, and ``sets``."""
    settings = (REDUCED, "run.rerun=off", f"run.cache={cache}", *sets)
    return [arg for setting in settings for arg in ("--set", setting)]


def survey(config: str, out: Path, sets: list[str]) -> dict:
    argv = ["survey", "--config", config, "--out", str(out), "--quiet", *sets]
    assert main(argv) == 0
    return json.loads((out / "result.json").read_text())["objects"]["rice_box"]


def test_the_real_drivers_fly_the_mission_on_the_twins_to_the_same_cell(tmp_path, cache):
    """ARCOS driver + VC-C4 driver (on AUX1) over pseudo-terminals to the emulators, world at
    2x (faster, the 100 ms SIP cycle coarsens the base's control and its odometry slips): the
    estimate lands in the same cell as the pure-sim run of the same mission or in one next to
    it (diagonals too: the realistic camera's noise falls on other frames in each run)."""
    twins = survey(
        "living_room_serial_twins",
        tmp_path / "twins",
        reduced(cache, "serial_twins.time_scale=2.0"),
    )
    sim = survey("living_room_survey", tmp_path / "sim", reduced(cache))
    apart = np.subtract(twins["estimate_m"][:2], sim["estimate_m"][:2])
    assert np.abs(apart).max() <= 0.1 + 1e-9  # cells are 0.1 m
    assert twins["error_m"] < 0.2 and sim["error_m"] < 0.2


def test_serve_hardware_answers_probe_and_the_drivers_commands(tmp_path, capsys):
    links = tmp_path / "links"
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "serve-hardware",
            "--seconds",
            "30",
            "--time-scale",
            "4",
            "--link-dir",
            str(links),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert "serving" in "".join(server.stdout.readline() for _ in range(3))
        assert (
            main(
                [
                    "hw",
                    "probe",
                    "--port",
                    str(links / "arcos"),
                    "--port",
                    str(links / "vcc4"),
                    "--port",
                    "/dev/null",
                ]
            )
            == 0
        )
        printed = capsys.readouterr().out
        assert "ARCOS robot 'twin' (Pioneer peoplebot-sh)" in printed
        assert f"{links / 'vcc4'}: VC-C4 answers" in printed
        assert "/dev/null: no ARCOS robot and no VC-C4 answers" in printed
        assert main(["hw", "vcc4", "--port", str(links / "vcc4"), "goto", "-30", "10"]) == 0
        assert "pan -30.0" in capsys.readouterr().out
        assert main(["hw", "arcos", "--port", str(links / "arcos"), "status"]) == 0
        assert "battery" in capsys.readouterr().out
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_hardware_configs_name_bad_devices_in_one_line(tmp_path, cache, capsys):
    out = tmp_path / "new" / "run"
    argv = ["survey", "--config", "living_room_serial_twins", "--out", str(out), "--quiet"]
    started = time.monotonic()
    code = main([*argv, *reduced(cache, "robot.base.port=/dev/no-such-port")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "ARCOS base: open /dev/no-such-port: no such port" in err
    assert time.monotonic() - started < 30  # a missing port fails fast, never a long timeout
    assert not (tmp_path / "new").exists()  # a false start leaves no run folder to trip over


def test_a_line_pulled_mid_mission_is_recovered_and_no_view_is_lost(tmp_path, cache):
    from twin.app.config import load_config
    from twin.app.detection import prepare_detector
    from twin.app.factory import BuildContext, build_robot
    from twin.app.mission import Mission
    from twin.app.survey import plan_views, run_survey
    from twin.core.grid import AccumulatorGrid

    sets = reduced(cache, "serial_twins.time_scale=2.0")[1::2]
    config = load_config("living_room_serial_twins", overrides=sets)
    context = BuildContext(config)
    robot, context = build_robot(config, context)
    grid = AccumulatorGrid(["rice_box"], config.grid.spec)
    detector = prepare_detector(config.objects, config.detector, config.cache, lambda _: None)

    def pull_the_cable(view):
        if view.index in (5, 14):
            context.twins.hangup("arcos")  # the head rides on the base's AUX1 line too

    try:
        with robot:
            mission = Mission(robot, detector, grid)
            run_survey(mission, plan_views(config.mission, robot.pantilt.limits), pull_the_cable)
        arcos = getattr(robot.base, "inner", robot.base)  # under the laser localizer, if any
        reconnects = arcos.reconnects
    finally:
        context.close()
    assert mission.views_done == 24 and grid.views("rice_box") == 24
    assert reconnects >= 2
    best = grid.peaks("rice_box", k=1, min_separation=0.5).best
    assert math.dist((best.x, best.y), (1.5, 5.0)) < 0.2
