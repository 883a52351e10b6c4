"""A base that knows where it is from its laser, and drives around what its map holds.

``LaserLocalizedBase`` wraps any ``Base`` (the MuJoCo base, the ARCOS driver) with Monte Carlo
localization on an occupancy map (``twin.nav.mcl``) fed by the base's odometry and the robot's
laser, and with legs planned on the map inflated by the robot's radius (``twin.nav.planner``).
It is itself a ``Base``, so a mission needs no change: ``pose()`` is the localized pose (the
filter's estimate carried forward by the odometry moved since), ``pose_covariance()`` how sure
the filter is, and ``go_to`` drives planned legs, each re-localized at its end.

Why legs, and why at rest: the filter is updated with scans taken while the base stands, so a
scan's beams are not smeared by motion; between scans the odometry (with its real errors) is
trusted only for one leg. A leg is driven only if the map and the newest scan both show its
corridor free (an obstacle the map does not hold stops the leg before it starts); a contact or a
stall during a leg backs the robot off (away from where its bumper was pressed), re-localizes
and re-plans around what the bumper felt (a toy on the floor lies below the laser's plane), up
to ``MAX_RECOVERIES`` times a goal, then is an error — never a view fused from a pose that
silently went wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.app.record import Localization
from twin.core.devices import Base, BumpedError, DeviceFaultError, Laser, LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, wrap_angle
from twin.nav.distance import obstacle_distance
from twin.nav.maps import OccupancyMap
from twin.nav.mcl import MclConfig, MonteCarloLocalizer, PoseEstimate
from twin.nav.planner import NoPathError, PathPlanner
from twin.nav.scan_matching import CorrelativeScanMatcher, LikelihoodTable

ARRIVED_M = 0.05  # a goal is reached within this distance (the Base contract's tolerance)
ARRIVED_YAW = math.radians(3.0)
# Scans weighed at rest after a leg: until the filter has been localized for the first number
# of scans in a row, at most the second number. One update after a long leg collapses the
# cloud spread by the motion model onto the few particles nearest the truth, centimetres off;
# each further scan at rest (the filter jitters its particles) pulls it in: measured on a room
# with a 1 % wheel error, 1 update left 3-11 cm, 3 left 0.5-3 cm, 6 left 2-5 mm.
SETTLE_UPDATES = (6, 30)
GLOBAL_UPDATES = 24  # scans weighed at rest to find a robot nobody placed
# A scan match around the filter's mean disagreeing by more than this many of its own standard
# deviations (and at least the floors below) re-centres the particles on the match.
RECENTRE_SIGMAS = 3.0
RECENTRE_MIN_M = 0.03
RECENTRE_MIN_YAW = math.radians(1.5)
# A match is trusted when its returns lie on average within about 1.5 sigma of the map's
# obstacle outlines (mean log-likelihood above -1.1 with the table's sigma)
MATCH_MIN_MEAN_LOG_LIKELIHOOD = -1.1
BACK_OFF_M = 0.20  # how far the base backs away after touching something
# Touches a go_to recovers from (each backed off, re-localized and planned around) before the
# next is an error: a bumper tells the side of a toy crate, not its size, so going round it
# may take a second touch.
MAX_RECOVERIES = 3
# What a bumper felt is planned around as a disc of this radius just beyond the robot's rim:
# the bumper tells the side, not the size (the apartment's floor crate is 0.4 m x 0.3 m).
BUMPED_RADIUS_M = 0.15
# A leg may start this far inside the planning margin (from the nearest cell outside it): a
# goal at the margin's edge is reached within the base's 5 cm, a leg stopped short by the laser
# or backed off a touch leaves the robot nearer, and the next leg must still be able to leave;
# its first stretch heads straight for the margin's edge, away from what is nearest.
START_TOLERANCE = 0.25


@dataclass(frozen=True)
class LocalizerSettings:
    """What the wrapper needs besides the devices and the map (SI units)."""

    particles: int = 500
    beams: int = 60
    start_sigma: tuple[float, float, float] = (0.10, 0.10, math.radians(5.0))
    robot_radius: float = 0.30  # m: the Peoplebot's footprint from its centre
    margin: float = 0.05  # m: kept clear beyond the radius when planning
    seed: int = 0


class LaserLocalizedBase(Base):
    """``base``'s motion, ``laser``'s scans and ``occupancy`` map: a localized, careful base.

    ``start`` is where the mission says the robot stands (the filter starts around it with the
    settings' ``start_sigma``); ``None`` localizes globally over the map's free cells.
    ``drive_map`` (default: ``occupancy``) is what legs are planned on: the laser's map with
    what the laser cannot see added, e.g. a table top above its plane
    (``twin.sim.scene_map.drive_map``).
    """

    def __init__(
        self,
        base: Base,
        laser: Laser,
        occupancy: OccupancyMap,
        settings: LocalizerSettings | None = None,
        start: Pose2D | None = None,
        drive_map: OccupancyMap | None = None,
    ) -> None:
        self.inner, self.laser, self.map = base, laser, occupancy
        self.settings = settings or LocalizerSettings()
        self.start = start
        self.name = f"{base.name} (localized by {laser.name})"
        # one distance transform for the filter and the planner
        self._distance = obstacle_distance(occupancy)
        self.planner = PathPlanner(
            occupancy if drive_map is None else drive_map,
            self.settings.robot_radius,
            self.settings.margin,
            unknown_is_obstacle=False,
            distance=self._distance if drive_map is None else None,
        )
        self._table = LikelihoodTable(occupancy)
        self._matcher = CorrelativeScanMatcher(
            window_m=0.3, window_yaw=math.radians(10.0), mount=laser.mount
        )
        self._mcl: MonteCarloLocalizer | None = None
        self._estimate: PoseEstimate | None = None
        self._odometry_at_estimate: Pose2D | None = None
        self._scan: Scan | None = None
        self._recoveries_left = MAX_RECOVERIES

    # -- the device ---------------------------------------------------------------------------

    def connect(self) -> None:
        self.inner.connect()

    def close(self) -> None:
        self.inner.close()

    @property
    def is_connected(self) -> bool:
        return self.inner.is_connected

    def stop(self) -> None:
        self.inner.stop()

    # -- where the base is --------------------------------------------------------------------

    def pose(self) -> Pose2D:
        """The filter's estimate, carried forward by the odometry moved since it was made."""
        estimate, anchor = self._localized()
        return estimate.pose.compose(anchor.relative(self.inner.pose()))

    def pose_covariance(self) -> np.ndarray:
        estimate, _ = self._localized()
        return estimate.covariance

    def estimate(self) -> PoseEstimate:
        """The filter's latest belief (pose, covariance, whether it is localized)."""
        return self._localized()[0]

    def set_pose(self, pose: Pose2D) -> None:
        """Restart the filter around ``pose`` (with the settings' start spread), then weigh a
        scan: a declared pose is a strong hint, not a certainty."""
        self.require_connected("set the pose")
        self._filter().init_pose(pose, self.settings.start_sigma)
        self._settle()

    def restart(self, start: Pose2D | None) -> None:
        """Forget everything (a reused world for a new mission): the filter starts anew from
        its seed around ``start`` (``None``: globally) at the next pose it is asked for."""
        self.start = start
        self._mcl = None
        self._estimate = self._odometry_at_estimate = None
        self._scan = None
        self.planner.forget_obstacles()

    def snapshot(self) -> Localization:
        """What the recorder shows of the localization now: scan, mount, particles."""
        particles = self._mcl.particles if self._mcl is not None else None
        return Localization(self._scan, self.laser.mount, particles)

    @property
    def mount(self) -> LaserMount:
        return self.laser.mount

    # -- moving ---------------------------------------------------------------------------------

    def go_to(self, goal: Pose2D, *, timeout: float = 60.0) -> Pose2D:
        """Drive to ``goal`` (map frame) by legs planned around the map's obstacles; each leg
        ends with a scan at rest that re-localizes the base, and the last legs correct what the
        odometry got wrong until the localized pose is within 5 cm and 3 degrees."""
        self.require_connected(f"go to ({goal.x:.2f}, {goal.y:.2f}) m")
        self._recoveries_left = MAX_RECOVERIES
        for _ in range(3):  # the planned path, then up to two corrections
            here = self.pose()
            if _arrived(here, goal):
                break
            self._drive_path(here, goal, timeout)
        return self.pose()

    def drive(self, speed: float, turn_rate: float, duration: float) -> Pose2D:
        self.inner.drive(speed, turn_rate, duration)
        self._settle()
        return self.pose()

    # -- pieces -----------------------------------------------------------------------------------

    def _filter(self) -> MonteCarloLocalizer:
        if self._mcl is None:
            s = self.settings
            self._mcl = MonteCarloLocalizer(
                self.map,
                self.laser.mount,
                rng=np.random.default_rng(s.seed),
                particles=s.particles,
                config=MclConfig(beams=s.beams),
                initial_pose=self.start,
                initial_sigma=s.start_sigma,
                distance=self._distance,
            )
        return self._mcl

    def _localized(self) -> tuple[PoseEstimate, Pose2D]:
        if self._estimate is None or self._odometry_at_estimate is None:
            self.require_connected("localize")
            global_start = self.start is None
            self._settle((GLOBAL_UPDATES, GLOBAL_UPDATES) if global_start else SETTLE_UPDATES)
        assert self._estimate is not None and self._odometry_at_estimate is not None
        return self._estimate, self._odometry_at_estimate

    def _update(self) -> PoseEstimate:
        """Weigh one fresh scan, taken at rest, against the map."""
        mcl = self._filter()
        self._scan = self.laser.scan()
        odometry = self.inner.pose()
        estimate = mcl.update(odometry, self._scan)
        if self._recentre(estimate, self._scan):
            estimate = mcl.update(odometry, self._scan)
        self._estimate = estimate
        self._odometry_at_estimate = odometry
        return self._estimate

    def _recentre(self, estimate: PoseEstimate, scan: Scan) -> bool:
        """Re-centre the particles on a scan match that disagrees with their mean.

        Why: after a long leg, or once the filter has re-found a kidnapped robot, one update
        collapses the cloud onto the few particles nearest the truth, a decimetre off with a
        covariance of a centimetre (the survivors are alike); the filter's jitter then walks it
        in by about 2 cm a scan. An exhaustive match of the scan over a window around the mean
        (Olson 2009) lands within a few centimetres at once, with an honest covariance; the
        filter, restarted around it, refines from there. A poor match (returns far from the
        map: a kidnapping not yet found, an unmapped change) leaves the filter alone."""
        if not estimate.localized:  # let the filter find the robot first (it resets nothing)
            return False
        try:
            match = self._matcher.match(self._table, scan, estimate.pose)
        except InputError:  # a scan without returns
            return False
        if match.mean_log_likelihood < MATCH_MIN_MEAN_LOG_LIKELIHOOD:
            return False
        sigma = np.sqrt(np.maximum(np.diag(match.covariance), 0.0))
        off = math.hypot(match.pose.x - estimate.pose.x, match.pose.y - estimate.pose.y)
        turned = abs(float(wrap_angle(match.pose.yaw - estimate.pose.yaw)))
        far = off > max(RECENTRE_SIGMAS * float(sigma[:2].max()), RECENTRE_MIN_M)
        turned_away = turned > max(RECENTRE_SIGMAS * float(sigma[2]), RECENTRE_MIN_YAW)
        if not (far or turned_away):
            return False
        self._filter().init_pose(match.pose, tuple(float(v) for v in sigma))
        return True

    def _settle(self, updates: tuple[int, int] = SETTLE_UPDATES) -> PoseEstimate:
        """Scans at rest until the filter has said "localized" ``updates[0]`` times in a row,
        or ``updates[1]`` scans: a filter that has just re-found itself (after a kidnapping)
        says so while still decimetres off, and converges over the next few scans."""
        least, most = updates
        in_a_row = 0
        estimate = self._update()
        for _ in range(1, most):
            in_a_row = in_a_row + 1 if estimate.localized else 0
            if in_a_row >= least:
                break
            estimate = self._update()
        return estimate

    def _drive_path(self, here: Pose2D, goal: Pose2D, timeout: float) -> None:
        try:
            legs = self._legs(here, goal)
        except (InputError, NoPathError) as exc:
            raise DeviceFaultError(
                self.name,
                f"go to ({goal.x:.2f}, {goal.y:.2f}) m",
                f"no safe path from ({here.x:.2f}, {here.y:.2f}) m: {exc}",
                "choose a stop farther from the furniture, or check the map",
            ) from None
        for target in legs:
            if not self._drive_leg(target, goal, timeout):
                return  # it met something, and went on to ``goal`` by a new plan

    def _legs(self, here: Pose2D, goal: Pose2D) -> list[Pose2D]:
        """The planned waypoints as poses: each faces along its next leg, the last the goal."""
        if math.hypot(goal.x - here.x, goal.y - here.y) < ARRIVED_M:
            return [goal]  # only a turn on the spot is left
        points = self.planner.plan((here.x, here.y), (goal.x, goal.y), START_TOLERANCE).waypoints[
            1:
        ]
        poses = []
        for k, (x, y) in enumerate(points):
            if k + 1 < len(points):
                nx, ny = points[k + 1]
                poses.append(Pose2D(float(x), float(y), math.atan2(ny - y, nx - x)))
            else:
                poses.append(Pose2D(float(x), float(y), goal.yaw))
        return poses

    def _drive_leg(self, target: Pose2D, goal: Pose2D, timeout: float) -> bool:
        """Drive one leg to ``target``; True when it got there. After a touch (or a stall) the
        base backs off and plans again to ``goal``, the leg's own end may lie in what it felt
        (a door's middle, with a crate before it): False once that new plan is driven."""
        here = self.pose()
        blocked = self._blocked_by_scan(here, target)
        if blocked is not None:
            raise DeviceFaultError(
                self.name,
                f"drive to ({target.x:.2f}, {target.y:.2f}) m",
                f"the laser sees something the map does not hold at ({blocked[0]:.2f}, "
                f"{blocked[1]:.2f}) m in the way",
                "clear the way, or make a new map ('twin map') if the room has changed",
            )
        estimate, anchor = self._localized()
        # the goal in the odometry frame: odometry = anchor ∘ estimate⁻¹ ∘ map pose
        odometry_goal = anchor.compose(estimate.pose.relative(target))
        try:
            self.inner.go_to(odometry_goal, timeout=timeout)
        except DeviceFaultError as fault:
            if self._recoveries_left <= 0:
                raise
            self._recoveries_left -= 1
            # touched something (or stalled): remember what the bumper felt, back away from it,
            # find ourselves, and plan again around it (MAX_RECOVERIES a goal)
            bearing = fault.bearing if isinstance(fault, BumpedError) else None
            if bearing is not None:
                touched = self.pose()
                reach = self.settings.robot_radius + BUMPED_RADIUS_M
                self.planner.add_obstacle(
                    touched.x + reach * math.cos(touched.yaw + bearing),
                    touched.y + reach * math.sin(touched.yaw + bearing),
                    BUMPED_RADIUS_M,
                )
            behind = bearing is not None and abs(float(wrap_angle(bearing))) > math.pi / 2
            self.inner.drive(0.1 if behind else -0.1, 0.0, BACK_OFF_M / 0.1)
            self._settle()
            self._drive_path(self.pose(), goal, timeout)
            return False
        self._settle()
        return True

    def _blocked_by_scan(self, here: Pose2D, target: Pose2D) -> tuple[float, float] | None:
        """A return of the newest scan inside the leg's corridor (the robot's width plus the
        margin, from here to the target) that the map does not explain, or ``None``."""
        if self._scan is None:
            return None
        hits = Localization(self._scan, self.laser.mount).scan_points(here)
        if len(hits) == 0:
            return None
        ax, ay, bx, by = here.x, here.y, target.x, target.y
        length = math.hypot(bx - ax, by - ay)
        if length < 1e-6:
            return None
        ux, uy = (bx - ax) / length, (by - ay) / length
        along = (hits[:, 0] - ax) * ux + (hits[:, 1] - ay) * uy
        across = np.abs(-(hits[:, 0] - ax) * uy + (hits[:, 1] - ay) * ux)
        width = self.settings.robot_radius + self.settings.margin
        inside = (along > 0.0) & (along < length + self.settings.robot_radius) & (across < width)
        if not inside.any():
            return None
        # a return the map explains (an obstacle cell within two cells) is not news
        rows, cols = self.map.cell_of(hits[inside, 0], hits[inside, 1])
        ny, nx = self.map.shape
        rows, cols = np.clip(rows, 0, ny - 1), np.clip(cols, 0, nx - 1)
        unexplained = self._distance[rows, cols] > 2.0 * self.map.resolution
        if not unexplained.any():
            return None
        first = int(np.argmin(np.where(unexplained, along[inside], np.inf)))
        return float(hits[inside][first, 0]), float(hits[inside][first, 1])


def _arrived(pose: Pose2D, goal: Pose2D) -> bool:
    return (
        math.hypot(goal.x - pose.x, goal.y - pose.y) <= ARRIVED_M
        and abs(float(wrap_angle(goal.yaw - pose.yaw))) <= ARRIVED_YAW
    )
