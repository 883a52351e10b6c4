"""The paper's survey (Section 2): a fixed plan of stops and headings, flown view by view.

At every stop the robot looks in each of the mission's headings, by panning the head where its
range allows and turning the base for the rest. The plan only chooses views; each one is taken,
scored and fused by ``Mission.observe`` (``twin.app.mission``), so a resumed survey simply
continues the plan from the mission's view count.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from twin.app.config import MissionConfig
from twin.app.mission import Mission, NotReachedError
from twin.core.devices import PanTiltLimits
from twin.core.errors import TwinError
from twin.core.geometry import Pose2D, wrap_angle

PAN_MARGIN = math.radians(5.0)  # stay clear of the head's end stops


@dataclass(frozen=True)
class PlannedView:
    """One view of the plan: where the base stands and faces, and the head's pan and tilt
    (radians); ``index`` is its place in the plan; ``objects`` the objects it looks for (None:
    all of them)."""

    index: int
    stop: int
    base: Pose2D
    pan: float
    tilt: float = 0.0
    objects: tuple[str, ...] | None = None


def plan_views(
    mission: MissionConfig, limits: PanTiltLimits, floor_objects: Sequence[str] = ()
) -> list[PlannedView]:
    """Every view of the mission, in the order the robot takes them.

    With ``turn = "pan"`` each stop's headings are covered by as few base orientations as the
    pan range allows (greedily, each orientation facing an uncovered heading and taking every
    heading within reach), ordered to turn the least; with ``"base"`` the base faces every
    heading with the head straight.

    With the mission's ``floor_tilt`` and some ``floor_objects`` (those that stand on the
    floor), every stop sweeps its headings a second time with the head that far down, for those
    objects only. Why: with the head near level the floor shows only from 2.6 m out, so a crate
    within that of a stop is found, if at all, from the far stops alone; and the views down are
    for the floor's objects only, since the carpet and tiles seen from above, never in any
    other object's calibration, outscore it (measured: the game box 8/8 to 0/8).
    """
    reach = pan_reach(limits)
    views: list[PlannedView] = []
    yaw = mission.start[2]
    sweeps: list[tuple[float | None, tuple[str, ...] | None]] = [(None, None)]
    if mission.floor_tilt is not None and floor_objects:
        sweeps.append((mission.floor_tilt, tuple(floor_objects)))
    for stop_index, (x, y) in enumerate(mission.stops):
        for tilt, objects in sweeps:
            yaw = _sweep(views, mission, stop_index, (x, y), yaw, reach, tilt, objects)
    return views


def _sweep(
    views: list[PlannedView],
    mission: MissionConfig,
    stop_index: int,
    place: tuple[float, float],
    yaw: float,
    reach: float,
    tilt: float | None,
    objects: tuple[str, ...] | None,
) -> float:
    """Append one stop's sweep of the mission's headings (at ``tilt``, None: the stop's own)
    to ``views``, starting with the base at ``yaw``; returns the base's yaw at its end."""
    x, y = place
    head_tilt = mission.tilt_at(stop_index) if tilt is None else tilt
    remaining = list(mission.headings)
    while remaining:
        if mission.turn == "base" or reach <= 0.0:
            base_yaw = _nearest(remaining, yaw)
            taken = [base_yaw]
        else:
            base_yaw, taken = _best_orientation(remaining, yaw, reach)
        for heading in sorted(taken, key=lambda h: wrap_angle(h - base_yaw)):
            pan = float(wrap_angle(heading - base_yaw))
            base = Pose2D(x, y, base_yaw)
            views.append(PlannedView(len(views), stop_index, base, pan, head_tilt, objects))
            remaining.remove(heading)
        yaw = base_yaw
    return yaw


def pan_reach(limits: PanTiltLimits) -> float:
    """How far (radians, either way) the head pans for a view: its range less the margin that
    keeps it off the end stops (0: it cannot pan)."""
    return max(0.0, min(limits.pan_max, -limits.pan_min) - PAN_MARGIN)


def _nearest(headings: Sequence[float], yaw: float) -> float:
    return min(headings, key=lambda h: abs(wrap_angle(h - yaw)))


def _best_orientation(
    headings: Sequence[float], yaw: float, reach: float
) -> tuple[float, list[float]]:
    """The base yaw (one of the headings) covering most headings; ties: least turning."""

    def covered(base: float) -> list[float]:
        return [h for h in headings if abs(wrap_angle(h - base)) <= reach + 1e-9]

    best = max(headings, key=lambda b: (len(covered(b)), -abs(wrap_angle(b - yaw))))
    return float(wrap_angle(best)), covered(best)


def run_survey(
    mission: Mission,
    plan: Sequence[PlannedView],
    on_view: Callable[[PlannedView], None] | None = None,
    beyond: int = 0,
) -> None:
    """Observe every view of ``plan`` the mission has not taken yet (all of them, unless it was
    resumed from a checkpoint); ``on_view`` sees each before it is taken. A stop whose place
    the base cannot reach (``NotReachedError``) has its views skipped (``Mission.skip``).
    ``beyond``: views a follow-up search may take after the plan (``search.follow_up_views``),
    which a resumed run may already hold."""
    done = mission.views_done
    if done > len(plan) + beyond:
        raise TwinError(
            f"the run holds {done} views but its plan has {len(plan)}"
            + (f" and its follow-up {beyond}" if beyond else "")
            + "; resume with the config the run started with"
        )
    unreachable: dict[int, str] = {}  # stop -> why its place was not reached
    for planned in plan[done:]:
        if on_view:
            on_view(planned)
        if planned.stop in unreachable:
            mission.skip(planned, unreachable[planned.stop])
            continue
        try:
            mission.observe(planned)
        except NotReachedError as exc:
            # Something stands where the plan wanted the robot (a toy crate left on the floor):
            # the survey reports the stop's views as not taken and goes on to the next stop.
            unreachable[planned.stop] = str(exc)
            mission.say(f"stop {planned.stop + 1} not reached, its views skipped: {exc}")
            mission.skip(planned, str(exc))
