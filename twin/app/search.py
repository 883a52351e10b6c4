"""Search, don't survey: after every view, choose the next one, and stop once sure.

The paper's survey (``twin.app.survey``) flies a fixed plan. A search asks, before each view,
which of the candidate views (``twin.app.candidates``: places on the free floor x headings) is
worth most per second of robot time, and takes it with ``Mission.observe`` like any other view.
What a view is worth is ``twin.core.view_gain``'s, over the mission's calibrated belief (the
posterior of ``twin.core.confidence``); what it costs is the robot's time to get there: the
drive along the planning map's shortest path (one Dijkstra search prices every place), the
turns, the localizer settling after a leg, the head's pan, plus ``view_time_s`` for the view
itself (Ye & Tsotsos 1999: detection probability per unit cost, greedily, one view ahead).

Planners (``search.planner``):

* ``information``: expected information (nats) about each sought object's cell, per second;
* ``detection``: probability of detecting a sought object, per second (Ye & Tsotsos);
* ``coverage``: the cells seen least so far (each weighed by exp(-views seen)), per second;
* ``random``: any reachable view not taken yet, uniformly (seeded per view: resumable);
* ``survey``: the mission's fixed plan, in order (the paper's).

Every planner stops the same way: when every sought object's ``confidence`` reaches
``search.confidence`` (found) or its P(absent) reaches ``search.absent`` (declared absent), when
``max_views`` or ``max_time_s`` (robot clock) runs out, or when it has no view left. A view
already taken (same place and heading) is not taken again: the same frame would be no new
evidence, though the belief would count it as such. A planner's state is the mission's (its
grid, belief and view log), so a resumed search continues where it stopped.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twin.app.candidates import Candidates, DetectionRates
from twin.app.mission import Mission
from twin.app.record import ViewRecord
from twin.app.survey import pan_reach
from twin.core.confidence import posterior
from twin.core.devices import BaseLimits, DeviceFaultError, PanTiltLimits
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, wrap_angle
from twin.core.view_gain import (
    Footprints,
    detection_probability,
    information_gain,
    unseen_coverage,
)

MAX_REFUSALS = 3  # places refused in a row before a search gives up (the base is in trouble)
SAME_PLACE = 0.15  # metres: a candidate this close to the robot is reached without driving
TAKEN_M, TAKEN_RAD = 0.15, math.radians(10.0)  # a logged view this close is that candidate


@dataclass(frozen=True)
class TimeModel:
    """Seconds of robot time to get from one view to another (a planner's estimate).

    Drives and turns follow a trapezoidal speed profile with the base's limits; every move ends
    with the localizer weighing scans at rest (``leg_overhead``); the head pans at its top speed.
    A planned drive is slower than one straight leg at top speed: it stops, settles and turns
    at every waypoint, and the controller creeps in to its goal. Measured on the twin over 27
    moves of two searches (``benchmarks/bench_search.py``), a drive took about 3.7 s + 4.4 s per
    metre where one leg at top speed would take 1.8 s + 2 s per metre, hence ``drive_speed``:
    the share of the top speed a planned drive averages.
    """

    base: BaseLimits
    head: PanTiltLimits
    leg_overhead: float = 2.5  # s: localizing at rest after a move (scans weighed at rest)
    drive_speed: float = 0.45  # of the base's top speed, on average over a planned drive

    @property
    def pan_reach(self) -> float:
        return pan_reach(self.head)

    @staticmethod
    def _profile(amount: np.ndarray, speed: float, accel: float) -> np.ndarray:
        amount = np.abs(amount)
        ramp = speed * speed / accel  # the distance spent reaching full speed and stopping
        return np.where(
            amount < ramp, 2.0 * np.sqrt(amount / accel), amount / speed + speed / accel
        )

    def drive(self, metres: np.ndarray) -> np.ndarray:
        speed = self.base.speed * self.drive_speed
        return self._profile(np.asarray(metres, float), speed, self.base.accel)

    def turn(self, radians: np.ndarray) -> np.ndarray:
        return self._profile(np.asarray(radians, float), self.base.turn_rate, self.base.turn_accel)

    def pan(self, radians: np.ndarray) -> np.ndarray:
        return np.abs(np.asarray(radians, float)) / self.head.pan_speed


@dataclass(frozen=True)
class Moves:
    """For every candidate view: the seconds to reach it, and the base yaw and head pan it is
    taken with (inf seconds: unreachable)."""

    seconds: np.ndarray
    base_yaw: np.ndarray
    pan: np.ndarray
    metres: np.ndarray  # along the planning map's shortest path to the view's place


def moves(
    candidates: Candidates,
    here: Pose2D,
    pan_now: float,
    place_metres: np.ndarray,
    timing: TimeModel,
) -> Moves:
    """Price every candidate from the robot's pose ``here`` and head pan ``pan_now``, given the
    shortest-path metres to every place (``place_metres``, (P,), inf: unreachable).

    At the robot's own place (within ``SAME_PLACE``) a heading within the head's reach is only a
    pan; beyond it the base turns the least that brings it within reach. Elsewhere the base
    drives there and faces the heading with the head straight."""
    headings = candidates.headings
    n_h = len(headings)
    places = candidates.places
    metres = np.repeat(place_metres, n_h)
    heading = np.tile(headings, len(places))
    direct = np.repeat(np.hypot(places[:, 0] - here.x, places[:, 1] - here.y), n_h)
    here_place = direct < SAME_PLACE
    reach = timing.pan_reach
    # Driving: turn to the first leg (taken as the straight bearing), drive, turn to the heading.
    bearing = np.arctan2(
        np.repeat(places[:, 1], n_h) - here.y, np.repeat(places[:, 0], n_h) - here.x
    )
    drive = (
        timing.turn(wrap_angle(bearing - here.yaw))
        + timing.drive(metres)
        + timing.turn(wrap_angle(heading - bearing))
        + timing.leg_overhead
        + timing.pan(pan_now)
    )
    # Staying: pan within reach, or turn the least and pan to the reach's edge.
    wanted = wrap_angle(heading - here.yaw)
    pan_here = np.clip(wanted, -reach, reach)
    turn = wrap_angle(wanted - pan_here)
    stay = timing.pan(pan_here - pan_now) + np.where(
        np.abs(turn) > 1e-9, timing.turn(turn) + timing.leg_overhead, 0.0
    )
    seconds = np.where(here_place, stay, drive)
    seconds = np.where(np.isfinite(metres) | here_place, seconds, np.inf)
    base_yaw = np.where(here_place, wrap_angle(here.yaw + turn), heading)
    pan = np.where(here_place, pan_here, 0.0)
    return Moves(seconds, base_yaw, pan, np.where(here_place, 0.0, metres))


@dataclass(frozen=True)
class ViewChoice:
    """The view a planner chose (a ``twin.app.mission.ViewTarget``) and why: ``why`` in words,
    ``scores`` every candidate's score at the time (NaN: not eligible), for the viewer."""

    index: int  # the candidate view (-1: a view of a fixed plan)
    stop: int  # the places visited so far, this one included
    base: Pose2D
    pan: float
    tilt: float
    why: str
    scores: np.ndarray | None = None
    gain: float = math.nan
    seconds: float = math.nan


@dataclass
class Situation:
    """What a planner knows before a view: where the robot is, what every candidate costs, which
    were taken, the posterior of each object still sought and the grid's seen counts."""

    views_done: int
    here: Pose2D
    moves: Moves
    taken: np.ndarray  # (n_views,) bool
    places_visited: int
    posteriors: dict[str, np.ndarray] = field(default_factory=dict)  # sought objects only
    observed: np.ndarray | None = None  # (ny, nx) views' seen share per cell, summed
    # (n_cells, headings): how often each cell was seen facing each heading (share-weighted)
    repeats: np.ndarray | None = None
    sought_as: str = "belief"  # what ``posteriors`` are, in a planner's words


class Planner(Protocol):
    name: str

    def choose(self, situation: Situation) -> ViewChoice | None:
        """The next view, or None when this planner has none left."""
        ...


class GainPlanner:
    """The candidate of the most expected gain per second (``information``, ``detection`` or
    ``coverage``)."""

    def __init__(
        self,
        name: str,
        candidates: Candidates,
        footprints: dict[str, Footprints],
        rates: dict[str, DetectionRates],
        view_time: float,
        tilt: float = 0.0,
        repeat_discount: float = 1.0,
    ) -> None:
        if name not in ("information", "detection", "coverage"):
            raise InputError(f"unknown gain planner {name!r}")
        self.name, self.candidates, self.footprints = name, candidates, footprints
        self.rates, self.view_time, self.tilt = rates, view_time, tilt
        self.repeat_discount = repeat_discount
        f = candidates.footprints
        # each footprint entry's heading: the direction its cell would be seen from
        rows = np.repeat(np.arange(f.rows), np.diff(f.indptr))
        self._entry_heading = (f.row_view[rows] % len(candidates.headings)).astype(np.intp)

    def novelty(self, situation: Situation) -> np.ndarray | None:
        """Per footprint entry, the share of what the view would show there that is news:
        ``repeat_discount`` to the power of the views that saw the cell facing the same way."""
        if situation.repeats is None or self.repeat_discount >= 1.0:
            return None
        seen = situation.repeats[self.candidates.footprints.cells, self._entry_heading]
        return self.repeat_discount**seen

    def gains(self, situation: Situation) -> np.ndarray:
        """(n_views,) the expected gain of every candidate (nats, probability, or cells)."""
        if self.name == "coverage":
            if situation.observed is None:
                raise InputError("the coverage planner needs the grid's seen counts")
            return unseen_coverage(self.candidates.footprints, situation.observed)
        total = np.zeros(self.candidates.n_views)
        novelty = self.novelty(situation)
        for name, cells in situation.posteriors.items():
            prints, rates = self.footprints[name], self.rates[name]
            if self.name == "information":
                total += information_gain(prints, cells, rates.fpr, novelty)
            else:
                total += detection_probability(prints, cells, rates.contrast, novelty)
        return total

    def choose(self, situation: Situation) -> ViewChoice | None:
        gains = self.gains(situation)
        seconds = situation.moves.seconds + self.view_time
        eligible = np.isfinite(seconds) & ~situation.taken
        if not eligible.any():
            return None
        scores = np.where(eligible, gains / seconds, np.nan)
        order = np.argsort(np.where(eligible, -scores, np.inf), kind="stable")
        best = int(order[0])
        unit = {"information": "nats", "detection": "P(detect)", "coverage": "cells unseen"}
        x, y = self.candidates.places[self.candidates.place_of(best)]
        heading = math.degrees(self.candidates.heading_of(best))
        span = self.candidates.footprints.entries_of(best)
        prints = self.candidates.footprints
        # a cell in two overlapping columns' wedges is still seen once: at most all of it
        cells_seen, where = np.unique(prints.cells[span], return_inverse=True)
        shares = np.minimum(np.bincount(where, weights=prints.share[span]), 1.0)
        seen = [
            f"{100 * float(cells.ravel()[cells_seen] @ shares):.0f} % of "
            f"{name}'s {situation.sought_as}"
            for name, cells in situation.posteriors.items()
        ]
        why = (
            f"from ({x:.2f}, {y:.2f}) m facing {heading:.0f} deg"
            + (f", seeing {', '.join(seen)}" if seen else "")
            + f": {self.name}: {gains[best]:.3f} {unit[self.name]} expected for "
            f"{seconds[best]:.1f} s ({situation.moves.metres[best]:.2f} m to drive), "
            f"{scores[best]:.4f}/s, best of {int(eligible.sum())} views"
        )
        if eligible.sum() > 1:
            second = int(order[1])
            why += (
                f"; next best {scores[second]:.4f}/s "
                f"({gains[second]:.3f} in {seconds[second]:.1f} s)"
            )
        return view_choice(self.candidates, situation, best, why, self.tilt, scores, gains[best])


class RandomPlanner:
    """Any reachable view not taken yet, uniformly; view k's draw is seeded by (seed, k), so a
    resumed search draws what the uninterrupted one would have."""

    name = "random"

    def __init__(self, candidates: Candidates, seed: int, tilt: float = 0.0) -> None:
        self.candidates, self.seed, self.tilt = candidates, seed, tilt

    def choose(self, situation: Situation) -> ViewChoice | None:
        eligible = np.flatnonzero(np.isfinite(situation.moves.seconds) & ~situation.taken)
        if len(eligible) == 0:
            return None
        rng = np.random.default_rng([self.seed, situation.views_done])
        best = int(rng.choice(eligible))
        why = f"random: one of {len(eligible)} reachable views not taken yet"
        return view_choice(self.candidates, situation, best, why, self.tilt)


class PlanPlanner:
    """The mission's fixed plan (``twin.app.survey.plan_views``), view by view, from the
    mission's view ``start`` on (0: the plan is the whole search)."""

    name = "survey"

    def __init__(self, plan: Sequence[Any], start: int = 0, reason: str = "") -> None:
        self.plan, self.start, self.reason = list(plan), start, reason

    def choose(self, situation: Situation) -> ViewChoice | None:
        k = situation.views_done - self.start
        if not 0 <= k < len(self.plan):
            return None
        view = self.plan[k]
        why = (
            f"survey{self.reason}: view {view.index + 1} of {len(self.plan)} of the fixed plan "
            f"(stop {view.stop + 1})"
        )
        return ViewChoice(-1, view.stop, view.base, view.pan, view.tilt, why)


class FallingBackPlanner:
    """A belief-driven planner for its first ``after`` views, then the fixed plan.

    The belief can be wrong where the detector is weak (a box before a black screen scores
    little even in view) or a distractor looks like the object from every side: the greedy
    planner then keeps asking it what it cannot answer. A systematic survey does not depend on
    the belief, so once ``after`` views have not settled the search, it flies the plan for what
    is left of the budget. The switch depends on the view count only, so a resumed search
    switches where the uninterrupted one would have."""

    def __init__(self, planner: Planner, plan: Sequence[Any], after: int) -> None:
        self.planner, self.after = planner, after
        self.name = planner.name
        reason = f" (the belief had not settled after {after} views)"
        self.fallback = PlanPlanner(plan, after, reason)

    def choose(self, situation: Situation) -> ViewChoice | None:
        if situation.views_done < self.after:
            return self.planner.choose(situation)
        return self.fallback.choose(situation)


def view_choice(
    candidates: Candidates,
    situation: Situation,
    view: int,
    why: str,
    tilt: float,
    scores: np.ndarray | None = None,
    gain: float = math.nan,
) -> ViewChoice:
    """Candidate ``view`` as the target to observe, moved to as ``situation.moves`` says."""
    place = candidates.places[candidates.place_of(view)]
    m = situation.moves
    moving = m.metres[view] > 0.0
    if moving:
        base = Pose2D(float(place[0]), float(place[1]), float(m.base_yaw[view]))
    else:  # turn (or not) where the robot stands: no drive of a few centimetres to the lattice
        base = Pose2D(situation.here.x, situation.here.y, float(m.base_yaw[view]))
    stop = situation.places_visited + (1 if moving or situation.places_visited == 0 else 0)
    return ViewChoice(
        view, stop - 1, base, float(m.pan[view]), tilt, why, scores, gain, float(m.seconds[view])
    )


# -- the loop ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StopRule:
    """When a search ends (``search.*`` of the config)."""

    confidence: float = 0.95
    absent: float = 0.95
    max_views: int = 40
    max_time: float = 900.0


def verdicts(mission: Mission, rule: StopRule) -> dict[str, str]:
    """Per object: "found" (confidence reached), "absent" (P(absent) reached) or "sought"."""
    details = mission.confidence_details()
    out = {}
    for name in mission.grid.objects:
        if name not in details:
            out[name] = "sought"
            continue
        confidence, p_absent = details[name]
        out[name] = (
            "found" if confidence >= rule.confidence
            else "absent" if p_absent >= rule.absent
            else "sought"
        )  # fmt: skip
    return out


def stop_reason(mission: Mission, rule: StopRule) -> str | None:
    """Why the search should stop now, or None to go on."""
    states = verdicts(mission, rule)
    if mission.views_done > 0 and all(s != "sought" for s in states.values()):
        found = [n for n, s in states.items() if s == "found"]
        absent = [n for n, s in states.items() if s == "absent"]
        parts = []
        if found:
            parts.append(f"found {', '.join(found)} (confidence >= {rule.confidence:g})")
        if absent:
            parts.append(f"declared {', '.join(absent)} absent (P >= {rule.absent:g})")
        return "; ".join(parts)
    return budget_spent(mission, rule)


def budget_spent(mission: Mission, rule: StopRule) -> str | None:
    """Whether the search has spent its views or its robot time, and which."""
    if mission.views_done >= rule.max_views:
        return f"view budget spent ({rule.max_views} views)"
    if mission.state.robot_time >= rule.max_time:
        return f"time budget spent ({rule.max_time:g} s of robot time)"
    return None


class PlaceDistances:
    """Metres along the planning map's shortest path from a pose to every candidate place (one
    Dijkstra search, ``PathPlanner.distances_from``); inf where the robot cannot go."""

    def __init__(self, planner: Any, places: np.ndarray) -> None:
        self.planner = planner
        rows, cols = planner.map.cell_of(places[:, 0], places[:, 1])
        ny, nx = planner.map.shape
        inside = (rows >= 0) & (rows < ny) & (cols >= 0) & (cols < nx)
        self._rows, self._cols = np.clip(rows, 0, ny - 1), np.clip(cols, 0, nx - 1)
        self._inside = inside

    def __call__(self, here: Pose2D) -> np.ndarray:
        from twin.app.localization import START_TOLERANCE

        # reachable as the base's own legs are planned: from up to its tolerance off the margin
        field_m = self.planner.distances_from((here.x, here.y), START_TOLERANCE)
        return np.where(self._inside, field_m[self._rows, self._cols], np.inf)


class Searcher:
    """Runs a search on a ``Mission``: situation, choice, view, until a stop reason."""

    def __init__(
        self,
        mission: Mission,
        planner: Planner,
        candidates: Candidates,
        place_metres: Callable[[Pose2D], np.ndarray],
        timing: TimeModel,
        rule: StopRule,
        temperature: float,
        p_absent: float,
    ) -> None:
        self.mission, self.planner, self.candidates = mission, planner, candidates
        self.place_metres, self.timing, self.rule = place_metres, timing, rule
        self.temperature, self.p_absent = temperature, p_absent
        # places the robot could not reach this session, and why (result.json reports them)
        self.unreachable: list[dict[str, Any]] = []
        self._blocked_places: set[int] = set()
        self._refusals = 0  # places refused in a row

    def situation(self) -> Situation:
        mission, cand = self.mission, self.candidates
        robot = mission.robot
        here = robot.base.pose()
        pan_now = float(robot.pantilt.position()[0])
        place_metres = self.place_metres(here)
        place_metres[list(self._blocked_places)] = np.inf
        taken = np.zeros(cand.n_views, dtype=bool)
        visited: list[tuple[float, float]] = []
        f = cand.footprints
        repeats = np.zeros((f.n_cells, len(cand.headings)))
        for logged in mission.views.views:
            ox, oy = logged.origin
            axis = float(np.mean(logged.wedges))
            view, metres, radians = cand.nearest(ox, oy, axis)
            if metres <= TAKEN_M and radians <= TAKEN_RAD:
                taken[view] = True
            # what it saw, as the nearest candidate would have (for the planner's novelty)
            span = f.entries_of(view)
            np.add.at(repeats[:, view % len(cand.headings)], f.cells[span], f.share[span])
            if not visited or math.hypot(ox - visited[-1][0], oy - visited[-1][1]) > SAME_PLACE:
                visited.append((ox, oy))
        posteriors = {}
        belief = mission.belief
        states = verdicts(mission, self.rule)
        if belief is not None:
            for name in mission.grid.objects:
                if states[name] == "sought":
                    cells, _ = posterior(belief.layer(name), self.temperature, self.p_absent)
                    posteriors[name] = cells
        grid = mission.grid
        observed = sum(grid.observed(n) for n in grid.objects) / len(grid.objects)
        return Situation(
            mission.views_done,
            here,
            moves(cand, here, pan_now, place_metres, self.timing),
            taken,
            len(visited),
            posteriors,
            observed,
            repeats,
        )

    def stop_reason(self) -> str | None:
        """Why the search should stop now (see ``stop_reason``), or None to go on."""
        return stop_reason(self.mission, self.rule)

    def take(self, choice: ViewChoice) -> ViewRecord | None:
        """Observe ``choice``; returns its record, or None if the base refused to reach it.

        A candidate's place the base refuses to reach (``DeviceFaultError``: no safe path, the
        laser sees something the map does not hold in the way, or a touch its recovery could
        not get round) is struck off for this session: a search, unlike a fixed plan, has other
        places to look from. The base has stopped, backed off and localized again before it
        refuses, and the refusal is reported (``unreachable``). ``MAX_REFUSALS`` in a row, a
        refused view of a fixed plan, or any other device error are raised."""
        try:
            record = self.mission.observe(choice)
        except DeviceFaultError as exc:
            self._refusals += 1
            if choice.index < 0 or self._refusals >= MAX_REFUSALS:
                raise
            place = self.candidates.place_of(choice.index)
            self._blocked_places.add(place)
            x, y = (float(v) for v in self.candidates.places[place])
            self.unreachable.append(
                {"view": self.mission.views_done, "place_m": [x, y], "reason": str(exc)}
            )
            self.mission.say(f"({x:.2f}, {y:.2f}) m not reached, looking elsewhere: {exc}")
            return None
        self._refusals = 0
        return record

    def run(self, on_view: Callable[[ViewChoice], None] | None = None) -> str:
        """Take views (``take``) until a stop reason; returns it."""
        while True:
            reason = self.stop_reason()
            if reason is not None:
                return reason
            choice = self.planner.choose(self.situation())
            if choice is None:
                return f"no view left to take ({self.planner.name})"
            if on_view is not None:
                on_view(choice)
            self.take(choice)


# -- wiring ---------------------------------------------------------------------------------------


def search_candidates(config: Any, world: Any, camera: Any, planner_map: Any, spans: np.ndarray,
                      say: Callable[[str], None] = lambda _: None) -> Candidates:  # fmt: skip
    """The config's candidate views on ``planner_map`` (a ``PathPlanner``), from the cache in
    ``run.cache`` or built (and cached) now."""
    from twin.app.candidates import (
        build_candidates,
        candidates_key,
        lattice_places,
        load_candidates,
        save_candidates,
    )
    from twin.app.visibility_models import default_reach, planning_visibility

    options, spec = config.search, config.grid.spec
    occupancy = planner_map.map
    # Views are taken where the robot has room: ``clearance_m`` beyond what its legs keep, so
    # it can turn on the spot, and its laser sees more than a wall at arm's length.
    half = occupancy.resolution / 2.0
    roomy = planner_map.distance - half >= planner_map.clearance + options.clearance_m
    places = lattice_places(~roomy, occupancy.origin[:2], occupancy.resolution, options.spacing_m)
    reach = default_reach((spec.x_min, spec.y_min, spec.x_max, spec.y_max), config.grid.max_range)
    key = candidates_key(
        config.scene,
        places=places,
        headings=options.headings,
        spec=[spec.x_min, spec.y_min, spec.x_max, spec.y_max, spec.cell_size],
        camera=[camera.width, camera.height, camera.hfov],
        spans=np.asarray(spans),
        visibility=[config.visibility.source, config.visibility.supports,
                    config.visibility.object_height_m, config.visibility.object_radius_m],
        tilt=config.mission.tilt,
        reach=reach,
    )  # fmt: skip
    path = config.cache / "search" / f"candidates-{key}.npz"
    cached = load_candidates(path, key)
    if cached is not None:
        return cached
    say(f"pricing {len(places) * options.headings} candidate views (cached for next time)")
    visibility = planning_visibility(config, world, camera, occupancy)
    candidates = build_candidates(
        places, options.headings, spec, camera, spans, visibility, reach, config.mission.tilt
    )
    save_candidates(path, candidates, key)
    return candidates


def search_confidence(config: Any) -> Any:
    """How a search reads its confidence: the config's ``[confidence]`` with the search's own
    temperature (``search.temperature``: a search's views are more alike than a survey's)."""
    from dataclasses import replace

    return replace(config.confidence, temperature=config.search.temperature)


def make_searcher(
    config: Any,
    mission: Mission,
    world: Any,
    plan: Sequence[Any],
    say: Callable[[str], None] = lambda _: None,
    follow_up: bool = False,
) -> Searcher:
    """The search ``config`` describes, on ``mission`` (its robot's base must plan on a map:
    ``pose_source = "laser"``). ``plan`` is the mission's fixed plan (the ``survey`` planner).

    ``follow_up``: the search that follows a flown plan (``follow_up``): its planner has no
    plan to fall back on, its budget is ``search.follow_up_views`` views beyond the plan and no
    time limit, and the mission keeps the survey's confidence (its views were the plan's)."""
    from twin.app.candidates import detection_rates

    robot, options = mission.robot, config.search
    planner_map = getattr(robot.base, "planner", None)
    if planner_map is None:
        raise InputError(
            "twin search plans its drives on the localization map: set robot.base.pose_source "
            '= "laser" (with a [localization] map)'
        )
    models = {m.name: m for m in mission.detector.models}
    if follow_up:
        check_follow_up(mission.detector)
    needs_belief = options.planner in ("information", "detection") and not follow_up
    missing = [name for name, m in models.items() if m.calibration is None]
    if needs_belief and (missing or mission.belief is None):
        raise InputError(
            f'search.planner = "{options.planner}" weighs views by the detector\'s calibrated '
            f"belief, and {missing[0] if missing else 'the mission'!r} has no calibration: store "
            "one with 'twin roc --store', or choose search.planner = \"coverage\""
        )
    spans = mission.detector.column_spans(robot.camera.model.width)
    candidates = search_candidates(config, world, robot.camera.model, planner_map, spans, say)
    rates = {name: detection_rates(m.calibration) for name, m in models.items() if m.calibration}
    footprints = {name: candidates.for_detector(r) for name, r in rates.items()}
    tilt = config.mission.tilt
    if follow_up:  # the contenders' cells, each seen anew: the likeliest to be seen, per second
        planner: Planner = GainPlanner(
            "detection", candidates, footprints, rates, options.view_time_s, tilt,
            options.repeat_discount,
        )  # fmt: skip
    elif options.planner == "random":
        planner = RandomPlanner(candidates, options.seed, tilt)
    elif options.planner == "survey":
        planner = PlanPlanner(plan)
    else:
        planner = GainPlanner(
            options.planner, candidates, footprints, rates, options.view_time_s, tilt,
            options.repeat_discount,
        )  # fmt: skip
        if options.survey_after > 0 and not follow_up:
            planner = FallingBackPlanner(planner, plan, options.survey_after)
    inner = getattr(robot.base, "inner", robot.base)  # a localized base wraps the device
    timing = TimeModel(getattr(inner, "limits", BaseLimits()), robot.pantilt.limits)
    if follow_up:
        rule = StopRule(
            options.confidence, options.absent, len(plan) + options.follow_up_views, math.inf
        )
        confidence = mission.confidence_options
    else:
        rule = StopRule(options.confidence, options.absent, options.max_views, options.max_time_s)
        mission.confidence_options = confidence = search_confidence(config)
    parts = (mission, planner, candidates, PlaceDistances(planner_map, candidates.places), timing,
             rule, confidence.temperature, confidence.p_absent)  # fmt: skip
    if follow_up:
        return DoubtSearcher(
            *parts, ratio=options.follow_up_ratio, peak_separation=config.grid.peak_separation,
            reach=options.follow_up_range_m,
        )  # fmt: skip
    return Searcher(*parts)


class DoubtSearcher(Searcher):
    """A search that looks again at each object's contenders: the peaks of its grid layer that
    come within ``ratio`` of the chosen one (``doubts``), not at its belief's unseen corners.

    After a survey, the calibrated belief of an object not yet found puts its mass where the
    plan saw least (a corner behind a sofa); chasing that, the apartment's follow-up views went
    to walls no calibration frame had seen from so close and raised new look-alikes there (two
    development runs, one right and one wrong after the plan, both lost the rice box to such a
    wall). The question a survey leaves is which of two or three places it is: a view that sees
    them anew answers it."""

    def __init__(
        self, *args: Any, ratio: float, peak_separation: float, reach: float, **kwargs: Any
    ) -> None:
        super().__init__(*args, **kwargs)
        self.ratio, self.peak_separation, self.reach = ratio, peak_separation, reach
        grid = self.mission.grid
        # A resumed follow-up starts its count afresh: looks before it are the plan's too.
        self._seen_before = {name: grid.observed(name) for name in grid.objects}
        self._doubts: tuple[int, dict[str, np.ndarray]] | None = None

    def doubts(self) -> dict[str, np.ndarray]:
        """``doubts`` of the mission as it stands (once per view: the stop rule and the
        planner both ask, and each asks ``Mission.located`` over the whole view log)."""
        done = self.mission.views_done
        if self._doubts is None or self._doubts[0] != done:
            self._doubts = (done, doubts(self.mission, self.ratio, self.peak_separation))
        return self._doubts[1]

    def situation(self) -> Situation:
        situation = super().situation()
        situation.posteriors = self.contenders()
        situation.sought_as = "contenders"
        # Only from near a contender: from across the flat a box is a few pixels, its score
        # under the room's (the development run that lost its coffee-table box so: 4 views
        # from 4 m, each taking from the truth's cell what the room there usually gains).
        spec, near = self.mission.grid.spec, np.zeros(len(self.candidates.places), dtype=bool)
        for cells in situation.posteriors.values():
            for row, col in zip(*np.nonzero(cells), strict=True):
                x, y = spec.cell_center(int(row), int(col))
                near |= np.hypot(*(self.candidates.places - (x, y)).T) <= self.reach
        headings = len(self.candidates.headings)
        situation.taken = situation.taken | ~np.repeat(near, headings)
        return situation

    def contenders(self) -> dict[str, np.ndarray]:
        """``doubts``, each contender weighed by 1 / (1 + the full views of it this follow-up
        has taken): every look adds what it sees to the grid, a look-alike's score too, so a
        contender looked at more than the others gains on them for that alone (a development
        run whose box was right after the plan lost it to the desk the follow-up kept
        looking at, the nearer of the two)."""
        grid, out = self.mission.grid, {}
        for name, cells in self.doubts().items():
            looks = np.maximum(grid.observed(name) - self._seen_before[name], 0.0)
            weighed = cells / (1.0 + looks)
            out[name] = weighed / weighed.sum()
        return out

    def stop_reason(self) -> str | None:
        if not self.doubts():
            return no_doubt(self.ratio)
        return budget_spent(self.mission, self.rule)


def check_follow_up(detector: Any) -> None:
    """Before a survey flies: its follow-up weighs views by each model's detection rates (its
    score calibration), so refuse a detector whose models lack one now, not after the plan."""
    missing = [m.name for m in detector.models if m.calibration is None]
    if missing:
        raise InputError(
            f"search.follow_up_views weighs views by the detector's calibration, and "
            f"{missing[0]!r} has none: store one with 'twin roc --store' (or give the object a "
            "scene body to calibrate it in the twin), or set search.follow_up_views = 0"
        )


def no_doubt(ratio: float) -> str:
    """Why a follow-up stops (or never starts) with views left."""
    return f"no doubt left (every object's first peak over {ratio:g}x its next)"


def doubts(mission: Mission, ratio: float, peak_separation: float) -> dict[str, np.ndarray]:
    """Per object whose chosen peak is less than ``ratio`` times its next: a distribution over
    the grid's cells, equal on the peaks that come within ``ratio`` of the chosen one (not on
    those passed over because no surface there fits their height)."""
    out = {}
    grid = mission.grid
    for name, found in mission.located(peak_separation).items():
        if not found.ratio < ratio:
            continue
        passed = {(p.row, p.col) for p, _ in found.passed_over}
        contenders = [
            p for p in found.peaks.peaks
            if p.value * ratio > found.peak.value and (p.row, p.col) not in passed
        ]  # fmt: skip
        cells = np.zeros(grid.spec.shape)
        for peak in contenders or [found.peak]:
            cells[peak.row, peak.col] = 1.0
        out[name] = cells / cells.sum()
    return out


def follow_up(
    config: Any,
    mission: Mission,
    world: Any,
    plan: Sequence[Any],
    say: Callable[[str], None] = lambda _: None,
    on_view: Callable[[ViewChoice, Candidates], None] | None = None,
) -> dict[str, Any] | None:
    """After the fixed ``plan`` is flown: up to ``search.follow_up_views`` more views while an
    object is in doubt (``DoubtSearcher``); what it did (its planner, why it stopped, the views
    it took, the places refused), or None when the config asks for none.

    A survey ends where its plan ends, however unsure it is. On the apartment's randomized runs
    the rice box's failures were nearly all unsure (confidence under 0.35) with the truth the
    grid's second peak behind a look-alike: a few views chosen for what they would settle,
    from places the plan never stood, look again where the survey left a doubt. ``on_view``
    sees each choice, with the candidates it was chosen among, before it is taken."""
    options = config.search
    if options.follow_up_views == 0:
        return None
    if not doubts(mission, options.follow_up_ratio, config.grid.peak_separation):
        # no candidate views to price (~15 s the first time in the apartment) for none taken
        return {"planner": "detection", "stopped": no_doubt(options.follow_up_ratio),
                "views": 0, "unreachable": []}  # fmt: skip
    before = mission.views_done
    searcher = make_searcher(config, mission, world, plan, say, follow_up=True)
    shown = None if on_view is None else lambda choice: on_view(choice, searcher.candidates)
    stopped = searcher.run(shown)
    return {
        "planner": searcher.planner.name,
        "stopped": stopped,
        "views": mission.views_done - before,
        "unreachable": searcher.unreachable,
    }


def path_length(planner_map: Any, path: Sequence[Sequence[float]]) -> float:
    """Metres driven between the views of ``path`` ((x, y, yaw) each), along the planning map's
    shortest paths (straight where a leg cannot be planned: a pose a hair inside the margin)."""
    from twin.nav.planner import NoPathError

    total = 0.0
    for a, b in itertools.pairwise(path):
        straight = math.hypot(b[0] - a[0], b[1] - a[1])
        if straight < SAME_PLACE:
            total += straight
            continue
        try:
            total += planner_map.plan(a[:2], b[:2]).length
        except (InputError, NoPathError):
            total += straight
    return total
