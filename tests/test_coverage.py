"""Properties of supersampled wedge coverage (twin.core.coverage via AccumulatorGrid.coverage)."""

import math

import numpy as np
import pytest

from twin.core.grid import AccumulatorGrid, GridSpec


def brute_force_coverage(spec, s, origin, a0, a1, max_range=None):
    """Point-by-point reference: the fraction of each cell's s x s sample points in [a0, a1)."""
    h = spec.cell_size / s
    xs = spec.x_min + (np.arange(spec.nx * s) + 0.5) * h
    ys = spec.y_min + (np.arange(spec.ny * s) + 0.5) * h
    x, y = np.meshgrid(xs, ys)
    bearing = np.arctan2(y - origin[1], x - origin[0]) % (2 * np.pi)
    inside = ((bearing - a0) % (2 * np.pi)) < (a1 - a0)
    if max_range is not None:
        inside &= np.hypot(x - origin[0], y - origin[1]) <= max_range
    return inside.reshape(spec.ny, s, spec.nx, s).mean(axis=(1, 3))


def clip_polygon(polygon, keep):
    """Sutherland-Hodgman clip of a polygon by the half-plane keep(p) >= 0 (keep is linear)."""
    out = []
    for i, p in enumerate(polygon):
        q = polygon[(i + 1) % len(polygon)]
        kp, kq = keep(p), keep(q)
        if kp >= 0:
            out.append(p)
        if (kp >= 0) != (kq >= 0):
            t = kp / (kp - kq)
            out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return out


def polygon_area(polygon):
    if len(polygon) < 3:
        return 0.0
    x, y = np.array(polygon).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def wedge_area_in_rect(spec, origin, a0, a1):
    """Exact area of the (narrower than pi) wedge from origin inside the grid rectangle."""
    ox, oy = origin
    rect = [(spec.x_min, spec.y_min), (spec.x_max, spec.y_min),
            (spec.x_max, spec.y_max), (spec.x_min, spec.y_max)]  # fmt: skip
    # Left of the ray at a0, right of the ray at a1.
    left_of_a0 = lambda p: math.cos(a0) * (p[1] - oy) - math.sin(a0) * (p[0] - ox)  # noqa: E731
    right_of_a1 = lambda p: math.sin(a1) * (p[0] - ox) - math.cos(a1) * (p[1] - oy)  # noqa: E731
    return polygon_area(clip_polygon(clip_polygon(rect, left_of_a0), right_of_a1))


@pytest.mark.parametrize("seed", range(40))
def test_coverage_equals_point_by_point_reference(seed):
    rng = np.random.default_rng(seed)
    nx, ny = (int(v) for v in rng.integers(2, 12, size=2))
    cell = float(rng.uniform(0.1, 1.0))
    spec = GridSpec(-1.0, 0.5, -1.0 + nx * cell, 0.5 + ny * cell, cell)
    s = int(rng.integers(1, 11))
    grid = AccumulatorGrid(["a"], spec, supersample=s)
    origin = (float(rng.uniform(-2, spec.x_max + 1)), float(rng.uniform(-0.5, spec.y_max + 1)))
    a0 = rng.uniform(-8, 8, size=4)
    a1 = a0 + rng.uniform(0, 2 * np.pi, size=4)
    max_range = float(rng.uniform(0.3, 6)) if seed % 2 else None
    got = grid.coverage(origin, np.stack([a0, a1], axis=1), max_range)
    for w in range(4):
        want = brute_force_coverage(spec, s, origin, a0[w], a1[w], max_range)
        np.testing.assert_allclose(got[w], want, atol=1e-12)


@pytest.mark.parametrize(
    ("origin", "a0_deg", "width_deg"),
    [((2.3, 1.7), 10.0, 30.0), ((0.2, 0.3), 20.0, 5.0), ((4.9, 5.6), 200.0, 45.0),
     ((-1.0, 2.5), -20.0, 40.0), ((2.5, 2.5), 170.0, 20.0)],
)  # fmt: skip
def test_wedge_coverage_equals_its_area_inside_the_grid(origin, a0_deg, width_deg):
    spec = GridSpec(0.0, 0.0, 5.0, 6.0, 0.5)
    s = 10
    grid = AccumulatorGrid(["a"], spec, supersample=s)
    a0, a1 = math.radians(a0_deg), math.radians(a0_deg + width_deg)
    covered_area = grid.coverage(origin, [[a0, a1]]).sum() * spec.cell_size**2
    exact = wedge_area_in_rect(spec, origin, a0, a1)
    # Supersampling misclassifies only sample points within a sub-cell of the two rays.
    sub = spec.cell_size / s
    ray_length = 2 * math.hypot(spec.x_max - spec.x_min, spec.y_max - spec.y_min)
    assert abs(covered_area - exact) <= ray_length * sub, (covered_area, exact)
    assert exact > 0.0


def test_mirror_symmetric_wedges_give_mirrored_coverage():
    spec = GridSpec(0.0, 0.0, 4.0, 3.0, 0.25)
    grid = AccumulatorGrid(["a"], spec)
    origin = (2.0, 0.37)  # on the vertical mirror line x = 2
    a0, a1 = math.radians(52.3), math.radians(71.9)
    right = grid.coverage(origin, [[a0, a1]])[0]
    left = grid.coverage(origin, [[math.pi - a1, math.pi - a0]])[0]
    np.testing.assert_allclose(left, right[:, ::-1], atol=1e-12)
    assert right.sum() > 1.0


def test_full_circle_covers_every_cell_once():
    spec = GridSpec(0.0, 0.0, 4.5, 6.0, 0.1)
    grid = AccumulatorGrid(["a"], spec)
    coverage = grid.coverage((1.234, 4.321), [[0.3, 0.3 + 2 * math.pi]])[0]
    np.testing.assert_allclose(coverage, 1.0)


def test_adjacent_wedges_partition_their_union():
    spec = GridSpec(0.0, 0.0, 5.0, 5.0, 0.5)
    grid = AccumulatorGrid(["a"], spec)
    edges = np.linspace(-0.4, 5.0, 17)
    parts = grid.coverage((1.1, 3.3), np.stack([edges[:-1], edges[1:]], axis=1))
    whole = grid.coverage((1.1, 3.3), [[edges[0], edges[-1]]])[0]
    np.testing.assert_allclose(parts.sum(axis=0), whole, atol=1e-12)
    assert parts.max() <= 1.0


def test_max_range_limits_the_wedge_to_a_disc():
    spec = GridSpec(0.0, 0.0, 6.0, 6.0, 0.1)
    grid = AccumulatorGrid(["a"], spec)
    coverage = grid.coverage((3.02, 2.97), [[0.0, 2 * math.pi]], max_range=1.5)[0]
    area = coverage.sum() * spec.cell_size**2
    assert area == pytest.approx(math.pi * 1.5**2, rel=5e-3)
    x, y = spec.cell_centers()
    assert np.all(coverage[np.hypot(x - 3.02, y - 2.97) > 1.5 + spec.cell_size] == 0.0)


def test_visibility_weighs_each_cell_by_its_wedges_profile_at_its_distance():
    """A wedge whose profile sees only its first metre adds nothing beyond it (and nothing to
    the observed count there), and a half-visible band adds half."""
    import numpy as np

    from twin.core.grid import AccumulatorGrid, GridSpec
    from twin.core.visibility import ColumnVisibility

    spec = GridSpec(0.0, 0.0, 4.0, 4.0, 0.1)
    wedge = np.array([[-0.2, 0.2]])  # looking along +x from (0.05, 2.05)
    origin = (0.05, 2.05)
    full = AccumulatorGrid(["a"], spec)
    full.fuse("a", origin, wedge, np.array([1.0]))
    seen = AccumulatorGrid(["a"], spec)
    profile = np.zeros((1, 40))  # 0.1 m bins up to 4 m
    profile[0, :10] = 1.0  # the first metre in view
    profile[0, 20:25] = 0.5  # half-visible at 2.0-2.5 m
    seen.fuse_all(origin, wedge, {"a": np.array([1.0])}, visibility=ColumnVisibility(profile, 0.1))
    xs, ys = spec.cell_centers()
    distance = np.hypot(xs - origin[0], ys - origin[1])
    near, band, far = distance < 0.95, (distance > 2.05) & (distance < 2.45), distance > 2.55
    np.testing.assert_allclose(seen.layer("a")[near], full.layer("a")[near])
    np.testing.assert_allclose(seen.layer("a")[band], 0.5 * full.layer("a")[band])
    assert seen.layer("a")[far].sum() == 0.0 and full.layer("a")[far].sum() > 1.0
    np.testing.assert_allclose(seen.observed("a")[far], 0.0)


def test_visibility_everywhere_changes_nothing():
    import numpy as np

    from twin.core.grid import AccumulatorGrid, GridSpec
    from twin.core.visibility import ColumnVisibility

    spec = GridSpec(0.0, 0.0, 3.0, 3.0, 0.1)
    wedges = np.array([[0.1, 0.4], [0.4, 0.7], [2.0, 2.6]])
    values = np.array([0.2, 0.9, 0.5])
    plain, seeing = AccumulatorGrid(["a"], spec), AccumulatorGrid(["a"], spec)
    plain.fuse("a", (1.0, 1.2), wedges, values)
    everywhere = ColumnVisibility.everywhere(3, reach=10.0)
    seeing.fuse_all((1.0, 1.2), wedges, {"a": values}, visibility=everywhere)
    np.testing.assert_allclose(seeing.layer("a"), plain.layer("a"), atol=1e-12)
