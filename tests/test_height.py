"""An object's height from its best patch rows (twin.core.height) and the view log that keeps
them."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from twin.app.mission import estimates, locate
from twin.app.view_log import LoggedView, ViewLog, fuse_view
from twin.core.errors import InputError
from twin.core.fusion import make_rule
from twin.core.geometry import CameraModel
from twin.core.grid import AccumulatorGrid, GridSpec
from twin.core.height import (
    HeightCheck,
    HeightEstimate,
    best_patch_elevations,
    estimate_height,
    height_fits,
    weighted_median,
)
from twin.core.visibility import ColumnVisibility, SupportLevels
from twin.rfch.params import PatchGrid

CAMERA = CameraModel()  # 320 x 240, 45 degrees


def project(camera: CameraModel, point: np.ndarray, height: float, tilt: float):
    """Pixel (u, v) of a point (ahead, left, z) in metres for a camera ``height`` up, tilted by
    ``tilt``: written independently of the module, as a rotation of the point into the camera."""
    ahead, left, z = point
    rise = z - height
    c, s = math.cos(tilt), math.sin(tilt)
    forward, up = ahead * c + rise * s, -ahead * s + rise * c
    f = camera.focal_px
    return camera.width / 2 - f * left / forward, camera.height / 2 - f * up / forward


@pytest.mark.parametrize("tilt_deg", [0.0, -20.0, 15.0])
def test_the_ray_through_a_pixel_rises_to_the_point_it_shows(tilt_deg):
    tilt = math.radians(tilt_deg)
    rng = np.random.default_rng(1)
    for _ in range(50):
        point = np.array([rng.uniform(1.0, 5.0), rng.uniform(-1.0, 1.0), rng.uniform(0.0, 2.0)])
        u, v = project(CAMERA, point, 1.0, tilt)
        if not (0 <= u < CAMERA.width and 0 <= v < CAMERA.height):
            continue
        elevation = CAMERA.pixel_rays(np.array(u), np.array(v), tilt)[1]
        expected = math.atan2(point[2] - 1.0, math.hypot(point[0], point[1]))
        assert float(elevation) == pytest.approx(expected, abs=1e-9)


def test_the_image_centre_looks_along_the_tilt():
    for tilt in (-0.4, 0.0, 0.3):
        _, elevation = CAMERA.pixel_rays(np.array(160.0), np.array(120.0), tilt)
        assert float(elevation) == pytest.approx(tilt)


def test_a_bump_over_two_rows_has_its_centre_between_them():
    boxes = PatchGrid().boxes((240, 320, 3))
    rows, cols = boxes.shape[:2]
    scores = np.full((1, rows, cols), 0.1)
    scores[0, 5, 3] = scores[0, 6, 3] = 0.8  # an object between rows 5 and 6 of column 3
    scores[0, 9, 7] = 0.9  # and one wholly in row 9 of column 7
    elevations = best_patch_elevations(scores, boxes, CAMERA, 0.0)
    v_between = 0.5 * (boxes[5, 3, 1] + boxes[6, 3, 3])
    u3 = 0.5 * (boxes[0, 3, 0] + boxes[0, 3, 2])
    u7 = 0.5 * (boxes[0, 7, 0] + boxes[0, 7, 2])
    v9 = 0.5 * (boxes[9, 7, 1] + boxes[9, 7, 3])
    assert elevations[0, 3] == pytest.approx(CAMERA.pixel_rays(u3, v_between)[1])
    assert elevations[0, 7] == pytest.approx(CAMERA.pixel_rays(u7, v9)[1])


def test_scores_that_do_not_fit_the_patch_grid_are_refused():
    boxes = PatchGrid().boxes((240, 320, 3))
    with pytest.raises(InputError, match="patch grid"):
        best_patch_elevations(np.zeros((1, 3, 3)), boxes, CAMERA, 0.0)


def test_weighted_median_follows_the_weights():
    values = np.array([0.0, 1.0, 10.0])
    assert weighted_median(values, np.array([1.0, 1.0, 1.0])) == 1.0
    assert weighted_median(values, np.array([1.0, 1.0, 5.0])) == 10.0


def views_of(target, z, rng, n=12, noise=0.01, liars=3):
    """n views looking at an object at ``target`` standing ``z`` high: each view's column toward
    it stands out and its elevation is the truth plus noise; ``liars`` views see nothing there
    (a plain column) and give random elevations."""
    origins, wedges, values, elevations = [], [], [], []
    for i in range(n):
        angle = 2 * math.pi * i / n
        distance = rng.uniform(1.5, 4.0)
        origin = (target[0] + distance * math.cos(angle), target[1] + distance * math.sin(angle))
        axis = angle + math.pi  # looking at the target
        edges = axis + np.linspace(0.4, -0.4, 9)
        wedge = np.stack([edges[1:], edges[:-1]], axis=1)
        value = np.full(8, 0.2)
        elevation = rng.uniform(-0.3, 0.3, 8)
        if i >= liars:
            value[3] = value[4] = 0.9
            truth = math.atan2(z - 1.0, distance) + rng.normal(0, noise)
            elevation[3] = elevation[4] = truth
        origins.append(origin)
        wedges.append(wedge)
        values.append(value)
        elevations.append(elevation)
    return np.array(origins), np.array(wedges), np.array(values), np.array(elevations)


def test_the_height_is_the_one_the_views_that_see_the_object_agree_on():
    rng = np.random.default_rng(7)
    target, z = (2.0, 3.0), 0.62
    origins, wedges, values, elevations = views_of(target, z, rng)
    found = estimate_height(target, origins, wedges, values, elevations, np.ones(len(origins)))
    assert found is not None
    assert found.z == pytest.approx(z, abs=0.03)
    assert found.views == len(origins) - 3  # plain columns do not vote
    assert found.spread < 0.05


def test_views_out_of_range_or_looking_away_do_not_vote():
    rng = np.random.default_rng(8)
    target = (2.0, 3.0)
    origins, wedges, values, elevations = views_of(target, 0.5, rng, liars=0)
    heights = np.ones(len(origins))
    none = estimate_height(target, origins, wedges, values, elevations, heights, max_range=1.0)
    assert none is None
    away = estimate_height((40.0, 40.0), origins, wedges, values, elevations, heights)
    assert away is None


def test_a_view_the_visibility_says_could_not_see_there_does_not_vote():
    rng = np.random.default_rng(9)
    target, z = (2.0, 3.0), 1.4
    origins, wedges, values, elevations = views_of(target, z, rng, liars=0)
    elevations[:6] = -0.5  # these six claim the floor ...
    profiles = [np.ones((8, 100)) for _ in range(len(origins))]
    for i in range(6):
        profiles[i][:] = 0.0  # ... but could not have seen an object there
    steps = np.full(len(origins), 0.05)
    heights = np.ones(len(origins))
    found = estimate_height(target, origins, wedges, values, elevations, heights, profiles, steps)
    assert found is not None and found.views == len(origins) - 6
    assert found.z == pytest.approx(z, abs=0.03)


def test_the_view_log_keeps_elevations_and_reads_logs_without_them(tmp_path):
    rng = np.random.default_rng(10)
    target, z = (2.0, 3.0), 0.9
    origins, wedges, values, elevations = views_of(target, z, rng)
    log = ViewLog(["box"], None)
    for i in range(len(origins)):
        log.append(
            LoggedView(
                tuple(origins[i]), wedges[i], {"box": values[i]}, None, True,
                {"box": elevations[i]}, 1.0,
            )
        )  # fmt: skip
    log.save(tmp_path / "views.npz")
    again = ViewLog.load(tmp_path / "views.npz")
    assert again.height("box", target) == log.height("box", target)
    assert log.height("box", target).z == pytest.approx(z, abs=0.03)
    old = ViewLog(["box"], None)
    for view in log.views:
        old.append(LoggedView(view.origin, view.wedges, view.values, None, True))
    old.save(tmp_path / "old.npz")
    assert ViewLog.load(tmp_path / "old.npz").height("box", target) is None


def test_a_height_fits_between_a_surface_and_an_object_height_above_it():
    levels = np.array([0.0, 0.45, np.nan])
    assert height_fits(0.1, levels, 0.2)  # on the floor
    assert height_fits(0.6, levels, 0.2)  # on the 0.45 m table
    assert not height_fits(1.3, levels, 0.2)  # in mid-air
    assert not height_fits(0.3, np.array([np.nan]), 0.2)  # nowhere to stand


def _log_of(*objects):
    """A view log of 12 views round each (target, z, strength)."""
    log = ViewLog(["box"], None)
    rng = np.random.default_rng(3)
    for target, z, strength in objects:
        origins, wedges, values, elevations = views_of(target, z, rng, liars=0)
        for i in range(len(origins)):
            log.append(
                LoggedView(
                    tuple(origins[i]), wedges[i], {"box": values[i] * strength}, None, True,
                    {"box": elevations[i]}, 1.0,
                )
            )  # fmt: skip
    return log


def test_a_peak_whose_height_fits_no_surface_there_is_passed_over():
    """Bearings crossing over bare floor put a look-alike 1.3 m up, where nothing could hold
    it: the estimate goes to the weaker peak on the table, and the result says why."""
    spec = GridSpec(0.0, 0.0, 9.0, 7.0, 0.1)
    log = _log_of(((2.0, 3.0), 1.3, 1.0), ((6.0, 3.0), 0.6, 0.8))
    grid = AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4)
    log.fuse_into(grid)
    levels = np.full((*spec.shape, 2), np.nan)
    levels[..., 0] = 0.0  # the floor everywhere
    levels[28:33, 58:63, 1] = 0.45  # a table round (6, 3)
    supports = SupportLevels(0.0, 0.0, 0.1, levels)
    plain = locate(grid, "box", 0.5, log)
    assert math.hypot(plain.peak.x - 2.0, plain.peak.y - 3.0) < 0.25  # the look-alike wins
    found = locate(grid, "box", 0.5, log, supports, object_height=0.3)
    assert math.hypot(found.peak.x - 6.0, found.peak.y - 3.0) < 0.25
    assert found.height is not None and found.height.z == pytest.approx(0.6, abs=0.05)
    [(passed, z)] = found.passed_over
    assert (passed.x, passed.y) == (plain.peak.x, plain.peak.y) and z == pytest.approx(1.3, 0.05)
    entry = estimates(grid, {"box": (6.0, 3.0, 0.6)}, 0.5, log, supports, 0.3)["box"]
    assert entry["error_m"] < 0.25 and entry["height_error_m"] < 0.05
    # it stands on the table: 0.15 m above it, and the rows' own answer is kept beside
    assert entry["stands_on_m"] == 0.45 and entry["estimate_m"][2] == pytest.approx(0.6)
    assert entry["height_measured_m"] == pytest.approx(0.6, abs=0.05)
    assert entry["passed_over"][0]["z_m"] == pytest.approx(1.3, abs=0.05)
    assert entry["peak_ratio"] is None or entry["peak_ratio"] >= 1.0


def test_the_height_check_keeps_the_band_where_the_row_shows_an_object_on_the_floor():
    """A column looking along +x whose best patch is a crate's centre, 0.12 m up, 3 m away:
    only the stretch of floor where that row's ray is between the floor and the crate's top
    (give or take the row's uncertainty) counts in full; a column without a row keeps all."""
    levels = np.full((40, 80, 1), 0.0)  # bare floor, 8 m x 4 m
    check = HeightCheck(SupportLevels(0.0, -2.0, 0.1, levels), object_height=0.25)
    wedges = np.array([[-0.02, 0.02], [-0.02, 0.02]])
    elevation = math.atan2(0.12 - 1.0, 3.0)
    weights = check.weights((0.0, 0.0), wedges, np.array([elevation, np.nan]), 1.0, 0.05, 140)
    distance = (np.arange(140) + 0.5) * 0.05
    full = distance[weights[0] == 1.0]
    # 1 - 0.293 d within [-0.1, 0.35] m, widened by 0.026 m per metre: 2.03 m to 4.12 m
    assert full.min() == pytest.approx(2.03, abs=0.05) and full.max() == pytest.approx(
        4.12, abs=0.05
    )
    assert set(np.unique(weights[0])) == {check.outside, 1.0}
    assert (weights[1] == 1.0).all()
    shaped = check.shape(
        ColumnVisibility(np.full((2, 140), 0.5), 0.05), (0.0, 0.0), wedges,
        np.array([elevation, np.nan]), 1.0,
    )  # fmt: skip
    np.testing.assert_allclose(shaped.profiles, 0.5 * weights)


def test_a_mission_with_the_height_check_replays_from_its_log():
    """``fuse_view`` (what the mission does) and ``ViewLog.fuse_into`` with the same check give
    the same grid, and the check takes the look-alike in mid-air off the floor."""
    spec = GridSpec(0.0, 0.0, 9.0, 7.0, 0.1)
    log = _log_of(((2.0, 3.0), 1.3, 1.0), ((6.0, 3.0), 0.6, 0.8))
    everywhere = ColumnVisibility.everywhere(8, 8.0)
    seen = ViewLog(["box"], None)
    for view in log.views:
        seen.append(replace(view, visibility=everywhere))
    levels = np.full((*spec.shape, 2), np.nan)
    levels[..., 0] = 0.0
    levels[28:33, 58:63, 1] = 0.45
    check = HeightCheck(SupportLevels(0.0, 0.0, 0.1, levels), 0.2)
    live = AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4)
    for view in seen.views:
        fuse_view(live, view, None, height_check=check)
    replayed = seen.fuse_into(AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4),
                              height_check=check)  # fmt: skip
    np.testing.assert_array_equal(live.layer("box"), replayed.layer("box"))
    plain = seen.fuse_into(AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4))
    mid_air, table = (30, 19), (30, 60)
    assert plain.layer("box")[mid_air] > plain.layer("box")[table]
    assert live.layer("box")[mid_air] < live.layer("box")[table]


def test_an_object_known_to_stand_on_the_floor_is_not_the_peak_on_a_table():
    """``SupportLevels.of_kinds``: a crate that lives on the floor (``stands_on``) passes over
    the stronger peak whose height fits only the table's top there."""
    spec = GridSpec(0.0, 0.0, 9.0, 7.0, 0.1)
    log = _log_of(((6.0, 3.0), 0.6, 1.0), ((2.0, 3.0), 0.12, 0.8))
    grid = AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4)
    log.fuse_into(grid)
    levels = np.full((*spec.shape, 2), np.nan)
    levels[..., 0] = 0.0
    levels[28:33, 58:63, 1] = 0.45  # a table round (6, 3)
    supports = SupportLevels(0.0, 0.0, 0.1, levels)
    anywhere = locate(grid, "box", 0.5, log, supports, object_height=0.2)
    assert math.hypot(anywhere.peak.x - 6.0, anywhere.peak.y - 3.0) < 0.25
    floor = supports.of_kinds(("floor",))
    assert np.isnan(floor.levels[30, 60, 1]) and floor.levels[30, 60, 0] == 0.0
    found = locate(grid, "box", 0.5, log, floor, object_height=0.2)
    assert math.hypot(found.peak.x - 2.0, found.peak.y - 3.0) < 0.25
    tables = supports.of_kinds(("table",))
    assert np.isnan(tables.levels[10, 10]).all() and tables.levels[30, 60, 1] == 0.45
    with pytest.raises(InputError, match="sofa"):
        supports.of_kinds(("sofa",))


def test_rows_biased_toward_the_surface_still_say_which_surface():
    """Rows that read a 0.3 m box on a 0.755 m desk 0.2 m low (the desk's wood matches it)
    put it on the desk, 0.15 m up; rows that fit no surface leave the height as measured;
    between two shelves the nearer standing centre wins."""
    measured = HeightEstimate(0.706, 4, 0.07)
    on_desk = measured.on_surface(np.array([0.0, 0.755, np.nan]), 0.3)
    assert on_desk.z == pytest.approx(0.905) and on_desk.surface == 0.755
    assert on_desk.measured == 0.706 and on_desk.views == 4
    assert measured.on_surface(np.array([0.0, 1.2]), 0.3) == measured  # mid-air: as it was
    shelves = np.array([[1.1, 1.45], [np.nan, 1.45]])
    # 1.37 m and 1.41 m fit both shelves (within 0.1 m of 1.1-1.32 and of 1.45-1.67)
    assert HeightEstimate(1.37, 3, 0.02).on_surface(shelves, 0.22).surface == 1.1
    assert HeightEstimate(1.41, 3, 0.02).on_surface(shelves, 0.22).surface == 1.45
    crate = HeightEstimate(0.26, 5, 0.01).on_surface(np.array([0.0]), 0.25)
    assert crate.z == pytest.approx(0.125) and crate.measured == 0.26


def test_without_a_model_of_the_room_the_rows_height_stands():
    """``SupportLevels.anywhere`` offers every height in 0.2 m steps: no surface to stand on,
    so ``locate`` keeps the rows' height (a stand-in's level would round it)."""
    spec = GridSpec(0.0, 0.0, 9.0, 7.0, 0.1)
    log = _log_of(((6.0, 3.0), 0.67, 1.0))
    grid = AccumulatorGrid(["box"], spec, make_rule("accumulate"), 4)
    log.fuse_into(grid)
    anywhere = SupportLevels.anywhere((0.0, 0.0, 9.0, 7.0))
    assert not anywhere.surfaces and not anywhere.of_kinds(("table",)).surfaces
    found = locate(grid, "box", 0.5, log, anywhere, object_height=0.3)
    assert found.height is not None and found.height.surface is None
    assert found.height.z == pytest.approx(0.67, abs=0.05)
