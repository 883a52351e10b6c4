"""Differential-drive kinematics: wheel odometry, its errors, stall detection, and a
turn-drive-turn go-to-pose controller.

Pure arithmetic, no MuJoCo: the sim feeds it wheel angles and motor torques and applies the wheel
speeds it returns, exactly as a real base's firmware would. Units: metres, radians, seconds.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from twin.core.devices import PIONEER_LIMITS, BaseLimits
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, wrap_angle


@dataclass(frozen=True)
class DiffDriveGeometry:
    """Wheel radius and track (distance between the wheels' contact points), metres."""

    wheel_radius: float
    track: float

    def wheel_speeds(self, v: float, omega: float) -> tuple[float, float]:
        """Left and right wheel angular speeds (rad/s) for body speed v (m/s), turn rate (rad/s)."""
        half = 0.5 * self.track * omega
        return (v - half) / self.wheel_radius, (v + half) / self.wheel_radius


@dataclass(frozen=True)
class OdometryErrors:
    """How a real base's wheels differ from what its odometry assumes (all relative, no unit).

    ``wheel_radius_error`` (left, right): the physical wheel's radius is ``(1 + e)`` times the
    assumed one (0.01: 1 % larger, so odometry under-reports that wheel's travel by 1 %).
    ``track_error``: the physical track (wheel contact spacing) is ``(1 + e)`` times the assumed.
    ``slip_noise``: random slip per wheel; a wheel that rolls ``s`` metres is counted with an
    error of standard deviation ``slip_noise * sqrt(s * 1 m)``, i.e. ``slip_noise`` metres per
    metre after the first metre, growing with the square root of the distance (independent
    increments, Chong & Kleeman 1997). ``seed`` seeds that noise.

    The sim makes the first two physically true (the MuJoCo wheels and their spacing change) and
    adds the slip to the odometry's wheel increments. The defaults are an ideal base.
    """

    wheel_radius_error: tuple[float, float] = (0.0, 0.0)
    track_error: float = 0.0
    slip_noise: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        try:
            left, right = (float(e) for e in self.wheel_radius_error)
        except (TypeError, ValueError):
            raise InputError(
                f"wheel_radius_error must be two numbers (left, right), got "
                f"{self.wheel_radius_error!r}"
            ) from None
        object.__setattr__(self, "wheel_radius_error", (left, right))
        checks = (
            ("wheel_radius_error", left, 0.1),
            ("wheel_radius_error", right, 0.1),
            ("track_error", self.track_error, 0.2),
        )
        for name, value, bound in checks:
            if not (math.isfinite(value) and abs(value) <= bound):
                raise InputError(
                    f"odometry {name} {value!r} is not a relative error within +-{bound:g}; "
                    "use e.g. 0.005 for 0.5 %"
                )
        if not (math.isfinite(self.slip_noise) and 0.0 <= self.slip_noise <= 0.1):
            raise InputError(
                f"odometry slip_noise {self.slip_noise!r} must be within [0, 0.1] "
                "(relative standard deviation after 1 m)"
            )

    def physical(self, assumed: DiffDriveGeometry) -> tuple[float, float, float]:
        """The real base's (left radius, right radius, track), metres, for the assumed geometry."""
        left, right = self.wheel_radius_error
        return (
            assumed.wheel_radius * (1.0 + left),
            assumed.wheel_radius * (1.0 + right),
            assumed.track * (1.0 + self.track_error),
        )

    def turn_gain(self) -> float:
        """True turn / odometry turn of a pivot on the spot (wheels turning equal and opposite):
        ``(1 + (e_left + e_right) / 2) / (1 + track_error)``. 1.0 for an ideal base."""
        left, right = self.wheel_radius_error
        return (1.0 + 0.5 * (left + right)) / (1.0 + self.track_error)

    def straight_drift(self, assumed: DiffDriveGeometry) -> float:
        """True heading change (rad) per metre of a drive that odometry counts as straight
        (both wheels turning through the same angle): ``(e_right - e_left) / track_true``."""
        left, right = self.wheel_radius_error
        return (right - left) / (assumed.track * (1.0 + self.track_error))


class Odometry:
    """Dead reckoning from wheel angle increments (exact arcs, not Euler steps).

    With ``slip_noise`` > 0 (see ``OdometryErrors``) each wheel's counted increment gets a
    zero-mean Gaussian error of variance ``slip_noise**2 * |increment|`` from ``rng``.
    """

    def __init__(
        self,
        geometry: DiffDriveGeometry,
        pose: Pose2D,
        left: float,
        right: float,
        slip_noise: float = 0.0,
        rng: np.random.Generator | None = None,
    ):
        self.geometry = geometry
        self.slip_noise = slip_noise
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.reset(pose, left, right)

    def reset(self, pose: Pose2D, left: float, right: float) -> None:
        """Declare the current pose; ``left``/``right`` are the wheel angles now (rad)."""
        self.x, self.y, self.yaw = pose.x, pose.y, pose.yaw
        self._left, self._right = left, right

    def update(self, left: float, right: float) -> None:
        """Integrate the wheels' new angles (rad)."""
        r = self.geometry.wheel_radius
        dl, dr = (left - self._left) * r, (right - self._right) * r
        self._left, self._right = left, right
        if self.slip_noise > 0.0:
            zl, zr = self.rng.standard_normal(2)
            dl += self.slip_noise * math.sqrt(abs(dl)) * float(zl)
            dr += self.slip_noise * math.sqrt(abs(dr)) * float(zr)
        ds, dyaw = 0.5 * (dl + dr), (dr - dl) / self.geometry.track
        # chord of the arc, taken along the mean heading
        chord = ds if abs(dyaw) < 1e-9 else 2.0 * ds / dyaw * math.sin(0.5 * dyaw)
        heading = self.yaw + 0.5 * dyaw
        self.x += chord * math.cos(heading)
        self.y += chord * math.sin(heading)
        self.yaw = float(wrap_angle(self.yaw + dyaw))

    @property
    def pose(self) -> Pose2D:
        return Pose2D(self.x, self.y, self.yaw)


class StallMonitor:
    """Per-wheel stall flags from motor torque, as a base's firmware raises them from current.

    A wheel is stalled once its motor has strained (``|torque| >= threshold``, N m) for at least
    ``duty`` of the last ``window`` seconds. A share of the time, not an unbroken stretch: a base
    pushing a wall slips and grips in turn (stick-slip), its torque dipping below the threshold
    every ~0.1 s, and an unbroken-stretch rule restarted its clock at every dip, never firing
    while the wheels spun in place and odometry ran on.
    """

    def __init__(self, threshold: float, window: float, duty: float = 0.5) -> None:
        self.threshold, self.window, self.duty = threshold, window, duty
        self.reset()

    def reset(self) -> None:
        """Forget the history (a new motion starts)."""
        self._samples: deque[tuple[float, bool, bool]] = deque()
        self._last: float | None = None
        self._strained = [0.0, 0.0]
        self._covered = 0.0

    def update(self, now: float, left: float, right: float) -> tuple[bool, bool]:
        """Record the torques (N m) applied up to ``now`` (s); returns (left, right) stalled."""
        flags = (abs(left) >= self.threshold, abs(right) >= self.threshold)
        if self._last is None or now < self._last:
            self._last = now
            return False, False
        span = now - self._last
        self._last = now
        self._samples.append((span, *flags))
        self._covered += span
        for i in (0, 1):
            self._strained[i] += span * flags[i]
        while self._samples and self._covered - self._samples[0][0] >= self.window:
            old, *old_flags = self._samples.popleft()
            self._covered -= old
            for i in (0, 1):
                self._strained[i] -= old * old_flags[i]
        if self._covered < self.window * (1.0 - 1e-9):
            return False, False
        limit = self.duty * self._covered
        return self._strained[0] >= limit, self._strained[1] >= limit


def _approach(error: float, vmax: float, decel: float, gain: float) -> float:
    """Speed toward zero error: capped, slowing so that it can stop in time, linear at the end."""
    mag = min(vmax, math.sqrt(2.0 * decel * abs(error)), gain * abs(error))
    return math.copysign(mag, error)


class GoToController:
    """Turn toward the goal, drive straight to it, then turn to the goal's yaw.

    Closed on the odometry estimate (what a real base knows). ``command(pose, dt)`` returns the
    body speed and turn rate to apply for the next ``dt`` seconds; ``done`` turns true once the
    final yaw is within ``yaw_tolerance`` and the position within ``xy_tolerance``.
    The internal tolerances are tighter than the 5 cm / 3 degree promise so that wheel slip and
    servo lag still land inside it.
    """

    def __init__(
        self,
        goal: Pose2D,
        limits: BaseLimits = PIONEER_LIMITS,
        xy_tolerance: float = 0.01,
        yaw_tolerance: float = math.radians(0.7),
    ) -> None:
        self.goal = goal
        self.limits = limits
        self.xy_tolerance = xy_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.near = 3.0 * xy_tolerance
        self.phase = "turn"
        self._v = 0.0
        self._w = 0.0

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def _ramp(self, v: float, w: float, dt: float) -> tuple[float, float]:
        dv = self.limits.accel * dt
        dw = self.limits.turn_accel * dt
        self._v = min(max(v, self._v - dv), self._v + dv)
        self._w = min(max(w, self._w - dw), self._w + dw)
        return self._v, self._w

    def command(self, pose: Pose2D, dt: float) -> tuple[float, float]:
        lim = self.limits
        dx, dy = self.goal.x - pose.x, self.goal.y - pose.y
        dist = math.hypot(dx, dy)
        if self.phase == "turn":
            # already close (e.g. a pure turn at a stop): a pivot-drive-pivot to fix a
            # centimetre would be slower and no better
            if dist <= self.near:
                self.phase = "align"
            else:
                err = float(wrap_angle(math.atan2(dy, dx) - pose.yaw))
                if abs(err) < math.radians(1.0) and abs(self._w) < 0.05:
                    self.phase = "drive"
                else:
                    return self._ramp(
                        0.0, _approach(err, lim.turn_rate, 0.5 * lim.turn_accel, 4.0), dt
                    )
        if self.phase == "drive":
            along = dx * math.cos(pose.yaw) + dy * math.sin(pose.yaw)
            if along <= self.xy_tolerance * 0.5:
                self.phase = "settle"
            else:
                # steer at the goal point while far, straight once close (avoids spinning on it)
                heading = float(wrap_angle(math.atan2(dy, dx) - pose.yaw)) if dist > 0.1 else 0.0
                v = _approach(along, lim.speed, 0.5 * lim.accel, 3.0)
                return self._ramp(v, 2.0 * heading, dt)
        if self.phase == "settle":
            if abs(self._v) < 1e-3:
                self.phase = "align"
            else:
                return self._ramp(0.0, 0.0, dt)
        if self.phase == "align":
            err = pose.heading_error_to(self.goal)
            if abs(err) < self.yaw_tolerance and abs(self._w) < 0.05:
                # a drive that ended off the goal (slip, a nudge) starts over, else done
                self.phase = "turn" if dist > self.near else "done"
            else:
                return self._ramp(0.0, _approach(err, lim.turn_rate, 0.5 * lim.turn_accel, 4.0), dt)
        return self._ramp(0.0, 0.0, dt)
