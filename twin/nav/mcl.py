"""Monte Carlo localization against an occupancy map, from odometry and a planar laser.

The textbook filter (Thrun, Burgard & Fox, *Probabilistic Robotics*, ch. 5, 6 and 8):

* **Motion**: ``sample_motion_model_odometry`` (Table 5.6) applies the odometry increment since
  the last update, split into rot1 / trans / rot2 and perturbed with standard deviations
  ``sqrt(a1 rot1² + a2 trans²)``, ``sqrt(a3 trans² + a4 (rot1² + rot2²))``,
  ``sqrt(a1 rot2² + a2 trans²)``. As in ROS amcl, a rotation's noise is measured from the nearer
  of forwards and backwards (driving backwards is not a half turn), and a step shorter than 1 cm
  has no rot1 (its direction is noise). Every update also adds a small ``jitter`` (roughening):
  a robot standing still keeps being weighed, and duplicated particles must not stay identical.
* **Measurement**: the likelihood field (6.4): a beam's end point at distance d from the nearest
  obstacle has likelihood ``z_hit N(d; 0, sigma_hit) + z_rand / max_range``; beams without a
  return (NaN, or at max range) are left out, as the textbook does; of the rest ``beams`` are
  used, evenly spread. d is the distance to the nearest face of an occupied cell, signed (an
  exact distance transform, ``twin.nav.distance.signed_surface_distance``), read between cell
  centres by bilinear interpolation, then turned into a log-likelihood by a 1 mm table. (The
  textbook's distance to the nearest occupied cell centre, read so, is flat across a wall cell
  and pulled every pose half a cell, 2.5 cm, towards the walls it saw most of.)
* **Resampling**: low-variance (Table 4.4), only when the effective sample size
  ``1 / sum(w²)`` drops below ``resample_threshold × N``. The number drawn is KLD-sampling's bound
  (8.3.7) on the histogram bins the weighted set occupies, between ``particles`` and
  ``max_particles``: a spread-out belief keeps thousands, a converged one drops to the tracking
  count.
* **Global initialisation**: poses uniform over the free cells (at least ``free_clearance`` from
  obstacle faces), headings uniform. While the belief is still that uniform prior, the first scan
  weighs a much denser sample of it (``global_samples``, 50 000: 50-100 ms, once) and resampling
  keeps at most ``max_particles``: with only 5000 particles on a 10 x 8 m map, often no particle
  lies within the likelihood's 20 cm basin of the true pose, and the filter collapsed onto a
  look-alike place it took augmented MCL minutes to leave.
* **Recovery**: augmented MCL (Table 8.3): short- and long-term averages ``w_fast`` / ``w_slow``
  of the measurement likelihood; each resampling replaces a fraction ``max(0, 1 - w_fast /
  w_slow)`` of the particles by random poses. The likelihood they average is the per-beam
  geometric mean, so the number of beams a scan kept does not move it. The random poses are
  picked by the latest scan from ``recovery_pool`` uniform candidates each (sensor resetting):
  on a 10 x 8 m map uniform poses alone often re-locked the filter onto a look-alike place.
* **Estimate**: weighted mean, circular mean for yaw, the 3 × 3 weighted covariance, the effective
  sample size, the weight within ``cluster_radius`` / ``cluster_angle`` of the mean (about 1 for
  one mode; two modes put the mean between them and this mass drops), and the scan fit: the
  fraction of the weighed beams that end near an obstacle seen from the mean pose (a tight cloud
  in the wrong place, as just after a kidnapping, is unimodal but does not fit).

Randomness comes only from the ``numpy.random.Generator`` handed in, so equal seeds give equal
runs. The per-particle loops are compiled by numba (``cache=True``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, require_finite, wrap_angle
from twin.nav.distance import obstacle_distance, signed_surface_distance
from twin.nav.maps import OccupancyMap

TWO_PI = 2.0 * math.pi
# Below this step length (m) the direction of travel is noise: the step has no rot1 (ROS amcl).
_SHORT_STEP = 0.01
_LUT_STEP = 0.001  # m: resolution of the likelihood-by-distance table


@dataclass(frozen=True)
class MclConfig:
    """The filter's parameters (SI units). Defaults suit an LMS200 on a map of 5 cm cells.

    ``sigma_hit`` (m) is wider than the scanner's 5 mm noise on purpose: it stands for the map's
    cells, furniture the map does not hold exactly, and the correlation between neighbouring
    beams, and it gives the likelihood a basin wide enough to pull in a particle 20 cm off.
    """

    beams: int = 60
    sigma_hit: float = 0.10
    z_hit: float = 0.9
    z_rand: float = 0.1
    # sample_motion_model_odometry: a1 rad²/rad², a2 rad²/m², a3 m²/m², a4 m²/rad²
    alphas: tuple[float, float, float, float] = (0.05, 0.05, 0.05, 0.05)
    jitter_xy: float = 0.01  # m per update
    jitter_yaw: float = math.radians(0.5)  # rad per update
    resample_threshold: float = 0.5  # resample when ESS < this × particle count
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    max_particles: int = 5000
    # the first scan after init_global weighs this many uniform poses (0: max_particles only)
    global_samples: int = 50000
    recovery_pool: int = 20  # uniform candidates per random particle, picked by the scan
    kld_epsilon: float = 0.05
    kld_z: float = 2.326  # upper 1 - delta quantile of the normal, delta = 0.01
    kld_bin_xy: float = 0.25  # m
    kld_bin_yaw: float = math.radians(10.0)
    free_clearance: float = 0.10  # m: random particles keep this far from occupied cells
    cluster_radius: float = 0.5  # m
    cluster_angle: float = math.radians(30.0)
    unimodal_mass: float = 0.9
    localized_std_xy: float = 0.10  # m
    localized_std_yaw: float = math.radians(5.0)
    fit_distance: float = 0.15  # m: a beam fits when its end point is this close to the map
    min_scan_fit: float = 0.5  # the fraction of beams that must fit to call it localized

    def __post_init__(self) -> None:
        positive = {
            "beams": self.beams,
            "sigma_hit": self.sigma_hit,
            "z_hit": self.z_hit,
            "z_rand": self.z_rand,
            "max_particles": self.max_particles,
            "kld_epsilon": self.kld_epsilon,
            "kld_bin_xy": self.kld_bin_xy,
            "kld_bin_yaw": self.kld_bin_yaw,
            "cluster_radius": self.cluster_radius,
            "cluster_angle": self.cluster_angle,
            "localized_std_xy": self.localized_std_xy,
            "localized_std_yaw": self.localized_std_yaw,
            "fit_distance": self.fit_distance,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"MCL {name} must be positive, got {value!r}")
        non_negative = {
            "jitter_xy": self.jitter_xy,
            "jitter_yaw": self.jitter_yaw,
            "free_clearance": self.free_clearance,
            "kld_z": self.kld_z,
        }
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"MCL {name} must be zero or positive, got {value!r}")
        for name, value in (
            ("beams", self.beams),
            ("max_particles", self.max_particles),
            ("global_samples", self.global_samples),
        ):
            if int(value) != value or value < 0:
                raise InputError(f"MCL {name} must be a whole number, got {value!r}")
        if int(self.recovery_pool) != self.recovery_pool or self.recovery_pool < 1:
            raise InputError(f"MCL recovery_pool must be 1 or more, got {self.recovery_pool!r}")
        if len(self.alphas) != 4 or not all(math.isfinite(a) and a >= 0 for a in self.alphas):
            raise InputError(f"MCL alphas must be four non-negative numbers, got {self.alphas!r}")
        for name, value in (
            ("resample_threshold", self.resample_threshold),
            ("alpha_slow", self.alpha_slow),
            ("alpha_fast", self.alpha_fast),
            ("unimodal_mass", self.unimodal_mass),
            ("min_scan_fit", self.min_scan_fit),
        ):
            if not 0.0 <= value <= 1.0:
                raise InputError(f"MCL {name} must be in [0, 1], got {value!r}")
        if self.alpha_slow > self.alpha_fast:
            raise InputError(
                f"MCL alpha_slow ({self.alpha_slow}) must not exceed alpha_fast "
                f"({self.alpha_fast}): w_slow is the long-term average"
            )


@dataclass(frozen=True)
class PoseEstimate:
    """The filter's belief after an update: the weighted mean pose and how much to trust it.

    ``covariance`` is over (x m, y m, yaw rad); ``ess`` the effective sample size before any
    resampling; ``mode_mass`` the weight within the config's cluster radius / angle of the mean;
    ``unimodal`` says it reaches the config's ``unimodal_mass`` (two modes put the mean between
    them and the mass near it drops); ``scan_fit`` is the fraction of the latest scan's weighed
    beams that end within ``fit_distance`` of an obstacle seen from the mean pose (None before
    the first scan): a tight cloud in the wrong place, as after a kidnapping, is unimodal but
    does not fit. ``localized`` says unimodal, fitting, and within the config's spreads.
    ``resampled`` and ``injected`` (random particles added) describe this update; ``beams`` is
    how many of the scan's beams were weighed.
    """

    pose: Pose2D
    covariance: np.ndarray
    ess: float
    particles: int
    mode_mass: float
    unimodal: bool
    scan_fit: float | None
    localized: bool
    resampled: bool = False
    injected: int = 0
    beams: int = 0
    timestamp: float | None = None

    @property
    def std_xy(self) -> float:
        """Standard deviation (m) of the position along its most uncertain direction."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.covariance[:2, :2])[-1], 0.0)))

    @property
    def std_yaw(self) -> float:
        """Standard deviation (rad) of the heading."""
        return float(math.sqrt(max(self.covariance[2, 2], 0.0)))


# -- compiled kernels ------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _wrap(angle: float) -> float:
    return (angle + math.pi) % TWO_PI - math.pi


@njit(cache=True)
def sample_motion_odometry(
    poses: np.ndarray,
    rot1: float,
    trans: float,
    rot2: float,
    alphas: np.ndarray,
    jitter_xy: float,
    jitter_yaw: float,
    noise: np.ndarray,
) -> None:
    """Move every particle (n, 3) in place by the odometry step (rot1, trans, rot2) with the
    textbook's noise; ``noise`` (n, 6) holds standard normals (3 for the step, 3 for jitter)."""
    a1, a2, a3, a4 = alphas[0], alphas[1], alphas[2], alphas[3]
    r1 = min(abs(_wrap(rot1)), abs(_wrap(rot1 - math.pi)))
    r2 = min(abs(_wrap(rot2)), abs(_wrap(rot2 - math.pi)))
    sd_rot1 = math.sqrt(a1 * r1 * r1 + a2 * trans * trans)
    sd_trans = math.sqrt(a3 * trans * trans + a4 * (r1 * r1 + r2 * r2))
    sd_rot2 = math.sqrt(a1 * r2 * r2 + a2 * trans * trans)
    for i in range(poses.shape[0]):
        h1 = rot1 - sd_rot1 * noise[i, 0]
        t = trans - sd_trans * noise[i, 1]
        h2 = rot2 - sd_rot2 * noise[i, 2]
        heading = poses[i, 2] + h1
        poses[i, 0] += t * math.cos(heading) + jitter_xy * noise[i, 3]
        poses[i, 1] += t * math.sin(heading) + jitter_xy * noise[i, 4]
        poses[i, 2] = _wrap(heading + h2 + jitter_yaw * noise[i, 5])


@njit(cache=True, inline="always")
def _surface_at(surface: np.ndarray, u: float, v: float, far: float) -> float:
    """|signed distance| read bilinearly at padded cell coordinates (u, v); ``far`` outside."""
    if not (u >= 0.0 and v >= 0.0 and u < surface.shape[1] - 1.0 and v < surface.shape[0] - 1.0):
        return far
    iu = int(u)
    iv = int(v)
    fu = u - iu
    fv = v - iv
    low = surface[iv, iu] + fu * (surface[iv, iu + 1] - surface[iv, iu])
    high = surface[iv + 1, iu] + fu * (surface[iv + 1, iu + 1] - surface[iv + 1, iu])
    return abs(low + fv * (high - low))


@njit(cache=True)
def log_likelihoods(
    poses: np.ndarray,
    beam_x: np.ndarray,
    beam_y: np.ndarray,
    surface: np.ndarray,
    x0: float,
    y0: float,
    inv_res: float,
    lut: np.ndarray,
    inv_lut_step: float,
    out: np.ndarray,
) -> None:
    """Sum over the beams of log p(beam | particle) into ``out`` (n,).

    ``beam_x``, ``beam_y`` are the end points in the base frame (the mount already applied);
    ``surface`` is the signed distance to the nearest obstacle face per cell, clipped and padded
    by one cell of the clip value (beyond the map), read with bilinear interpolation;
    ``lut[k]`` is the log-likelihood at distance k / ``inv_lut_step`` (the last entry also
    beyond it).
    """
    last = lut.shape[0] - 1
    far = last / inv_lut_step
    m = beam_x.shape[0]
    for i in range(poses.shape[0]):
        px, py = poses[i, 0], poses[i, 1]
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        total = 0.0
        for k in range(m):
            # padded column of cell (r, c)'s centre is c + 1: u = (x - x0) / res + 0.5
            u = (px + c * beam_x[k] - s * beam_y[k] - x0) * inv_res + 0.5
            v = (py + s * beam_x[k] + c * beam_y[k] - y0) * inv_res + 0.5
            j = int(_surface_at(surface, u, v, far) * inv_lut_step)
            total += lut[min(j, last)]
        out[i] = total


@njit(cache=True)
def beam_distances(
    pose: np.ndarray,
    beam_x: np.ndarray,
    beam_y: np.ndarray,
    surface: np.ndarray,
    x0: float,
    y0: float,
    inv_res: float,
    far: float,
) -> np.ndarray:
    """(m,) metres from each beam's end point, seen from one base pose (3,), to the nearest
    obstacle face (``far`` beyond the clip or the map)."""
    out = np.empty(beam_x.shape[0])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for k in range(beam_x.shape[0]):
        u = (pose[0] + c * beam_x[k] - s * beam_y[k] - x0) * inv_res + 0.5
        v = (pose[1] + s * beam_x[k] + c * beam_y[k] - y0) * inv_res + 0.5
        out[k] = _surface_at(surface, u, v, far)
    return out


@njit(cache=True)
def low_variance_indices(weights: np.ndarray, count: int, start: float) -> np.ndarray:
    """Table 4.4's low-variance sampler: ``count`` indices drawn with one random ``start`` in
    [0, 1) at the points (start + m) / count of the weights' cumulative sum (normalised), so
    particle i is drawn floor or ceil of ``count * weights[i]`` times."""
    out = np.empty(count, dtype=np.int64)
    last = weights.shape[0] - 1
    while last > 0 and weights[last] <= 0.0:
        last -= 1  # rounding in the sum must never reach a particle of weight 0
    step = 1.0 / count
    u = start * step
    cumulative = weights[0]
    i = 0
    for m in range(count):
        while u >= cumulative and i < last:
            i += 1
            cumulative += weights[i]
        out[m] = i
        u += step
    return out


def kld_bound(bins: int, epsilon: float, z: float) -> int:
    """KLD-sampling's particle count (Fox 2003): enough that the sample-based histogram over
    ``bins`` occupied bins is within KL divergence ``epsilon`` of the true one with
    probability 1 - delta (``z`` its normal quantile)."""
    if bins <= 1:
        return 1
    k = bins - 1
    a = 2.0 / (9.0 * k)
    return math.ceil(k / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3)


def _logsumexp(values: np.ndarray) -> float:
    top = float(np.max(values))
    if not math.isfinite(top):
        return top
    return top + math.log(float(np.sum(np.exp(values - top))))


# -- the filter ------------------------------------------------------------------------------


@dataclass
class _Monitor:
    """Augmented MCL's averages, in log space (the likelihoods are tiny)."""

    log_slow: float | None = None
    log_fast: float | None = None

    def update(self, log_avg: float, alpha_slow: float, alpha_fast: float) -> None:
        if self.log_slow is None or self.log_fast is None:
            self.log_slow = self.log_fast = log_avg
            return
        self.log_slow = _log_blend(self.log_slow, log_avg, alpha_slow)
        self.log_fast = _log_blend(self.log_fast, log_avg, alpha_fast)

    @property
    def inject_fraction(self) -> float:
        if self.log_slow is None or self.log_fast is None:
            return 0.0
        return max(0.0, 1.0 - math.exp(min(self.log_fast - self.log_slow, 0.0)))


def _log_blend(log_old: float, log_new: float, alpha: float) -> float:
    """log((1 - alpha) exp(log_old) + alpha exp(log_new))."""
    if alpha <= 0.0:
        return log_old
    if alpha >= 1.0:
        return log_new
    return float(np.logaddexp(math.log1p(-alpha) + log_old, math.log(alpha) + log_new))


class MonteCarloLocalizer:
    """Particle filter over base poses (map frame) from odometry and laser scans.

    ``update(odometry_pose, scan)`` moves the particles by the odometry increment since the
    previous update (the first call only records the odometry), weighs them by the scan,
    resamples if the effective sample size is low, and returns the estimate. Without
    ``initial_pose`` the filter starts globally (``init_global``), else around it.
    ``distance`` may hand in ``obstacle_distance(map)`` already computed (the planner's, say).
    """

    def __init__(
        self,
        occupancy_map: OccupancyMap,
        mount: LaserMount,
        *,
        rng: np.random.Generator,
        particles: int = 500,
        config: MclConfig | None = None,
        initial_pose: Pose2D | None = None,
        initial_sigma: tuple[float, float, float] = (0.1, 0.1, math.radians(10.0)),
        distance: np.ndarray | None = None,
    ) -> None:
        if not isinstance(rng, np.random.Generator):
            raise InputError(
                f"MonteCarloLocalizer needs a numpy.random.Generator (np.random.default_rng(seed))"
                f", got {type(rng).__name__}"
            )
        if int(particles) != particles or particles < 1:
            raise InputError(f"MCL particles must be a positive whole number, got {particles!r}")
        require_finite("laser mount", mount.x, mount.y, mount.yaw)
        self.map = occupancy_map
        self.mount = mount
        self.rng = rng
        self.config = config or MclConfig()
        self.particle_count = int(particles)
        self.max_particles = max(self.particle_count, self.config.max_particles)
        if distance is None:
            distance = obstacle_distance(occupancy_map)
        distance = np.asarray(distance, dtype=float)
        if distance.shape != occupancy_map.shape:
            raise InputError(
                f"distance field shape {distance.shape} does not match the map's "
                f"{occupancy_map.shape}"
            )
        self.distance = distance
        # the likelihood field: signed distance to obstacle faces, clipped where the Gaussian
        # has died out, padded by one cell of "far" for end points beyond the map
        self._clip = 8.0 * self.config.sigma_hit
        surface = np.clip(signed_surface_distance(occupancy_map, distance), -self._clip, self._clip)
        self._surface = np.pad(surface, 1, constant_values=self._clip)
        self._luts: dict[float, np.ndarray] = {}
        self._alphas = np.asarray(self.config.alphas, dtype=float)
        faces = distance - occupancy_map.resolution / 2.0
        spawn = occupancy_map.free & (faces >= self.config.free_clearance)
        self._spawn_cells = np.flatnonzero(spawn)
        self._odometry: Pose2D | None = None
        self._monitor = _Monitor()
        self._poses = np.zeros((0, 3))
        self._log_w = np.zeros(0)
        self._estimate: PoseEstimate | None = None
        self._scan_fit: float | None = None
        self._global_pending = False
        self._beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if initial_pose is None:
            self.init_global()
        else:
            self.init_pose(initial_pose, initial_sigma)

    # -- initialisation ---------------------------------------------------------------------

    def init_pose(
        self,
        pose: Pose2D,
        sigma: tuple[float, float, float] = (0.1, 0.1, math.radians(10.0)),
    ) -> PoseEstimate:
        """Start around ``pose``: ``particles`` Gaussian samples with standard deviations
        ``sigma`` = (x m, y m, yaw rad). Keeps the odometry reference."""
        if len(sigma) != 3 or not all(math.isfinite(s) and s >= 0 for s in sigma):
            raise InputError(f"init_pose sigma must be three non-negative numbers, got {sigma!r}")
        n = self.particle_count
        poses = np.empty((n, 3))
        noise = self.rng.standard_normal((n, 3))
        poses[:, 0] = pose.x + sigma[0] * noise[:, 0]
        poses[:, 1] = pose.y + sigma[1] * noise[:, 1]
        poses[:, 2] = wrap_angle(pose.yaw + sigma[2] * noise[:, 2])
        return self._reset(poses)

    def init_global(self) -> PoseEstimate:
        """Start anywhere: ``max_particles`` poses uniform over the free cells (at least
        ``free_clearance`` from occupied ones) with uniform headings."""
        estimate = self._reset(self._random_poses(self.max_particles))
        self._global_pending = True
        return estimate

    def init_particles(self, poses: np.ndarray, weights: np.ndarray | None = None) -> PoseEstimate:
        """Start from given hypotheses: (n, 3) poses (x m, y m, yaw rad) and optional weights
        (equal if None), e.g. the candidates of a global scan match."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) == 0:
            raise InputError(f"init_particles needs (n, 3) poses, got shape {poses.shape}")
        if not np.all(np.isfinite(poses)):
            raise InputError("init_particles poses must be finite")
        if weights is None:
            return self._reset(poses)
        weights = np.asarray(weights, dtype=float)
        if weights.shape != (len(poses),) or not np.all(weights >= 0) or weights.sum() <= 0:
            raise InputError(
                f"init_particles weights must be {len(poses)} non-negative numbers, not all 0"
            )
        with np.errstate(divide="ignore"):
            return self._reset(poses, np.log(weights / weights.sum()))

    def _reset(self, poses: np.ndarray, log_w: np.ndarray | None = None) -> PoseEstimate:
        self._poses = np.ascontiguousarray(poses, dtype=float).copy()
        self._poses[:, 2] = wrap_angle(self._poses[:, 2])
        self._log_w = np.full(len(poses), -math.log(len(poses))) if log_w is None else log_w
        self._monitor = _Monitor()
        self._scan_fit = None
        self._global_pending = False
        self._estimate = self._summarize(None, timestamp=None)
        return self._estimate

    def _random_poses(self, count: int) -> np.ndarray:
        if self._spawn_cells.size == 0:
            raise InputError(
                f"the map has no free cell {self.config.free_clearance} m from an obstacle to "
                "place particles in; lower free_clearance or give a start pose (init_pose)"
            )
        nx = self.map.shape[1]
        cells = self._spawn_cells[self.rng.integers(0, self._spawn_cells.size, count)]
        offsets = self.rng.random((count, 3))
        res = self.map.resolution
        poses = np.empty((count, 3))
        poses[:, 0] = self.map.origin[0] + (cells % nx + offsets[:, 0]) * res
        poses[:, 1] = self.map.origin[1] + (cells // nx + offsets[:, 1]) * res
        poses[:, 2] = offsets[:, 2] * TWO_PI - math.pi
        return poses

    # -- the filter -------------------------------------------------------------------------

    @property
    def particles(self) -> np.ndarray:
        """(n, 3) copy of the particles: x m, y m, yaw rad."""
        return self._poses.copy()

    @property
    def weights(self) -> np.ndarray:
        """(n,) copy of the normalised weights."""
        return np.exp(self._log_w)

    def estimate(self) -> PoseEstimate:
        """The belief as of the last update (or initialisation)."""
        assert self._estimate is not None
        return self._estimate

    def update(self, odometry_pose: Pose2D, scan: Scan | None = None) -> PoseEstimate:
        """One filter step: motion from the odometry increment, then (with a scan) the
        measurement, then low-variance resampling if the ESS is below the threshold."""
        self.predict(odometry_pose)
        if scan is not None and self._global_pending and self.config.global_samples:
            # the belief is still uniform: the scan weighs a denser sample of it
            self._poses = self._random_poses(max(self.config.global_samples, len(self._poses)))
            self._log_w = np.full(len(self._poses), -math.log(len(self._poses)))
        beams = None if scan is None else self._weigh(scan)
        if beams is not None:
            self._global_pending = False
        estimate = self._summarize(beams, timestamp=None if scan is None else scan.timestamp)
        if beams is not None and estimate.ess < self.config.resample_threshold * len(self._poses):
            estimate = replace(estimate, resampled=True, injected=self._resample())
        self._estimate = estimate
        return estimate

    def predict(self, odometry_pose: Pose2D) -> None:
        """Move the particles by the odometry increment since the last call (the first call
        only takes the odometry as the reference)."""
        previous, self._odometry = self._odometry, odometry_pose
        if previous is None:
            return
        dx, dy = odometry_pose.x - previous.x, odometry_pose.y - previous.y
        turn = float(wrap_angle(odometry_pose.yaw - previous.yaw))
        trans = math.hypot(dx, dy)
        if trans < _SHORT_STEP:
            # no rot1: the step's direction is noise; keep its component along the heading
            trans = dx * math.cos(previous.yaw) + dy * math.sin(previous.yaw)
            rot1 = 0.0
        else:
            rot1 = float(wrap_angle(math.atan2(dy, dx) - previous.yaw))
        rot2 = float(wrap_angle(turn - rot1))
        noise = self.rng.standard_normal((len(self._poses), 6))
        sample_motion_odometry(
            self._poses,
            rot1,
            trans,
            rot2,
            self._alphas,
            self.config.jitter_xy,
            self.config.jitter_yaw,
            noise,
        )

    def _lut(self, max_range: float) -> np.ndarray:
        """log(z_hit N(d; 0, sigma_hit) + z_rand / max_range) at d = 0, 1, 2 ... mm up to the
        clip distance, for scans of this max range."""
        lut = self._luts.get(max_range)
        if lut is None:
            cfg = self.config
            d = np.arange(round(self._clip / _LUT_STEP) + 1) * _LUT_STEP
            hit = cfg.z_hit * np.exp(-0.5 * (d / cfg.sigma_hit) ** 2)
            lut = np.log(hit / (cfg.sigma_hit * math.sqrt(TWO_PI)) + cfg.z_rand / max_range)
            self._luts[max_range] = lut
        return lut

    def _weigh(self, scan: Scan) -> tuple[np.ndarray, np.ndarray] | None:
        """Multiply the weights by the scan's likelihood; returns the end points (base frame)
        of the beams used, None if the scan had no usable beam (the weights stay)."""
        if not (math.isfinite(scan.max_range) and scan.max_range > 0):
            raise InputError(f"scan max_range must be positive, got {scan.max_range!r} m")
        ranges = np.asarray(scan.ranges, dtype=float)
        angles = np.asarray(scan.angles, dtype=float)
        if ranges.shape != angles.shape or ranges.ndim != 1:
            raise InputError(
                f"scan angles {angles.shape} and ranges {ranges.shape} must be equal 1-D arrays"
            )
        with np.errstate(invalid="ignore"):
            usable = np.isfinite(ranges) & (ranges > 0) & (ranges < scan.max_range)
        usable &= np.isfinite(angles)
        index = np.flatnonzero(usable)
        if index.size == 0:
            return None
        if index.size > self.config.beams:
            pick = np.round(np.linspace(0, index.size - 1, self.config.beams)).astype(np.int64)
            index = index[pick]
        r = ranges[index]
        a = angles[index] + self.mount.yaw
        beam_x = np.ascontiguousarray(self.mount.x + r * np.cos(a))
        beam_y = np.ascontiguousarray(self.mount.y + r * np.sin(a))
        self._beams = (beam_x, beam_y, self._lut(float(scan.max_range)))
        loglik = self._log_likelihoods(self._poses)
        # augmented MCL: the belief's predicted likelihood of the scan, per beam
        log_avg = _logsumexp(self._log_w + loglik / index.size)
        self._monitor.update(log_avg, self.config.alpha_slow, self.config.alpha_fast)
        log_w = self._log_w + loglik
        self._log_w = log_w - _logsumexp(log_w)
        return beam_x, beam_y

    def _log_likelihoods(self, poses: np.ndarray) -> np.ndarray:
        """log p(last weighed scan | pose) for each of the poses (n, 3)."""
        assert self._beams is not None
        beam_x, beam_y, lut = self._beams
        out = np.empty(len(poses))
        log_likelihoods(
            poses,
            beam_x,
            beam_y,
            self._surface,
            self.map.origin[0],
            self.map.origin[1],
            1.0 / self.map.resolution,
            lut,
            1.0 / _LUT_STEP,
            out,
        )
        return out

    def _ess(self) -> float:
        return float(1.0 / np.sum(np.exp(2.0 * self._log_w)))

    def _resample(self) -> int:
        """Low-variance resampling to the KLD count, a fraction of it replaced by random poses
        (augmented MCL); returns how many were random.

        The random poses are drawn as sensor resetting does (Lenser & Veloso 2000; the dual
        proposal of Mixture MCL, 8.3.5): ``recovery_pool`` uniform candidates per pose, of which
        the latest scan's likelihood picks (low-variance again). Uniform poses alone rarely land
        within the likelihood's 20 cm basin of a kidnapped robot on a large map, and the filter
        re-locked onto a look-alike place instead."""
        weights = np.exp(self._log_w)
        count = self._kld_count(weights)
        fraction = self._monitor.inject_fraction if self._spawn_cells.size else 0.0
        injected = int(self.rng.binomial(count, fraction)) if fraction > 0.0 else 0
        kept = count - injected
        parts = []
        if kept:
            weights /= weights.sum()
            index = low_variance_indices(weights, kept, float(self.rng.random()))
            parts.append(self._poses[index])
        if injected:
            pool = self._random_poses(injected * self.config.recovery_pool)
            if len(pool) > injected:
                loglik = self._log_likelihoods(pool)
                chance = np.exp(loglik - loglik.max())
                pick = low_variance_indices(chance / chance.sum(), injected, self.rng.random())
                pool = pool[pick]
            parts.append(pool)
        self._poses = np.ascontiguousarray(np.concatenate(parts))
        self._log_w = np.full(count, -math.log(count))
        return injected

    def _kld_count(self, weights: np.ndarray) -> int:
        """Particles to draw: KLD's bound for the bins holding at least 1 / max_particles of the
        weight (the bins a draw of max_particles would expect to fill), clipped to
        [particles, max_particles]."""
        cfg = self.config
        if self.max_particles == self.particle_count:
            return self.particle_count
        bx = np.floor(self._poses[:, 0] / cfg.kld_bin_xy).astype(np.int64)
        by = np.floor(self._poses[:, 1] / cfg.kld_bin_xy).astype(np.int64)
        byaw = np.floor((self._poses[:, 2] + math.pi) / cfg.kld_bin_yaw).astype(np.int64)
        # one integer per bin (2**21 bins per axis is far beyond any map)
        keys = ((bx - bx.min()) << 42) | ((by - by.min()) << 21) | byaw
        _, inverse = np.unique(keys, return_inverse=True)
        mass = np.bincount(inverse, weights=weights)
        bins = int(np.count_nonzero(mass >= 1.0 / self.max_particles))
        wanted = kld_bound(bins, cfg.kld_epsilon, cfg.kld_z)
        return int(min(max(wanted, self.particle_count), self.max_particles))

    def _summarize(
        self, beams: tuple[np.ndarray, np.ndarray] | None, timestamp: float | None
    ) -> PoseEstimate:
        """The weighted mean and covariance and the verdicts on them; with the weighed beams'
        end points the scan fit is measured anew from the mean pose."""
        cfg = self.config
        w = np.exp(self._log_w)
        w /= w.sum()
        x, y, yaw = self._poses[:, 0], self._poses[:, 1], self._poses[:, 2]
        mean_x, mean_y = float(w @ x), float(w @ y)
        mean_yaw = math.atan2(float(w @ np.sin(yaw)), float(w @ np.cos(yaw)))
        deviation = np.stack([x - mean_x, y - mean_y, wrap_angle(yaw - mean_yaw)], axis=1)
        covariance = (deviation * w[:, None]).T @ deviation
        near = (np.hypot(deviation[:, 0], deviation[:, 1]) <= cfg.cluster_radius) & (
            np.abs(deviation[:, 2]) <= cfg.cluster_angle
        )
        mode_mass = float(w[near].sum())
        std_xy = math.sqrt(max(float(np.linalg.eigvalsh(covariance[:2, :2])[-1]), 0.0))
        std_yaw = math.sqrt(max(float(covariance[2, 2]), 0.0))
        pose = Pose2D(mean_x, mean_y, float(wrap_angle(mean_yaw)))
        if beams is not None:
            distances = beam_distances(
                np.array([pose.x, pose.y, pose.yaw]),
                beams[0],
                beams[1],
                self._surface,
                self.map.origin[0],
                self.map.origin[1],
                1.0 / self.map.resolution,
                self._clip,
            )
            self._scan_fit = float(np.mean(distances <= cfg.fit_distance))
        unimodal = mode_mass >= cfg.unimodal_mass
        localized = (
            unimodal
            and std_xy <= cfg.localized_std_xy
            and std_yaw <= cfg.localized_std_yaw
            and (self._scan_fit is None or self._scan_fit >= cfg.min_scan_fit)
        )
        return PoseEstimate(
            pose=pose,
            covariance=covariance,
            ess=self._ess(),
            particles=len(self._poses),
            mode_mass=mode_mass,
            unimodal=bool(unimodal),
            scan_fit=self._scan_fit,
            localized=bool(localized),
            beams=0 if beams is None else len(beams[0]),
            timestamp=timestamp,
        )


Localizer = MonteCarloLocalizer
