"""``twin/ObjectSearch-v0``: learn where to look. One episode is one search mission in the twin.

The agent plays the part of ``twin search``'s planner (``twin.app.search``): before every view it
picks one of the config's candidate views, the robot drives there, turns, pans and takes it with
``Mission.observe`` exactly as a search does, and the view's column scores are fused into the
grid and the calibrated belief. The world is built once (``twin.app.batch.MissionWorld``: the
MuJoCo world, the connected robot, the trained detector, the visibility model) and reset per
episode, so ``reset`` costs a world reset and ``step`` one mission view (about 0.05-0.6 s).

Actions (``Discrete(n_views)``): view ``a`` is candidate place ``a // H`` facing heading
``a % H`` (``H = search.headings``; places ``env.candidates.places[p]`` in metres, headings
``env.candidates.headings[h]`` in radians, map frame: the camera's optical axis). A place within
0.15 m of the robot is reached by turning only. A view the robot cannot reach (no path on the
planning map) or has already taken is not taken: the step is penalised ``INVALID_PENALTY`` and
still counts against the view budget, so every episode ends. ``info["action_mask"]`` marks the
valid ones (int8, 1: reachable and not taken) for masked policies.

Observations (``spaces.Dict``): ``scores`` (objects x columns, float32 in [0, 1]: the last
view's per-column detector match, zeros before the first view); ``pose`` (x m, y m, yaw rad,
float32: the localized pose); ``grid`` (objects x ny x nx, float32: the posterior over cells of
each object's calibrated belief, ``twin.core.confidence.posterior`` with the search's temperature
and ``confidence.p_absent``: what the planners see);
``taken`` (``MultiBinary(n_views)``); with ``observation="image"`` also ``image`` (the last
frame, H x W x 3 uint8, black before the first view).

Reward: minus the robot seconds a view cost / 60 (one per robot minute), ``-INVALID_PENALTY``
for an invalid action, and when the episode ends +1 per object the search declares found
(confidence >= ``search.confidence``) whose estimate lies within ``confidence.radius_m`` of the
truth (the twin knows it). Terminated: every object found or declared absent (``stop_reason``);
truncated: ``max_views`` steps or ``search.max_time_s`` of robot time spent, no valid view left,
or the robot could not go on. A drive the base refuses (no safe path, something unmapped in the
way, a touch it could not get round) is penalised like an invalid action and, as
``Searcher.take`` does, strikes that place off for the episode; ``MAX_REFUSALS`` refusals in a
row, or any other device error, end the episode (``twin batch-survey`` counts that run failed).

Seeding: ``reset(seed=s)`` draws one number ``d`` from the env's generator (``info["draw"]``);
the objects' places (and lighting and threshold, when varied) are then those of run ``d`` of a
``twin batch-survey --seed 0`` with the same config and ``--vary``, so an episode the config's
own planner flies (``env.searcher.planner.choose(env.situation)`` each step) is that batch's
``--mission search`` run ``d``, view for view.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import Any, ClassVar, SupportsFloat

import gymnasium
import numpy as np
from gymnasium import spaces

from twin.app.batch import BatchSpec, MissionWorld, ThresholdedDetector, draw_mission
from twin.app.mission import Mission, estimates
from twin.app.run import make_grids
from twin.app.search import (
    Searcher,
    Situation,
    make_searcher,
    path_length,
    stop_reason,
    verdicts,
    view_choice,
)
from twin.app.survey import plan_views
from twin.app.visibility_models import build_height_check
from twin.core.confidence import posterior
from twin.core.devices import DeviceError
from twin.core.errors import InputError
from twin.core.geometry import wrap_angle

NO_FALLBACK = "search.survey_after=0"  # see ObjectSearchEnv.__init__

OBSERVATIONS = ("scores", "image")
INVALID_PENALTY = 1.0  # reward lost for an unreachable or already taken view (or a failed drive)
FOUND_BONUS = 1.0  # reward per object found (declared and within the radius) at the episode's end
SECONDS_PER_UNIT = 60.0  # one unit of reward per minute of robot time
# draws of the world's randomized factors come from SeedSequence(0, spawn_key=(draw, factor))
DRAW_LIMIT = 2**31 - 1


class ObjectSearchEnv(gymnasium.Env):
    """Find the config's objects in the twin by choosing views (see the module docstring).

    ``config``: a config file or a shipped config's name (default: the shipped living room);
    ``overrides``: ``--set KEY=VALUE`` strings; ``observation``: ``"scores"`` or ``"image"``
    (adds the RGB frame); ``max_views``: steps per episode (default ``search.max_views``);
    ``render_mode``: ``"rgb_array"`` (the last frame) or None; ``vary``: what each reset draws
    anew (``"target"``: the objects' places on the room's furniture; also ``"lighting"`` and
    ``"threshold"``, as ``twin batch-survey --vary``). Relative paths (``run.cache``: the trained
    detector and the candidate views) resolve in the working directory, as ``twin search``'s.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(
        self,
        config: str | None = "living_room_survey",
        overrides: tuple[str, ...] | list[str] = (),
        observation: str = "scores",
        max_views: int | None = None,
        render_mode: str | None = None,
        vary: tuple[str, ...] | list[str] = ("target",),
    ) -> None:
        super().__init__()
        if observation not in OBSERVATIONS:
            raise InputError(
                f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}"
            )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError(f'render_mode must be "rgb_array" or None, got {render_mode!r}')
        if isinstance(overrides, str):
            raise InputError('overrides must be a tuple of "KEY=VALUE" strings, not one string')
        if "target" not in vary:
            raise InputError(
                'vary must include "target": an episode must not always hide the object in the '
                "same place"
            )
        self.observation_mode, self.render_mode = observation, render_mode
        # An action is a candidate view: the search's fallback to the fixed plan (whose views
        # are not candidates) is off, so the config's own planner is a policy of this space.
        overrides = (NO_FALLBACK, *overrides)
        self._spec = BatchSpec.from_config(config, tuple(overrides), vary=tuple(vary))
        self.config = config_ = self._spec.load()
        search = config_.search
        self.max_views = search.max_views if max_views is None else max_views
        if isinstance(self.max_views, bool) or not isinstance(self.max_views, int | np.integer):
            raise InputError(f"max_views must be a positive integer, got {self.max_views!r}")
        if self.max_views < 1:
            raise InputError(f"max_views must be a positive integer, got {self.max_views}")
        self.max_time = float(search.max_time_s)
        self._world: MissionWorld | None = MissionWorld(self._spec)
        world = self._world
        # The grids are the same empty ones every episode (their room baselines take a second
        # to fuse): made once, copied per reset.
        self._empty_grids = make_grids(config_, world.detector, world.rooms)
        if self._empty_grids[1] is None:
            missing = [m.name for m in world.detector.models if m.calibration is None]
            raise InputError(
                f"the environment reads each object's confidence from the detector's calibrated "
                f"belief, and {missing[0]!r} has no calibration: store one with 'twin roc "
                "--store', or give it a scene body to train from (objects.NAME.body)"
            )
        self._plan = plan_views(config_.mission, world.robot.pantilt.limits, config_.floor_objects)
        self.objects: tuple[str, ...] = self._empty_grids[0].objects
        self._truth: dict[str, tuple[float, float, float]] = {}
        # A first searcher, on a mission never flown, builds (or loads) the candidate views and
        # checks the config can search (a laser-localized base) before anyone calls reset.
        self._mission: Mission | None = None
        self._searcher: Searcher = self._new_searcher(self._new_mission(world.detector))
        self.candidates = self._searcher.candidates
        self._mission = None  # that mission was only a probe

        camera = world.robot.camera.model
        n_columns = len(world.detector.column_spans(camera.width))
        spec = config_.grid.spec
        x0, y0, x1, y1 = world.robot.base.planner.map.extent
        self._pose_low = np.array([x0, y0, -math.pi], dtype=np.float32)
        self._pose_high = np.array([x1, y1, math.pi], dtype=np.float32)
        n_objects = len(self.objects)
        fields: dict[str, spaces.Space[Any]] = {
            "scores": spaces.Box(0.0, 1.0, (n_objects, n_columns), np.float32),
            "pose": spaces.Box(self._pose_low, self._pose_high, dtype=np.float32),
            "grid": spaces.Box(0.0, 1.0, (n_objects, spec.ny, spec.nx), np.float32),
            "taken": spaces.MultiBinary(self.candidates.n_views),
        }
        self._frame_shape = (camera.height, camera.width, 3)
        if observation == "image":
            fields["image"] = spaces.Box(0, 255, self._frame_shape, np.uint8)
        self.observation_space = spaces.Dict(fields)
        self.action_space = spaces.Discrete(self.candidates.n_views)

        # The episode (set by reset).
        self._situation: Situation | None = None
        self._scores = np.zeros((n_objects, n_columns), dtype=np.float32)
        self._frame: np.ndarray | None = None
        self._surfaces: dict[str, str] = {}
        self._steps = self._invalid = 0
        self._path_m = 0.0
        self._done = False
        self._fault: str | None = None
        self._draw = -1
        self._last: dict[str, Any] = {}

    # -- the public state -----------------------------------------------------------------------

    @property
    def searcher(self) -> Searcher:
        """The episode's ``twin.app.search.Searcher``: its ``planner`` is the config's
        (``search.planner``), e.g. for a greedy baseline ``searcher.planner.choose(situation)``."""
        return self._searcher

    @property
    def situation(self) -> Situation:
        """What a planner knows now (``twin.app.search.Situation``): pose, every view's cost in
        robot seconds, the taken mask, the posteriors of the objects still sought."""
        if self._situation is None:
            raise InputError("the environment has no episode yet; call reset() first")
        return self._situation

    @property
    def mission(self) -> Mission:
        """The episode's ``twin.app.mission.Mission`` (its grid, belief, views, robot time)."""
        if self._mission is None:
            raise InputError("the environment has no episode yet; call reset() first")
        return self._mission

    def action_mask(self) -> np.ndarray:
        """(n_views,) int8: 1 where a view is reachable and not taken yet."""
        moves = self.situation.moves
        return (np.isfinite(moves.seconds) & ~self.situation.taken).astype(np.int8)

    # -- gymnasium ----------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """A new episode: the objects placed anew on the room's furniture (drawn from ``seed``,
        or from the env's generator), the world, lights, robot and localizer reset to the
        mission's start. ``options`` is not used."""
        super().reset(seed=seed)
        world = self._live_world()
        # One number from the env's generator picks the draw; the world's randomized factors
        # are then those of batch-survey's run of that number (twin.app.batch.draw_mission).
        self._draw = int(self.np_random.integers(DRAW_LIMIT))
        draw = draw_mission(self._spec, self._draw)
        self._surfaces = world.reset(self._spec, draw)
        self._truth = {
            name: tuple(float(v) for v in world.sim.world.body_position(body))
            for name, body in world.targets.items()
        }
        detector = ThresholdedDetector(world.detector, draw.threshold)
        self._mission = self._new_mission(detector)
        self._searcher = self._new_searcher(self._mission)
        if self._searcher.candidates.n_views != self.candidates.n_views:
            raise InputError(
                "the candidate views changed under the environment (run.cache edited?); "
                "make a new environment"
            )
        self._scores = np.zeros_like(self._scores)
        self._frame = None
        self._steps = self._invalid = 0
        self._path_m = 0.0
        self._done = False
        self._fault = None
        self._last = {"action": None, "invalid": None, "stopped": None}
        self._situation = self._searcher.situation()
        return self._observation(), self._info()

    def step(
        self, action: Any
    ) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool, dict[str, Any]]:
        """Take view ``action`` (see the module docstring); returns (observation, reward,
        terminated, truncated, info)."""
        if self._mission is None or self._situation is None:
            raise InputError("the environment has no episode yet; call reset() first")
        if self._done:
            raise InputError("the episode is over; call reset() to start a new one")
        view = self._view_index(action)
        mission, situation = self._mission, self._situation
        self._steps += 1
        invalid = None
        if not math.isfinite(float(situation.moves.seconds[view])):
            invalid = "unreachable"
        elif situation.taken[view]:
            invalid = "taken"
        reward = 0.0
        if invalid is None:
            before = mission.state.robot_time
            clock = mission.robot.camera.now()
            choice = view_choice(
                self.candidates, situation, view, f"action {view}", self.config.mission.tilt
            )
            try:
                record = self._searcher.take(choice)  # a refused place is struck off there
            except DeviceError as exc:
                # The robot cannot go on (MAX_REFUSALS refusals in a row, or another device
                # error): the episode ends, as batch-survey counts such a run failed.
                invalid = f"drive failed: {exc}"
                self._fault = str(exc)
            else:
                if record is None:
                    invalid = f"drive failed: {self._searcher.unreachable[-1]['reason']}"
                else:
                    self._scores = np.clip(
                        np.stack([record.column_values[n] for n in self.objects]), 0.0, 1.0
                    ).astype(np.float32)
                    self._frame = record.view.image
                    if len(mission.state.path) >= 2:
                        planner = mission.robot.base.planner
                        self._path_m += path_length(planner, mission.state.path[-2:])
            # the robot time the step spent: on a view, or on a drive that was refused
            if invalid is None:
                spent = mission.state.robot_time - before
            else:
                spent = mission.robot.camera.now() - clock
            reward -= spent / SECONDS_PER_UNIT
        if invalid is not None:
            self._invalid += 1
            reward -= INVALID_PENALTY
        self._situation = self._searcher.situation()
        terminated, truncated, stopped = self._ending()
        self._done = terminated or truncated
        self._last = {"action": view, "invalid": invalid, "stopped": stopped}
        info = self._info()
        if self._done:
            found = [
                name
                for name, entry in info["objects"].items()
                if entry["verdict"] == "found"
                and entry["error_m"] is not None
                and entry["error_m"] <= self.config.confidence.radius_m
            ]
            reward += FOUND_BONUS * len(found)
            info["found"] = found
        return self._observation(), float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The last frame (H x W x 3 uint8; black before the first view) with ``"rgb_array"``,
        else None."""
        if self.render_mode != "rgb_array":
            return None
        return self._last_frame()

    def close(self) -> None:
        """Release the world and the robot (again: nothing happens)."""
        if self._world is not None:
            self._world.close()
            self._world = None
        super().close()

    # -- pieces -------------------------------------------------------------------------------

    def _live_world(self) -> MissionWorld:
        if self._world is None:
            raise InputError("the environment is closed; make a new one")
        return self._world

    def _new_mission(self, detector: Any) -> Mission:
        world, config = self._live_world(), self.config
        grid, belief = copy.deepcopy(self._empty_grids)  # one deep copy: a shared grid stays one
        return Mission(
            world.robot,
            detector,
            grid,
            max_range=config.grid.max_range,
            truth=self._truth,
            truth_pose=world.sim.truth_pose,
            visibility=world.visibility,
            fuse_visibility=config.grid.visibility,
            belief=belief,
            confidence_options=config.confidence,
            height_check=build_height_check(config, world.visibility),
            stands_on={obj.name: obj.stands_on for obj in config.objects},
            object_heights=config.object_heights,
        )

    def _new_searcher(self, mission: Mission) -> Searcher:
        world = self._live_world()
        searcher = make_searcher(self.config, mission, world.sim.world, self._plan)
        # The env's budget, not the config's, ends an episode (``max_views`` may differ).
        searcher.rule = replace(searcher.rule, max_views=self.max_views, max_time=self.max_time)
        return searcher

    def _view_index(self, action: Any) -> int:
        try:
            view = int(np.asarray(action).item())
        except (TypeError, ValueError):
            raise InputError(
                f"an action is one view index in 0..{self.candidates.n_views - 1}, got {action!r}"
            ) from None
        if not 0 <= view < self.candidates.n_views or float(np.asarray(action)) != view:
            raise InputError(
                f"an action is one view index in 0..{self.candidates.n_views - 1}, got {action!r}"
            )
        return view

    def _ending(self) -> tuple[bool, bool, str | None]:
        """(terminated, truncated, why): every object found or declared absent ends it; the
        step or time budget, or no valid view left, cuts it short."""
        mission = self.mission
        states = verdicts(mission, self._searcher.rule)
        if mission.views_done > 0 and all(s != "sought" for s in states.values()):
            return True, False, stop_reason(mission, self._searcher.rule)
        if self._fault is not None:
            return False, True, f"the robot could not go on: {self._fault}"
        if self._steps >= self.max_views:
            return False, True, f"step budget spent ({self.max_views} steps)"
        if mission.state.robot_time >= self.max_time:
            return False, True, f"time budget spent ({self.max_time:g} s of robot time)"
        if not self.action_mask().any():
            return False, True, "no reachable view left to take"
        return False, False, None

    def _last_frame(self) -> np.ndarray:
        if self._frame is None:
            return np.zeros(self._frame_shape, dtype=np.uint8)
        return np.array(self._frame, dtype=np.uint8)  # a copy: the caller may keep it

    def _observation(self) -> dict[str, np.ndarray]:
        situation, mission = self.situation, self.mission
        here = situation.here
        pose = np.array([here.x, here.y, wrap_angle(here.yaw)], dtype=np.float32)
        # the searcher's temperature and prior (a search reads its belief with its own
        # temperature, search.temperature): exactly the posterior its planners weigh
        search = self._searcher
        grid = np.stack(
            [
                posterior(mission.belief.layer(name), search.temperature, search.p_absent)[0]
                for name in self.objects
            ]
        )
        obs = {
            "scores": self._scores.copy(),
            # the localized pose lies on the map; clipped so a filter's stray estimate at its
            # edge cannot leave the space
            "pose": np.clip(pose, self._pose_low, self._pose_high),
            "grid": np.clip(grid, 0.0, 1.0).astype(np.float32),
            "taken": situation.taken.astype(np.int8),
        }
        if self.observation_mode == "image":
            obs["image"] = self._last_frame()
        return obs

    def _info(self) -> dict[str, Any]:
        """Per object the estimate [x, y, z] and its errors in the plan and in height (m,
        against the twin's truth; None before the first view), confidence, P(absent) and
        verdict; the views taken, steps (views and invalid actions), robot time (s), path
        length between views (m), the last action and why it was invalid, why the episode
        stopped, the action mask, the places the base refused to reach (``unreachable``) and
        the draw (see the module docstring). Fresh objects every call: a caller may keep them."""
        mission, search = self.mission, self._searcher
        located = mission.located(self.config.grid.peak_separation)
        details = mission.confidence_details(located)
        states = verdicts(mission, self._searcher.rule)
        truth = self._truth
        found = estimates(mission.grid, truth, self.config.grid.peak_separation, located=located)
        objects: dict[str, dict[str, Any]] = {}
        for name in self.objects:
            seen = mission.views_done > 0
            confidence, p_absent = details.get(name, (None, None))
            objects[name] = {
                "estimate_m": list(found[name]["estimate_m"]) if seen else None,
                "error_m": found[name].get("error_m") if seen else None,
                "height_error_m": found[name].get("height_error_m") if seen else None,
                "truth_m": [round(v, 4) for v in truth[name]] if name in truth else None,
                "surface": self._surfaces.get(name),
                "confidence": confidence,
                "p_absent": p_absent,
                "verdict": states[name],
            }
        return {
            "objects": objects,
            "views": mission.views_done,
            "steps": self._steps,
            "invalid_actions": self._invalid,
            "robot_time_s": round(mission.state.robot_time, 3),
            "path_length_m": round(self._path_m, 3),
            "action": self._last.get("action"),
            "invalid": self._last.get("invalid"),
            "stopped": self._last.get("stopped"),
            "action_mask": self.action_mask(),
            "unreachable": [dict(u, place_m=list(u["place_m"])) for u in search.unreachable],
            "draw": self._draw,
        }
