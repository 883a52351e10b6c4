"""One survey run from its folder: build everything the config names, fly the mission, report.

``twin survey`` prepares the folder (a copy of the config and the run's options) and calls
``run_mission``; a resumed run calls it again on the same folder.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from twin.app.config import SurveyConfig, load_config
from twin.app.plots import grid_figure
from twin.app.record import NullRecorder, Recorder, RerunRecorder, SceneInfo
from twin.app.survey import CHECKPOINT_GRID, SurveyContext, estimates, plan_views, run_survey
from twin.core.errors import InputError, TwinError
from twin.core.grid import AccumulatorGrid
from twin.core.store import json_safe, write_text_atomic

RESULT_FILE = "result.json"
RECORDING_FILE = "recording.rrd"


def run_mission(
    out: Path,
    options: dict[str, Any],
    resume: bool,
    started: float,
    quiet: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Run or resume the survey in ``out``; returns (and writes) ``result.json``'s content.

    ``on_result`` sees the result as soon as it is written, before a ``serve`` recorder keeps
    serving viewers until Ctrl-C."""
    from twin.app.factory import BuildContext, build_robot, uses_sim_world

    config = load_config(
        out / "config.toml",
        base_dir=Path(options["working_dir"]),
        folder=Path(options["config_source"]).parent,
    )
    context = BuildContext(config)
    if options.get("place_target") == "random":
        if not uses_sim_world(config):
            raise InputError("--place-target random works in the simulation only")
        # Before any serial twin starts stepping the world: placing edits the model.
        _place_target_randomly(config, context, int(options.get("seed", 0)))
    robot, context = build_robot(config, context)
    try:
        return _fly(config, robot, context, out, options, resume, started, quiet, on_result)
    finally:
        context.close()


def _fly(config, robot, context, out, options, resume, started, quiet, on_result) -> dict[str, Any]:
    """The run proper, once the devices (and any serial twins) exist."""
    from twin.app.detection import prepare_detector

    setup_started = time.perf_counter()
    truth = _truth(config, context)
    scene = _scene_info(config, context, truth)
    say = (lambda _: None) if quiet else print
    detector = prepare_detector(config.objects, config.detector, config.cache, say)
    grid = _grid(config, out, resume)
    recorder = _recorder(out, options, resume)
    plan = plan_views(config.mission, robot.pantilt.limits)
    recorder.begin(scene, grid, len(plan))
    setup_time = time.perf_counter() - setup_started

    from tqdm import tqdm

    done = grid.views(grid.objects[0])
    bar = tqdm(
        total=len(plan),
        initial=done,
        unit="view",
        desc="survey",
        disable=quiet or not sys.stderr.isatty(),
    )
    n_stops = len(config.mission.stops)

    def on_view(view) -> None:
        bar.set_description(f"stop {view.stop + 1}/{n_stops}")
        if view.index > done:
            bar.update()

    survey = SurveyContext(
        robot, detector, grid, config.mission, out, config.grid.max_range, recorder
    )
    try:
        with robot, bar:
            state = run_survey(survey, on_view=on_view, resume=resume)
            bar.update()
    finally:
        recorder.end()
    grid.save(out / "grid.npz")
    result = {
        "objects": estimates(
            grid, {k: v[:2] for k, v in truth.items()}, config.grid.peak_separation
        ),
        "views": state.views_done,
        "timings_s": {
            **{k: round(v, 3) for k, v in state.timings.items() if k != "total"},
            "setup": round(setup_time, 3),
            "total": round(time.perf_counter() - started, 3),
        },
        "grid": {
            "extent_m": list(scene.extent),
            "cell_size_m": grid.spec.cell_size,
            "fusion": grid.rule.name,
        },
        "target_placement": options.get("place_target", "config"),
    }
    for name in grid.objects:
        entry = result["objects"][name]
        grid_figure(
            out / f"grid_{name}.png",
            grid.layer(name),
            scene.extent,
            f"{name}: accumulator grid after {state.views_done} views",
            [(f.name, f.polygon) for f in scene.furniture if f.name not in truth],
            estimate=tuple(entry["estimate_m"]),
            truth=tuple(entry["truth_m"]) if "truth_m" in entry else None,
        )
    write_text_atomic(out / RESULT_FILE, json.dumps(json_safe(result), indent=1))
    if on_result is not None:
        on_result(result)
    recorder.wait()
    return result


def _place_target_randomly(config: SurveyConfig, context, seed: int) -> None:
    from twin.sim.placement import random_surface_pose

    rng = np.random.default_rng(seed)
    for obj in config.objects:
        if obj.body is not None:
            random_surface_pose(context.sim.world, obj.body, rng)


def _truth(config: SurveyConfig, context) -> dict[str, tuple[float, float, float]]:
    """Where the objects are (simulation only: the real robot has no ground truth)."""
    if context._sim is None:
        return {}
    world = context.sim.world
    return {
        obj.name: tuple(float(v) for v in world.body_position(obj.body))
        for obj in config.objects
        if obj.body is not None
    }


def _scene_info(config: SurveyConfig, context, truth) -> SceneInfo:
    """The room's outline and furniture from the scene file (the map, on the real robot too)."""
    from twin.sim import World

    world = context.sim.world if context._sim is not None else World(config.scene)
    furniture = tuple(world.footprints()[name] for name in world.furniture())
    return SceneInfo(world.room_bounds(), furniture, dict(truth))


def _grid(config: SurveyConfig, out: Path, resume: bool) -> AccumulatorGrid:
    names = [obj.name for obj in config.objects]
    checkpoint = out / CHECKPOINT_GRID
    if resume and checkpoint.is_file():
        grid = AccumulatorGrid.load(checkpoint)
        if list(grid.objects) != names or grid.spec != config.grid.spec:
            raise TwinError(f"{checkpoint} does not match the run's config; start a new run")
        return grid
    return AccumulatorGrid(names, config.grid.spec, config.grid.rule, config.grid.supersample)


def _recorder(out: Path, options: dict[str, Any], resume: bool) -> Recorder:
    mode = options.get("rerun", "save")
    if mode == "off":
        return NullRecorder()
    path = out / RECORDING_FILE
    if resume and path.exists():
        k = 1
        while (out / f"recording-resumed-{k}.rrd").exists():
            k += 1
        path = out / f"recording-resumed-{k}.rrd"
    return RerunRecorder(
        mode,
        path,
        bind=options.get("rerun_bind", "127.0.0.1"),
        recording_id=options.get("recording_id"),
    )
