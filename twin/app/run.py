"""One mission run in its folder: build what the config names, fly the plan, write the results.

A run folder holds ``config.toml`` (the config the run really uses, ``--set`` overrides
included), ``run.json`` (how it was started: ``RunOptions``), the checkpoint, and at the end
``result.json``, ``grid.npz``, ``views.npz`` (``twin.app.view_log``), ``grid_<object>.png``
and the Rerun recording. ``twin survey``
starts a run with ``start_run``; ``twin survey --resume DIR`` continues one with ``resume_run``;
both fly it with ``run_mission``.

An interrupted run (Ctrl-C, SIGTERM, a device error) still writes its results from the last
checkpoint, with ``"status"`` saying why it stopped, and can be resumed; a finished run
(``"status": "complete"``) is never run again.
"""

from __future__ import annotations

import json
import math
import sys
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from twin.app.config import RERUN_MODES, SurveyConfig, dump_toml, load_config, resolve_config
from twin.app.mission import Checkpoint, Mission, MissionState, PoseGate
from twin.app.outputs import check_output_folder, make_output_folder, removed_on_false_start
from twin.app.plots import grid_figure
from twin.app.record import NullRecorder, Recorder, RerunRecorder, SceneInfo
from twin.app.survey import plan_views, run_survey
from twin.app.view_log import ViewLog
from twin.app.visibility_models import build_height_check, build_visibility
from twin.core.errors import InputError, Terminated, TwinError
from twin.core.grid import AccumulatorGrid
from twin.core.store import json_safe, write_text_atomic

RESULT_FILE = "result.json"
VIEWS_FILE = "views.npz"  # every view as numbers, to fuse again with other settings (view_log)
RECORDING_FILE = "recording.rrd"
RUN_CONFIG = "config.toml"
RUN_OPTIONS = "run.json"
RUN_KIND = "twin-survey-run"
PLACEMENTS = ("config", "random")
MISSIONS = ("survey", "search")  # the fixed plan (twin survey), or views chosen as it goes


@dataclass(frozen=True)
class RunOptions:
    """How a run was started (``run.json``): what a resume needs besides the config."""

    config_source: str  # the config file it started from: relative paths in it resolve there
    working_dir: str  # run.out and run.cache resolve here
    place_target: str = "config"
    seed: int = 0
    rerun: str = "save"
    rerun_bind: str = "127.0.0.1"
    recording_id: str = field(default_factory=lambda: str(uuid.uuid4()))
    overrides: tuple[str, ...] = ()  # the --set KEY=VALUE it started with (already in config.toml)
    mission: str = "survey"  # "search": twin search (twin.app.search)

    def to_json(self) -> str:
        return json.dumps({"kind": RUN_KIND, **asdict(self)}, indent=1)

    @classmethod
    def read(cls, folder: Path) -> RunOptions:
        """The options of the run in ``folder``; a one-line error if it holds none or they are
        not what a run writes."""
        path = folder / RUN_OPTIONS
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(
                f"{folder} holds no survey to resume (no {RUN_OPTIONS}); check the folder"
            ) from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{path} is unreadable ({exc}); start a new run") from None
        strings = ("config_source", "working_dir", "place_target", "rerun", "rerun_bind",
                   "recording_id")  # fmt: skip
        ok = isinstance(data, dict) and all(isinstance(data.get(k), str) for k in strings)
        ok = ok and isinstance(data.get("seed"), int) and not isinstance(data.get("seed"), bool)
        ok = ok and data.get("place_target") in PLACEMENTS and data.get("rerun") in RERUN_MODES
        overrides = data.get("overrides", []) if isinstance(data, dict) else None
        ok = ok and isinstance(overrides, list) and all(isinstance(o, str) for o in overrides)
        ok = ok and isinstance(data, dict) and data.get("mission", "survey") in MISSIONS
        if not ok:
            raise InputError(
                f"{path} is not the options of a twin survey run (wrong shape); start a new run"
            )
        return cls(
            data["config_source"],
            data["working_dir"],
            data["place_target"],
            data["seed"],
            data["rerun"],
            data["rerun_bind"],
            data["recording_id"],
            tuple(overrides),
            data.get("mission", "survey"),
        )


def is_run_folder(folder: Path) -> bool:
    return (folder / RUN_OPTIONS).is_file()


@dataclass(frozen=True)
class PreparedRun:
    """A run folder claimed and written, ready for ``run_mission``."""

    folder: Path
    options: RunOptions
    created: list[Path]  # the folders made for it (removed again on a false start)


def start_run(
    config_name: str | Path | None,
    overrides: tuple[str, ...],
    out: Path | None,
    place_target: str = "config",
    seed: int = 0,
    rerun: str | None = None,
    rerun_bind: str = "127.0.0.1",
    mission: str = "survey",
) -> PreparedRun:
    """Check everything that can be checked, then claim the run's folder and write its config
    and options. ``out`` None: a new time-stamped folder below the config's ``run.out``;
    ``mission``: "survey" flies the fixed plan, "search" chooses its views (``twin search``)."""
    source = resolve_config(config_name)
    config = load_config(source, overrides=overrides)
    if place_target == "random" and not config.uses_sim_world:
        raise InputError("--place-target random works in the simulation only")
    if mission == "search" and config.localization is None:
        raise InputError(
            "twin search plans its drives on the localization map: set robot.base.pose_source "
            '= "laser" (with a [localization] map)'
        )
    if out is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out = config.out / stamp
        suffix = 1
        while out.exists():
            suffix += 1
            out = config.out / f"{stamp}-{suffix}"
    flag = "--out"
    if check_output_folder(out, flag, is_run_folder, "a twin survey run"):
        raise InputError(
            f"{out} holds a survey already; continue it with --resume {out}, "
            "or choose another --out"
        )
    options = RunOptions(
        str(source.resolve()),
        str(Path.cwd()),
        place_target,
        seed,
        rerun or config.rerun,
        rerun_bind,
        overrides=tuple(overrides),
        mission=mission,
    )
    created = make_output_folder(out, flag)
    with removed_on_false_start(out, created, lambda: False):
        comment = f"The config this run used: {source}"
        if overrides:
            comment += "\nwith --set " + " --set ".join(overrides)
        write_text_atomic(out / RUN_CONFIG, dump_toml(config.data, comment))
        write_text_atomic(out / RUN_OPTIONS, options.to_json())
    return PreparedRun(out, options, created)


def resume_run(folder: Path) -> PreparedRun | dict[str, Any]:
    """The run in ``folder`` to continue, or its result if it is finished (nothing to do)."""
    if not folder.exists():
        raise InputError(f"--resume {folder}: no such folder; give a run's folder")
    if not folder.is_dir():
        raise InputError(f"--resume {folder}: is a file; give the run's folder")
    options = RunOptions.read(folder)
    result = read_result(folder)
    if result is not None and result.get("status", "complete") == "complete":
        return result
    return PreparedRun(folder, options, [])


def read_result(folder: Path) -> dict[str, Any] | None:
    try:
        data = json.loads((folder / RESULT_FILE).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) else None


def run_mission(
    run: PreparedRun,
    resume: bool,
    started: float,
    quiet: bool = False,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Fly (or continue) the run in ``run.folder``; returns and writes ``result.json``'s content.

    A run that stops before its first view is checkpointed leaves no folder behind; one that
    stops later writes its results so far and re-raises (the command exits 130 on Ctrl-C, 143
    on SIGTERM, 2 on an error). ``on_result`` sees a finished run's result before a ``serve``
    recorder keeps serving viewers until Ctrl-C."""
    from twin.app.factory import BuildContext, build_robot

    out, options = run.folder, run.options
    checkpoint = Checkpoint(out)
    with removed_on_false_start(out, run.created, checkpoint.grid_path.is_file):
        config = load_config(
            out / RUN_CONFIG,
            base_dir=Path(options.working_dir),
            folder=Path(options.config_source).parent,
        )
        context = BuildContext(config)
        try:
            if options.place_target == "random":
                # Before any serial twin starts stepping the world: placing edits the model.
                _place_target_randomly(config, context, options.seed)
            robot, context = build_robot(config, context)
            return _fly(config, robot, context, run, resume, started, quiet, on_result)
        finally:
            context.close()


def _fly(config, robot, context, run, resume, started, quiet, on_result) -> dict[str, Any]:
    """The run proper, once the devices (and any serial twins) exist."""
    from tqdm import tqdm

    from twin.app.detection import mission_detector

    out, options = run.folder, run.options
    setup_started = time.perf_counter()
    sim = context.sim_in_use
    truth = _truth(config, sim)
    # The room: the twin's own world, or on the robot the scene file loaded once as its model.
    world = sim.world if sim is not None else _scene_world(config)
    scene = _scene_info(config, world, truth)
    say = (lambda _: None) if quiet else print
    detector, rooms = mission_detector(config, say)
    grid, belief = make_grids(config, detector, rooms)
    checkpoint = Checkpoint(out)
    state, views = MissionState(), None
    if resume and checkpoint.grid_path.is_file():
        grid, state, views, belief = _checkpointed(checkpoint, config, detector, rooms)
    plan = plan_views(config.mission, robot.pantilt.limits, config.floor_objects)
    recorder = _recorder(out, options, resume, say)
    gate = None
    occupancy = None
    if config.localization is not None:
        o = config.localization
        gate = PoseGate(o.max_sigma_m, math.radians(o.max_sigma_deg))
        occupancy = robot.base.map
        scene = replace(scene, occupancy=occupancy)
    visibility = build_visibility(config, world, robot.camera.model, occupancy)
    mission = Mission(
        robot,
        detector,
        grid,
        recorder=recorder,
        checkpoint=checkpoint,
        state=state,
        max_range=config.grid.max_range,
        truth=truth,
        truth_pose=sim.truth_pose if sim is not None else None,
        pose_gate=gate,
        say=say,
        visibility=visibility,
        fuse_visibility=config.grid.visibility,
        belief=belief,
        confidence_options=config.confidence,
        views=views,
        height_check=build_height_check(config, visibility),
        stands_on={obj.name: obj.stands_on for obj in config.objects},
        object_heights=config.object_heights,
    )
    searcher = None
    follow_views = 0
    if options.mission == "search":
        from twin.app.search import make_searcher

        searcher = make_searcher(config, mission, world, plan, say)
        scene = replace(scene, planner=config.search.planner)
    elif config.search.follow_up_views > 0:
        from twin.app.search import check_follow_up

        check_follow_up(detector)
        follow_views = config.search.follow_up_views
    total = config.search.max_views if searcher is not None else len(plan) + follow_views
    setup_time = time.perf_counter() - setup_started
    n_stops = len(config.mission.stops)
    bar = tqdm(
        total=total,
        initial=mission.views_done,
        unit="view",
        desc=options.mission,
        disable=quiet or not sys.stderr.isatty(),
    )

    def on_view(view) -> None:  # before each view: show the views done so far
        bar.update(mission.views_done - bar.n)
        if searcher is None:
            bar.set_description(f"stop {view.stop + 1}/{n_stops}")
        else:
            bar.set_description(f"place {view.stop + 1}")
            recorder.log_choice(mission.views_done, view, searcher.candidates)

    def on_follow_up(choice, candidates) -> None:  # a view the survey's follow-up chose
        bar.update(mission.views_done - bar.n)
        bar.set_description("follow-up")
        recorder.explain("detection, after the plan")
        recorder.log_choice(mission.views_done, choice, candidates)

    status, stopped_by, stop_reason = "complete", None, None
    followed = None
    try:
        recorder.begin(scene, grid, total)
        with robot, bar:
            if searcher is None:
                run_survey(mission, plan, on_view, beyond=follow_views)
                if follow_views:
                    from twin.app.search import follow_up

                    followed = follow_up(config, mission, world, plan, say, on_follow_up)
            else:
                stop_reason = searcher.run(on_view)
            bar.update(mission.views_done - bar.n)
    except (KeyboardInterrupt, TwinError) as exc:
        stopped_by = exc
        status = _status(exc)
    finally:
        recorder.end()
    if stopped_by is not None:
        if not checkpoint.grid_path.is_file():
            raise stopped_by  # nothing fused yet: nothing to report
        # The grid in memory may hold half a view: report what the checkpoint holds.
        grid, state, views, belief = _checkpointed(checkpoint, config, detector, rooms)
        mission = Mission(
            robot,
            detector,
            grid,
            state=state,
            truth=truth,
            max_range=config.grid.max_range,
            visibility=visibility,
            fuse_visibility=config.grid.visibility,
            belief=belief,
            confidence_options=_confidence(config, options),
            views=views,
            height_check=build_height_check(config, visibility),
            stands_on={obj.name: obj.stands_on for obj in config.objects},
            object_heights=config.object_heights,
        )
    extra = None
    if searcher is not None:
        extra = _search_results(config, stop_reason, searcher.unreachable)
    elif followed is not None:
        extra = {"follow_up": followed}
    result = _write_results(
        config, mission, scene, out, options, status, total, setup_time, started, extra
    )
    if stopped_by is not None:
        raise stopped_by
    if on_result is not None:
        on_result(result)
    recorder.wait()
    return result


def _confidence(config: SurveyConfig, options: RunOptions):
    """How the run reads its confidence (a search with its own temperature)."""
    if options.mission == "search":
        from twin.app.search import search_confidence

        return search_confidence(config)
    return config.confidence


def _checkpointed(checkpoint: Checkpoint, config: SurveyConfig, detector, rooms):
    """The checkpoint's grid, state and view log, and the belief to go with them: the grid
    itself for the calibrated rule, else a fresh one that the ``Mission`` refills from the log."""
    fresh, belief = make_grids(config, detector, rooms)
    grid, state = checkpoint.load(fresh) or (fresh, MissionState())
    views = checkpoint.load_views(state)
    return grid, state, views, grid if config.grid.fusion == "calibrated" else belief


def make_grids(
    config: SurveyConfig, detector, rooms: Mapping[str, ViewLog] | None = None
) -> tuple[AccumulatorGrid, AccumulatorGrid | None]:
    """The mission's grid (the configured rule) and its belief grid (the detector's calibrated
    log-likelihood ratios, for the confidence: the same grid when that is the rule; None when a
    model has no calibration). ``grid.fusion = "calibrated"`` without one is refused.

    ``rooms`` (``twin.app.detection.mission_detector``): the room's look without each object; with
    ``grid.room_baseline`` a grid fused with visibility subtracts what the room gains a cell
    by itself (``twin.app.room``). The baseline is per share of a cell seen, so a blind grid
    (``grid.visibility = false``, or no visibility model) gets none."""
    from twin.app.room import room_baselines

    names = [model.name for model in detector.models]
    missing = [model.name for model in detector.models if model.calibration is None]
    g = config.grid
    calibrated = {
        m.name: m.calibration.rule(by_distance=g.by_distance)
        for m in detector.models
        if m.calibration
    }
    if g.fusion == "calibrated" and missing:
        raise InputError(
            f'grid.fusion = "calibrated" needs each model\'s score calibration; {missing[0]!r} '
            "has none: store one with 'twin roc --store', train it from the scene (objects.NAME."
            "body), or choose another grid.fusion"
        )
    seeing = config.visibility.source != "none"
    rooms = dict(rooms or {}) if g.room_baseline and seeing else {}

    def grid_of(rules: dict[str, Any], fused_seeing: bool = True) -> AccumulatorGrid:
        known = {name: log for name, log in rooms.items() if name in rules and fused_seeing}
        baseline = room_baselines(known, rules, g.spec, g.supersample) if known else None
        return AccumulatorGrid(
            names, g.spec, rules, g.supersample, direction_bins=g.direction_bins, baseline=baseline
        )

    if g.fusion == "calibrated":
        grid = grid_of(calibrated, g.visibility)
        return grid, grid
    belief = None if missing else grid_of(calibrated)  # always fused with visibility
    return grid_of(dict.fromkeys(names, g.rule), g.visibility), belief


def _scene_world(config: SurveyConfig):
    """The scene as a model of the room (the real robot's visibility model and map drawing)."""
    from twin.sim import World

    return World(config.scene)


def _status(exc: BaseException) -> str:
    if isinstance(exc, Terminated):
        return "terminated"
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    return f"failed: {exc}"


def _write_results(
    config: SurveyConfig,
    mission: Mission,
    scene: SceneInfo,
    out: Path,
    options: RunOptions,
    status: str,
    views_planned: int,
    setup_time: float,
    started: float,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write the run's results (``extra``: what the mission kind adds, e.g. a search's)."""
    grid = mission.grid
    grid.save(out / "grid.npz")
    mission.views.save(out / VIEWS_FILE)
    result = mission.result(config.grid.peak_separation)
    result = {
        "status": status,
        **result,
        "views_planned": views_planned,
        "timings_s": {
            **result["timings_s"],
            "setup": round(setup_time, 3),
            "session": round(time.perf_counter() - started, 3),
        },
        "grid": {
            "extent_m": list(scene.extent),
            "cell_size_m": grid.spec.cell_size,
            "fusion": grid.rule.name,
        },
        "target_placement": options.place_target,
    }
    for name in grid.objects:
        entry = result["objects"][name]
        grid_figure(
            out / f"grid_{name}.png",
            grid.layer(name),
            scene.extent,
            f"{name}: accumulator grid after {mission.views_done} views",
            [(f.name, f.polygon) for f in scene.furniture if f.name not in mission.truth],
            estimate=tuple(entry["estimate_m"][:2]),
            truth=tuple(entry["truth_m"][:2]) if "truth_m" in entry else None,
        )
    planner_map = getattr(mission.robot.base, "planner", None)
    if planner_map is not None:
        from twin.app.search import path_length

        result["path_length_m"] = round(path_length(planner_map, mission.state.path), 3)
    result["time_s"] = result["robot_time_s"]
    result["mission"] = options.mission
    result.update(extra or {})
    write_text_atomic(out / RESULT_FILE, json.dumps(json_safe(result), indent=1))
    return result


def _search_results(
    config: SurveyConfig, stop_reason: str | None, unreachable: list[dict[str, Any]]
) -> dict[str, Any]:
    """A search's part of the result: its planner, why it stopped (None: it did not finish)
    and the places the base refused to reach this session."""
    return {
        "search": {
            "planner": config.search.planner,
            "stopped": stop_reason,
            "confidence_goal": config.search.confidence,
            "unreachable": unreachable,
        }
    }


def _place_target_randomly(config: SurveyConfig, context, seed: int) -> None:
    bodies = [obj.body for obj in config.objects if obj.body is not None]
    place_bodies_randomly(context.sim.world, bodies, np.random.default_rng(seed))


PASSABLE_DRAWS = 20  # placements drawn before giving up on one that leaves the way free


def place_bodies_randomly(
    world, bodies: list[str], rng: np.random.Generator, passable: Callable[[], bool] | None = None
) -> None:
    """Put the sought ``bodies`` at random fair spots (sim only). A scene that says which kinds
    of support each target stands on (the apartment's ``twin_target_supports``) places them all
    at once, each on its own kind, apart and in view (``place_targets``); otherwise each goes to
    a random level furniture top in turn (``random_surface_pose``).

    ``passable`` (e.g. ``stops_reachable``) judges a placement: one it refuses (a toy crate
    across the only way out of a room) is drawn again, up to ``PASSABLE_DRAWS`` times, then a
    ``TwinError``. A crate near the way stays: the robot must bump it and go round."""
    from twin.sim.placement import place_targets, random_surface_pose

    kinds = world.target_supports()
    for _ in range(PASSABLE_DRAWS):
        if bodies and all(body in kinds for body in bodies):
            place_targets(world, rng, {body: kinds[body] for body in bodies})
        else:
            for body in bodies:
                random_surface_pose(world, body, rng)
        if passable is None or passable():
            return
    raise TwinError(
        f"no placement of {', '.join(bodies)} in {PASSABLE_DRAWS} draws left the mission's "
        "stops reachable; move the stops off the narrow ways, or place the objects by hand"
    )


def stops_reachable(
    world,
    occupancy,
    start: tuple[float, float],
    stops: Sequence[tuple[float, float]],
    radius: float,
    margin: float,
) -> Callable[[], bool]:
    """A judge for ``place_bodies_randomly``: whether every stop can be reached from ``start``
    (metres) by a robot of ``radius`` + ``margin`` planning on ``occupancy`` with the scene's
    furniture and targets as they stand now (``twin.sim.scene_map.drive_map``)."""
    from twin.app.localization import START_TOLERANCE
    from twin.nav.planner import PathPlanner
    from twin.sim.scene_map import drive_map

    def judge() -> bool:
        planner = PathPlanner(
            drive_map(world, occupancy), radius, margin, unknown_is_obstacle=False
        )
        far = planner.distances_from(start, START_TOLERANCE)
        rows, cols = occupancy.cell_of(*np.asarray(stops, dtype=float).T)
        ny, nx = far.shape
        inside = (rows >= 0) & (rows < ny) & (cols >= 0) & (cols < nx)
        return bool(inside.all() and np.isfinite(far[rows, cols]).all())

    return judge


def _truth(config: SurveyConfig, sim) -> dict[str, tuple[float, float, float]]:
    """Where the objects are (simulation only: the real robot has no ground truth)."""
    if sim is None:
        return {}
    return {
        obj.name: tuple(float(v) for v in sim.world.body_position(obj.body))
        for obj in config.objects
        if obj.body is not None
    }


def _scene_info(config: SurveyConfig, world, truth) -> SceneInfo:
    """The room's outline and furniture from the scene file (the map, on the real robot too)."""
    furniture = tuple(world.footprints()[name] for name in world.furniture())
    return SceneInfo(world.room_bounds(), furniture, dict(truth), config.grid.peak_separation)


def _recorder(out: Path, options: RunOptions, resume: bool, say) -> Recorder:
    if options.rerun == "off":
        return NullRecorder()
    path = out / RECORDING_FILE
    if resume and path.exists():
        k = 1
        while (out / f"recording-resumed-{k}.rrd").exists():
            k += 1
        path = out / f"recording-resumed-{k}.rrd"
    return RerunRecorder(
        options.rerun, path, bind=options.rerun_bind, recording_id=options.recording_id
    )
