"""Batches of randomized survey missions: many runs of the mission, one summary.

Run ``i`` of a batch with seed ``S`` draws each varied factor from its own generator,
``SeedSequence(S, spawn_key=(i, k))`` with k = 0 target, 1 lighting, 2 threshold, so a run's
draws depend only on (S, i) and on which factors vary, never on the executor, the number of
workers or which worker ran it. The factors:

* **target** — every object with a scene body is put on a random level furniture top
  (``twin.sim.placement.random_surface_pose``); otherwise it stays where the scene has it.
* **lighting** — every scene light's diffuse intensity and the headlight's diffuse and ambient
  are scaled by one factor drawn uniformly from ``lighting`` (default 0.5 .. 1.5: from a dim
  evening room to one brighter than the scene's default; the detector was trained at 1.0).
* **threshold** — a detector threshold drawn uniformly from ``threshold`` (default 0 .. 0.25):
  every patch score below it reads 0 before fusion, so a column whose best patch is below it
  contributes nothing (the same cut as the logodds rule's ``threshold``, applied to any rule).
  Not varied, it is 0: the scores pass unchanged.

Each run is a ``Mission`` flown through the survey's plan, exactly as ``twin survey`` flies it
(no recording, no checkpoint). A worker keeps its MuJoCo world, connected robot and trained
detector between runs (``kept_in_worker``) and resets them before each: the world as loaded
(``World.reset``), the lights at the drawn scale, the robot at the mission's start. A mission in
a reused world is therefore the same as in a fresh one (a test checks it).

Results stream back to the caller, which appends each to ``DIR/runs.jsonl`` as it arrives: a
batch run again into the same folder runs only the missing runs (and may add runs).
"""

from __future__ import annotations

import hashlib
import math
import os
import socket
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from twin.app.executors import Executor, kept_in_worker
from twin.app.planner_names import BATCH_FACTORS
from twin.core.devices import DeviceError
from twin.core.errors import InputError
from twin.core.store import JsonLinesJournal, json_safe

VARY = BATCH_FACTORS
_FACTOR_KEY = {name: k for k, name in enumerate(VARY)}
DEFAULT_LIGHTING = (0.5, 1.5)  # scale of the scene's light intensities
# RFCH patch scores below this read 0. The rendered-frame ROC puts the best cut near 0.16
# (benchmarks/rfch_rendered.py); above ~0.35 the box's own columns are cut and a run says nothing.
DEFAULT_THRESHOLD = (0.0, 0.25)
SUCCESS_RADIUS_M = 0.3
JOURNAL_NAME = "runs.jsonl"


@dataclass(frozen=True)
class BatchSpec:
    """What every run of a batch shares: the config (its text, ``--set`` overrides applied, so
    remote workers need no copy of the file), where its relative paths resolve, the seed and
    the varied factors."""

    config_text: str
    config_name: str
    config_folder: str  # relative scene/model paths resolve here, else in the shipped scenes
    working_dir: str  # run.cache (the trained detector) resolves here
    seed: int = 0
    vary: tuple[str, ...] = VARY
    lighting: tuple[float, float] = DEFAULT_LIGHTING
    threshold: tuple[float, float] = DEFAULT_THRESHOLD
    tolerance: float = SUCCESS_RADIUS_M
    mission: str = "survey"  # or "search": views chosen as it goes (the config's [search])
    height_tolerance: float | None = None  # metres; None: success is judged in the plan only

    def __post_init__(self) -> None:
        if self.mission not in ("survey", "search"):
            raise InputError(f"--mission must be survey or search, got {self.mission!r}")
        unknown = [v for v in self.vary if v not in VARY]
        if unknown:
            raise InputError(
                f"--vary: unknown factor {unknown[0]!r}; choose from {', '.join(VARY)}"
            )
        if self.seed < 0:
            raise InputError(f"--seed must be a non-negative integer, got {self.seed}")
        lo, hi = self.lighting
        if not (0.0 < lo <= hi) or not math.isfinite(hi):
            raise InputError(f"--lighting must be LOW,HIGH with 0 < LOW <= HIGH, got {lo},{hi}")
        lo, hi = self.threshold
        if not (0.0 <= lo <= hi <= 1.0):
            raise InputError(f"--threshold must be LOW,HIGH within [0, 1], got {lo},{hi}")
        if not self.tolerance > 0.0:
            raise InputError(
                f"--tolerance must be a positive distance in metres, got {self.tolerance}"
            )
        if self.height_tolerance is not None and not self.height_tolerance > 0.0:
            raise InputError(
                "--height-tolerance must be a positive distance in metres, got "
                f"{self.height_tolerance}"
            )

    @classmethod
    def from_config(
        cls, name: str | Path | None, overrides: tuple[str, ...] = (), **factors: Any
    ) -> BatchSpec:
        """The spec of a config file (a path or a shipped config's name) with ``--set``
        overrides, checked here so that no worker meets a bad key."""
        from twin.app.config import dump_toml, load_config, resolve_config

        source = resolve_config(name)
        config = load_config(source, overrides=overrides)
        spec = cls(dump_toml(config.data), source.name, str(source.resolve().parent),
                   str(Path.cwd()), **factors)  # fmt: skip
        spec.load()
        return spec

    def identity(self) -> dict[str, Any]:
        """What decides a run's result (the tolerance only scores it, so it is not here)."""
        return {
            "config_sha256": hashlib.sha256(self.config_text.encode()).hexdigest(),
            "seed": self.seed,
            "vary": sorted(self.vary),
            "lighting": list(self.lighting),
            "threshold": list(self.threshold),
            **({"mission": self.mission} if self.mission != "survey" else {}),
        }

    def load(self):
        """The parsed config (``twin.app.config.SurveyConfig``), on whichever machine runs this."""
        from twin.app.config import ConfigError, parse_config

        try:
            data = tomllib.loads(self.config_text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{self.config_name}: not valid TOML ({exc}); fix the file") from None
        config = parse_config(
            data, self.config_name, Path(self.config_folder), Path(self.working_dir)
        )
        kinds = {d.type for d in config.devices.values()}
        if kinds != {"sim"}:
            raise InputError(
                f"{self.config_name}: randomized missions run in the simulation only; "
                'give every robot device type = "sim"'
            )
        if not any(o.body is not None for o in config.objects):
            raise InputError(
                f"{self.config_name}: objects: randomized missions score estimates against a scene "
                "body; give each object a body"
            )
        return config


@dataclass(frozen=True)
class MissionDraw:
    """A run's randomized factors (1.0 and 0.0 when not varied; target: seed of its draw)."""

    run: int
    lighting: float
    threshold: float
    place_target: bool
    camera_seed: int | None = None  # the camera's noise seed; None: the config's


def factor_rng(seed: int, run: int, factor: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, _FACTOR_KEY[factor])))


def draw_mission(spec: BatchSpec, run: int) -> MissionDraw:
    """Run ``run``'s factors: a function of (seed, run, factor) only."""
    lighting = 1.0
    threshold = 0.0
    if "lighting" in spec.vary:
        lighting = float(factor_rng(spec.seed, run, "lighting").uniform(*spec.lighting))
    if "threshold" in spec.vary:
        threshold = float(factor_rng(spec.seed, run, "threshold").uniform(*spec.threshold))
    camera_seed = None
    if "camera" in spec.vary:
        camera_seed = int(factor_rng(spec.seed, run, "camera").integers(2**31))
    return MissionDraw(run, lighting, threshold, "target" in spec.vary, camera_seed)


class ThresholdedDetector:
    """A detector whose patch scores below ``threshold`` read 0 (a ``PatchDetector``)."""

    def __init__(self, detector, threshold: float) -> None:
        self.detector = detector
        self.threshold = threshold

    @property
    def names(self) -> list[str]:
        return self.detector.names

    @property
    def models(self) -> list:
        """The detector's models: a search's planner reads their calibration (of the scores
        before the cut: for choosing views an estimate is enough)."""
        return self.detector.models

    def scores(self, image: np.ndarray) -> np.ndarray:
        scores = self.detector.scores(image)
        if self.threshold <= 0.0:
            return scores
        return np.where(scores >= self.threshold, scores, 0.0).astype(scores.dtype, copy=False)

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray:
        return self.detector.patch_boxes(shape)

    def column_spans(self, width: int) -> np.ndarray:
        return self.detector.column_spans(width)


class MissionWorld:
    """One worker's MuJoCo world, connected robot and trained detector, reused between runs."""

    def __init__(self, spec: BatchSpec) -> None:
        from twin.app.detection import mission_detector
        from twin.app.factory import build_robot

        self.config = config = spec.load()
        self.robot, context = build_robot(config)
        self.sim = context.sim
        self.start = context.start
        self.targets = {o.name: o.body for o in config.objects if o.body is not None}
        # quiet: the detector is trained before workers start
        self.detector, self.rooms = mission_detector(config, lambda _: None)
        self.robot.connect()
        self.camera_seed = getattr(self.robot.camera, "seed", 0)  # the config's, for every run
        from twin.app.visibility_models import build_visibility

        occupancy = getattr(self.robot.base, "map", None)
        self.visibility = build_visibility(
            config, self.sim.world, self.robot.camera.model, occupancy
        )

    def reset(self, spec: BatchSpec, draw: MissionDraw) -> dict[str, str]:
        """Put the world in run ``draw``'s state; returns the furniture each target stands on."""
        from twin.app.run import place_bodies_randomly

        world = self.sim.world
        world.reset()
        world.scale_lighting(draw.lighting)
        if draw.place_target:
            rng = factor_rng(spec.seed, draw.run, "target")
            place_bodies_randomly(world, list(self.targets.values()), rng, self._passable())
        self.sim.place(self.start)
        self._restart_devices(draw)
        return {name: world.support_of(body) for name, body in self.targets.items()}

    def _passable(self) -> Callable[[], bool] | None:
        """With a base that plans (laser localization), a placement must leave every stop of
        the mission reachable: a crate across the only door ends a survey before it has seen
        anything, and says nothing about finding objects."""
        from twin.app.localization import LaserLocalizedBase
        from twin.app.run import stops_reachable

        base = self.robot.base
        if not isinstance(base, LaserLocalizedBase):
            return None
        settings = base.settings
        return stops_reachable(
            self.sim.world, base.map, (self.start.x, self.start.y), self.config.mission.stops,
            settings.robot_radius, settings.margin,
        )  # fmt: skip

    def _restart_devices(self, draw: MissionDraw) -> None:
        """Devices that keep state of their own start afresh, as in a new world: the camera's
        noise, exposure and white balance (from the run's own seed when the batch varies the
        camera, else the config's), the laser's noise, and a localized base's filter (around
        the mission's start)."""
        from twin.app.localization import LaserLocalizedBase
        from twin.sim.laser import SimLaser
        from twin.sim.robot import SimCamera

        if isinstance(self.robot.camera, SimCamera):
            seed = self.camera_seed if draw.camera_seed is None else draw.camera_seed
            self.robot.camera.restart(seed)
        if isinstance(self.robot.laser, SimLaser):
            self.robot.laser.restart()
        if isinstance(self.robot.base, LaserLocalizedBase):
            localization = self.config.localization
            global_start = localization is not None and localization.global_start
            self.robot.base.restart(None if global_start else self.start)

    def close(self) -> None:
        self.robot.close()


def run_batch_mission(spec: BatchSpec, run: int) -> dict[str, Any]:
    """One randomized mission (the task a worker runs); returns its JSON-ready result."""
    from twin.app.mission import Mission
    from twin.app.run import make_grids
    from twin.app.search import follow_up, path_length
    from twin.app.survey import plan_views, run_survey
    from twin.app.visibility_models import build_height_check

    started = time.perf_counter()
    key = repr(sorted(spec.identity().items())) + spec.config_folder + spec.working_dir
    world, reused = kept_in_worker(key, partial(MissionWorld, spec), MissionWorld.close)
    config = world.config
    draw = draw_mission(spec, run)
    surfaces = world.reset(spec, draw)
    grid, belief = make_grids(config, world.detector, world.rooms)
    sim = world.sim
    truth = {
        name: tuple(float(v) for v in sim.world.body_position(body))
        for name, body in world.targets.items()
    }
    mission = Mission(
        world.robot,
        ThresholdedDetector(world.detector, draw.threshold),
        grid,
        max_range=config.grid.max_range,
        truth=truth,
        truth_pose=sim.truth_pose,
        visibility=world.visibility,
        fuse_visibility=config.grid.visibility,
        belief=belief,
        confidence_options=config.confidence,
        height_check=build_height_check(config, world.visibility),
        stands_on={obj.name: obj.stands_on for obj in config.objects},
        object_heights=config.object_heights,
    )
    setup = time.perf_counter() - started
    plan = plan_views(config.mission, world.robot.pantilt.limits, config.floor_objects)
    search: dict[str, Any] = {}
    failed: dict[str, str] = {}
    searcher = None
    try:
        if spec.mission == "search":
            from twin.app.search import make_searcher

            searcher = make_searcher(config, mission, sim.world, plan)
            stopped = searcher.run()
            search = {"search": {"planner": config.search.planner, "stopped": stopped,
                                 "unreachable": searcher.unreachable}}  # fmt: skip
        else:
            run_survey(mission, plan)
            followed = follow_up(config, mission, sim.world, plan)
            if followed is not None:
                search = {"follow_up": followed}
    except DeviceError as exc:
        # The robot could not go on (touched something, lost its way): the run is a failed
        # mission, counted as one, and the batch goes on; the error says what happened.
        failed = {"failed": str(exc)}
        if spec.mission == "search":
            refused = searcher.unreachable if searcher is not None else []
            search = {"search": {"planner": config.search.planner, "stopped": f"failed: {exc}",
                                 "unreachable": refused}}  # fmt: skip
    result = mission.result(config.grid.peak_separation)
    for name, surface in surfaces.items():
        result["objects"][name]["surface"] = surface
    return {
        "run": run,
        "lighting": draw.lighting,
        "threshold": draw.threshold,
        "camera_seed": draw.camera_seed,
        "objects": json_safe(result["objects"]),
        "views": result["views"],
        "views_refused": len(result["views_refused"]),  # not fused: unsure pose, stop not reached
        "time_s": result["robot_time_s"],
        "path_length_m": round(path_length(world.robot.base.planner, mission.state.path), 3),
        **search,
        **failed,
        "timings_s": {
            "setup": round(setup, 3),
            **result["timings_s"],
            "mission": round(time.perf_counter() - started, 3),
        },
        "reused_world": reused,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


# -- the batch, resumably ----------------------------------------------------------------------


class BatchJournal:
    """``DIR/runs.jsonl``: the batch's identity, then one finished run per line, appended as
    each arrives. A torn last line is ignored (that run runs again)."""

    def __init__(self, path: Path, spec: BatchSpec, fresh: bool = False) -> None:
        self.path = path
        self._journal = JsonLinesJournal(path, "batch", spec.identity(), fresh)
        self.done: dict[int, dict[str, Any]] = {}
        for entry in self._journal.entries:
            try:
                self.done[int(entry["run"])] = entry
            except (KeyError, TypeError, ValueError):
                continue

    def record(self, result: dict[str, Any]) -> None:
        self._journal.append(result)
        self.done[int(result["run"])] = result


def prepare(spec: BatchSpec, say: Callable[[str], None] = print) -> None:
    """Train (or load) the detector once here, before workers start, so local workers find it
    cached instead of each training it; and refuse a follow-up it cannot weigh views for
    (``check_follow_up``) before any run."""
    from twin.app.detection import mission_detector
    from twin.app.search import check_follow_up

    config = spec.load()
    detector, _ = mission_detector(config, say)
    if spec.mission == "survey" and config.search.follow_up_views > 0:
        check_follow_up(detector)


def run_batch(
    spec: BatchSpec,
    runs: int,
    executor: Executor,
    journal: BatchJournal | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every run of 0..runs-1 not in ``journal``; return all results in run order."""
    if runs < 1:
        raise InputError(f"--runs must be at least 1, got {runs}")
    done = dict(journal.done) if journal else {}
    todo = [i for i in range(runs) if i not in done]
    for _, result in executor.map_unordered(partial(run_batch_mission, spec), todo):
        if journal:
            journal.record(result)
        done[int(result["run"])] = result
        if on_result:
            on_result(result)
    return [done[i] for i in range(runs)]
