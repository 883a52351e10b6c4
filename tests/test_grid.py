"""The accumulator grid: fusion rules on hand-computed cases, peaks, files and bad input."""

import math

import numpy as np
import pytest

from twin.core.errors import FileFormatError, InputError
from twin.core.fusion import Accumulate, LogOdds, Normalized, logodds_weights, make_rule
from twin.core.grid import AccumulatorGrid, GridSpec, direction_bin, local_maxima
from twin.core.store import load_arrays, save_arrays

# Origin on the line x = 2: the bearings [-pi/2, pi/2) are exactly the cells right of it.
ORIGIN = (2.0, 1.93)
RIGHT = [-math.pi / 2, math.pi / 2]
LEFT = [math.pi / 2, 3 * math.pi / 2]


def small_grid(rule=None, **kwargs):
    return AccumulatorGrid(["box"], GridSpec(0.0, 0.0, 4.0, 4.0, 1.0), rule, **kwargs)


def test_accumulate_adds_value_times_coverage():
    grid = small_grid(Accumulate())
    grid.fuse("box", ORIGIN, [RIGHT, LEFT], [1.0, 0.2])
    grid.fuse("box", ORIGIN, [RIGHT], [0.5])
    layer = grid.layer("box")
    np.testing.assert_allclose(layer[:, 2:], 1.5)
    np.testing.assert_allclose(layer[:, :2], 0.2)
    np.testing.assert_allclose(grid.observed("box")[:, 2:], 2.0)
    assert grid.views("box") == 2


def test_accumulate_partial_coverage_is_proportional():
    grid = AccumulatorGrid(["box"], GridSpec(0.0, 0.0, 4.0, 4.0, 1.0), supersample=10)
    # A half-plane boundary through the middle of column 1 covers half of that column's cells.
    grid.fuse("box", (1.5, 1.93), [RIGHT], [0.8])
    np.testing.assert_allclose(grid.layer("box")[:, 1], 0.4)
    np.testing.assert_allclose(grid.layer("box")[:, 0], 0.0)


def test_cells_outside_every_wedge_keep_their_prior():
    prior = np.arange(16.0).reshape(4, 4)
    grid = small_grid(prior=prior)
    grid.fuse("box", ORIGIN, [RIGHT], [1.0])
    np.testing.assert_allclose(grid.layer("box")[:, :2], prior[:, :2])
    np.testing.assert_allclose(grid.layer("box")[:, 2:], prior[:, 2:] + 1.0)


def test_prior_as_function_of_position():
    grid = small_grid(prior=lambda x, y: 0.1 * x + y)
    x, y = grid.spec.cell_centers()
    np.testing.assert_allclose(grid.layer("box"), 0.1 * x + y)


def test_normalized_is_the_mean_value_of_the_views_that_saw_a_cell():
    grid = small_grid(Normalized(min_observed=1.0))
    grid.fuse("box", ORIGIN, [RIGHT], [1.0])
    grid.fuse("box", ORIGIN, [RIGHT], [0.0])
    grid.fuse("box", (1.5, 1.93), [RIGHT], [0.6])  # column 1 seen half, columns 2-3 fully
    layer = grid.layer("box")
    np.testing.assert_allclose(layer[:, 2:], (1.0 + 0.0 + 0.6) / 3)
    np.testing.assert_allclose(layer[:, 1], 0.0)  # seen 0.5 < min_observed: not trusted
    np.testing.assert_allclose(layer[:, 0], 0.0)
    lenient = small_grid(Normalized(min_observed=0.0))
    lenient.fuse("box", (1.5, 1.93), [RIGHT], [0.6])
    np.testing.assert_allclose(lenient.layer("box")[:, 1], 0.6)


def test_logodds_adds_positive_evidence_when_fired_and_negative_when_silent():
    rule = LogOdds(p_fp=0.2, p_fn=0.4, threshold=0.5)
    grid = small_grid(rule)
    grid.fuse("box", ORIGIN, [RIGHT, LEFT], [0.9, 0.1])
    layer = grid.layer("box")
    np.testing.assert_allclose(layer[:, 2:], math.log(0.6 / 0.2))
    np.testing.assert_allclose(layer[:, :2], math.log(0.4 / 0.8))


def test_logodds_weights_stay_finite_at_zero_and_one():
    for p_fp, p_fn in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)]:
        fired, silent = logodds_weights(p_fp, p_fn)
        assert math.isfinite(fired) and math.isfinite(silent)
    fired, silent = logodds_weights(0.0, 0.0)
    assert fired > 0 > silent


def test_fuse_all_equals_fusing_each_object_alone():
    spec = GridSpec(0.0, 0.0, 4.5, 6.0, 0.1)
    intervals = np.stack([np.linspace(0.2, 1.0, 9)[:-1], np.linspace(0.2, 1.0, 9)[1:]], axis=1)
    values = {"box": np.linspace(0, 1, 8), "cup": np.linspace(1, 0, 8)}
    together = AccumulatorGrid(["box", "cup"], spec)
    together.fuse_all((1.0, 1.5), intervals, values)
    for name in values:
        alone = AccumulatorGrid([name], spec)
        alone.fuse(name, (1.0, 1.5), intervals, values[name])
        np.testing.assert_allclose(together.layer(name), alone.layer(name))


def test_peaks_are_local_maxima_in_metres_with_their_ratio():
    spec = GridSpec(0.0, 0.0, 2.0, 1.0, 0.1)
    prior = np.zeros(spec.shape)
    prior[2, 3] = 5.0
    prior[2, 4] = 4.0  # a shoulder of the first peak, not a peak of its own
    prior[7, 15] = 2.0
    prior[8, 15] = 2.0  # a plateau counts once
    prior[5, 10] = 1.0
    grid = AccumulatorGrid(["box"], spec, prior=prior)
    peaks = grid.peaks("box", k=3)
    assert [(p.row, p.col) for p in peaks.peaks] == [(2, 3), (7, 15), (5, 10)]
    assert peaks.best.x == pytest.approx(0.35)
    assert peaks.best.y == pytest.approx(0.25)
    assert peaks.ratio == pytest.approx(2.5)


def test_peak_ratio_of_flat_and_single_peak_layers():
    grid = small_grid()
    assert math.isnan(grid.peaks("box").ratio)
    grid.fuse("box", ORIGIN, [[0.1, 0.2]], [1.0])
    assert grid.peaks("box").best.value > 0


def test_local_maxima_prefers_larger_values_then_raster_order():
    values = np.array([[1.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    assert local_maxima(values, 3) == [(2, 2), (0, 0), (0, 2)]


def test_save_and_load_round_trip(tmp_path):
    spec = GridSpec(-1.0, 0.0, 3.5, 6.0, 0.5)
    grid = AccumulatorGrid(["box", "cup"], spec, LogOdds(0.1, 0.3, 0.4), supersample=7)
    grid.fuse_all((0.3, 2.2), [[0.1, 0.5], [0.5, 0.9]], {"box": [1.0, 0.0], "cup": [0.2, 0.7]})
    path = grid.save(tmp_path / "grid.npz")
    loaded = AccumulatorGrid.load(path)
    assert loaded.objects == grid.objects and loaded.spec == grid.spec
    assert loaded.rule == grid.rule and loaded.supersample == 7
    for name in grid.objects:
        np.testing.assert_array_equal(loaded.layer(name), grid.layer(name))
        np.testing.assert_array_equal(loaded.observed(name), grid.observed(name))
        assert loaded.views(name) == 1
    assert not list(tmp_path.glob("*.tmp"))


def test_loading_a_corrupt_or_foreign_file_is_a_clear_error(tmp_path):
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 this is not a zip file")
    with pytest.raises(FileFormatError, match="not a readable"):
        AccumulatorGrid.load(corrupt)
    with pytest.raises(FileFormatError, match="no such file"):
        AccumulatorGrid.load(tmp_path / "missing.npz")
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, evidence=np.zeros(3))
    with pytest.raises(FileFormatError, match="no header"):
        AccumulatorGrid.load(foreign)


def test_loading_another_format_version_is_a_clear_error(tmp_path):
    path = save_arrays(tmp_path / "g.npz", "accumulator-grid", 99, {}, {"evidence": np.zeros(1)})
    with pytest.raises(FileFormatError, match="version 99 is not supported"):
        AccumulatorGrid.load(path)
    other = save_arrays(tmp_path / "m.npz", "rfch-model", 1, {}, {"x": np.zeros(1)})
    with pytest.raises(FileFormatError, match="not a 'accumulator-grid' file"):
        AccumulatorGrid.load(other)


@pytest.mark.parametrize(
    ("extent", "cell", "match"),
    [((0, 0, 4, 4), 0.0, "cell_size must be positive"),
     ((0, 0, 4, 4), -0.1, "cell_size must be positive"),
     ((0, 0, 0, 4), 0.1, "extent along x"),
     ((0, 5, 4, 4), 0.1, "extent along y"),
     ((0, 0, 4.55, 4), 0.1, "not a whole number"),
     ((0, 0, math.nan, 4), 0.1, "must be finite"),
     ((0, 0, 4, 4), math.inf, "must be finite")],
)  # fmt: skip
def test_bad_grid_geometry_is_named(extent, cell, match):
    with pytest.raises(InputError, match=match):
        GridSpec(*extent, cell)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"origin": (math.nan, 1.0)}, "origin must be finite"),
     ({"origin": (1.0, math.inf)}, "origin must be finite"),
     ({"origin": "here"}, "origin must be"),
     ({"intervals": [[0.0, 7.0]]}, "wider than 2 pi"),
     ({"intervals": [[1.0, 0.5]]}, "a0 <= a1"),
     ({"intervals": [[0.0, math.nan]]}, "finite"),
     ({"intervals": [0.0, 1.0]}, r"\(n, 2\)"),
     ({"values": [1.5]}, r"in \[0, 1\]"),
     ({"values": [-0.1]}, r"in \[0, 1\]"),
     ({"values": [math.nan]}, r"in \[0, 1\]"),
     ({"values": [0.1, 0.2]}, "one per interval"),
     ({"max_range": 0.0}, "max_range"),
     ({"max_range": -1.0}, "max_range"),
     ({"name": "cup"}, "unknown object 'cup'")],
)  # fmt: skip
def test_bad_fuse_input_is_named(kwargs, match):
    call = {"name": "box", "origin": (1.0, 1.0), "intervals": [[0.0, 0.5]], "values": [0.5]}
    call.update(kwargs)
    grid = small_grid()
    with pytest.raises(InputError, match=match):
        grid.fuse(**call)
    np.testing.assert_array_equal(grid.layer("box"), 0.0)  # nothing was half-applied


def test_bad_grid_construction_is_named():
    spec = GridSpec(0.0, 0.0, 1.0, 1.0, 0.5)
    with pytest.raises(InputError, match="at least one object"):
        AccumulatorGrid([], spec)
    with pytest.raises(InputError, match="distinct"):
        AccumulatorGrid(["a", "a"], spec)
    with pytest.raises(InputError, match="supersample"):
        AccumulatorGrid(["a"], spec, supersample=0)
    with pytest.raises(InputError, match="prior for 'a'"):
        AccumulatorGrid(["a"], spec, prior=np.zeros((3, 3)))
    with pytest.raises(InputError, match="prior for 'a' must be finite"):
        AccumulatorGrid(["a"], spec, prior=math.nan)
    with pytest.raises(InputError, match="unknown fusion rule"):
        make_rule("bayes")
    with pytest.raises(InputError, match="p_fp must be in"):
        LogOdds(p_fp=1.5)


# -- viewpoint-bias correction by direction bins ---------------------------------------------

# Half-planes that cover the whole 4 x 4 m grid from a camera outside it, to the west or east.
FROM_WEST = ((-1.0, 1.93), [RIGHT])
FROM_EAST = ((5.0, 1.93), [LEFT])


def scripted_views(grid):
    """Three views of two objects, one limited in range: the case ``OLD_SUMS`` was made from."""
    grid.fuse_all(
        (-0.37, 0.81),
        [[-0.9, -0.2], [-0.2, 0.35], [0.35, 1.1]],
        {"box": [0.9, 0.3, 0.05], "cup": [0.1, 0.6, 1.0]},
    )
    grid.fuse_all((3.42, 1.66), [[2.6, 3.3], [3.3, 4.0]], {"box": [0.7, 0.2]}, max_range=2.5)
    grid.fuse_all((1.21, -0.44), [[0.4, 1.9], [1.9, 2.8]], {"box": [0.45, 0.8], "cup": [0.33, 0.0]})


def scripted_grid(**kwargs):
    spec = GridSpec(0.0, 0.0, 3.0, 2.0, 1.0)
    return AccumulatorGrid(["box", "cup"], spec, Accumulate(), 7, {"box": 0.25}, **kwargs)


# The sums of ``scripted_views`` on ``scripted_grid()`` as the grid computed them before it had
# direction bins (twin/core/grid.py of commit ba73ae1), printed with repr: exact.
OLD_SUMS = {
    ("box", "evidence"): [1.6387755102040815, 1.4122448979591835, 1.1653061224489796,
                          1.019387755102041, 1.3989795918367345, 1.4051020408163264],
    ("box", "observed"): [1.9387755102040813, 2.775510204081632, 2.3061224489795915,
                          2.020408163265306, 2.9999999999999996, 2.979591836734693],
    ("cup", "evidence"): [0.3112244897959183, 0.7157142857142856, 0.7773469387755101,
                          1.050204081632653, 1.1340816326530612, 0.9871428571428571],
    ("cup", "observed"): [1.9387755102040813, 1.9999999999999998, 1.877551020408163,
                          1.9591836734693875, 1.9999999999999998, 1.9999999999999998],
}  # fmt: skip


def test_one_direction_bin_is_the_grid_as_it_was():
    grid = scripted_grid()
    scripted_views(grid)
    assert grid.direction_bins == 1
    for (name, kind), sums in OLD_SUMS.items():
        expected = np.array(sums).reshape(2, 3)
        np.testing.assert_array_equal(getattr(grid, kind)(name), expected)
        np.testing.assert_array_equal(getattr(grid, f"{kind}_by_direction")(name), [expected])
    for name in grid.objects:
        np.testing.assert_array_equal(grid.layer(name), grid.evidence(name))


def test_a_version_1_file_loads_as_one_direction_bin(tmp_path):
    # A file exactly as twin wrote it before direction bins existed.
    header = {
        "extent": [0.0, 0.0, 3.0, 2.0],
        "cell_size": 1.0,
        "supersample": 7,
        "objects": ["box", "cup"],
        "rule": {"name": "accumulate"},
    }
    arrays = {
        "evidence": np.array([OLD_SUMS["box", "evidence"], OLD_SUMS["cup", "evidence"]]),
        "observed": np.array([OLD_SUMS["box", "observed"], OLD_SUMS["cup", "observed"]]),
        "views": np.array([3, 2]),
    }
    arrays = {k: v.reshape(-1, 2, 3) if v.ndim == 2 else v for k, v in arrays.items()}
    path = save_arrays(tmp_path / "old.npz", "accumulator-grid", 1, header, arrays)
    grid = AccumulatorGrid.load(path)
    assert grid.direction_bins == 1 and grid.supersample == 7
    assert (grid.views("box"), grid.views("cup")) == (3, 2)
    for (name, kind), sums in OLD_SUMS.items():
        np.testing.assert_array_equal(getattr(grid, kind)(name), np.reshape(sums, (2, 3)))
    # ... and a grid of one bin is still written in that version, with the same arrays.
    resaved = grid.save(tmp_path / "resaved.npz")
    header_again, arrays_again = load_arrays(resaved, "accumulator-grid", 1)
    assert header_again == {"format": "accumulator-grid", "version": 1, **header}
    assert arrays_again.keys() == arrays.keys()
    for key, array in arrays.items():
        np.testing.assert_array_equal(arrays_again[key], array)


def test_views_from_one_direction_count_once_and_from_opposite_directions_add():
    once, thrice, both, plain = (small_grid(direction_bins=b) for b in (2, 2, 2, 1))
    once.fuse("box", *FROM_WEST, [0.6])
    for grid in (thrice, plain):
        for _ in range(3):
            grid.fuse("box", *FROM_WEST, [0.6])
    both.fuse("box", *FROM_WEST, [0.6])
    both.fuse("box", *FROM_EAST, [0.6])
    np.testing.assert_allclose(plain.layer("box"), 1.8)  # the paper's sum: seen often, gains
    np.testing.assert_allclose(once.layer("box"), 0.6)
    np.testing.assert_allclose(thrice.layer("box"), 0.6)
    np.testing.assert_allclose(thrice.observed("box"), 1.0)
    np.testing.assert_allclose(thrice.observed_by_direction("box").sum(axis=0), 3.0)
    np.testing.assert_allclose(both.layer("box"), 1.2)  # two directions: triangulation
    np.testing.assert_allclose(both.observed("box"), 2.0)
    assert thrice.views("box") == 3


def test_normalized_with_bins_is_the_mean_over_directions():
    plain, binned = small_grid(Normalized()), small_grid(Normalized(), direction_bins=2)
    for grid in (plain, binned):
        for _ in range(3):
            grid.fuse("box", *FROM_WEST, [1.0])
        grid.fuse("box", *FROM_EAST, [0.0])
    np.testing.assert_allclose(plain.layer("box"), 0.75)  # the views' mean
    np.testing.assert_allclose(binned.layer("box"), 0.5)  # the directions' mean


def test_logodds_with_bins_sums_the_mean_log_odds_of_each_direction():
    rule = LogOdds(p_fp=0.2, p_fn=0.4, threshold=0.5)
    grid = small_grid(rule, direction_bins=2)
    grid.fuse("box", *FROM_WEST, [0.9])
    grid.fuse("box", *FROM_WEST, [0.1])
    grid.fuse("box", *FROM_EAST, [0.9])
    fired, silent = logodds_weights(0.2, 0.4)
    np.testing.assert_allclose(grid.layer("box"), (fired + silent) / 2 + fired)


def test_partial_coverage_keeps_its_weight_until_a_direction_is_seen_in_full():
    grid = small_grid(direction_bins=4)
    # Column 1 is half covered; its cells see the camera due north or south of their centres.
    grid.fuse("box", (1.5, 1.93), [RIGHT], [0.8])
    np.testing.assert_allclose(grid.layer("box")[:, 1], 0.4)
    np.testing.assert_allclose(grid.observed("box")[:, 1], 0.5)
    for _ in range(2):
        grid.fuse("box", (1.5, 1.93), [RIGHT], [0.8])  # 1.5 views' worth from one direction
    np.testing.assert_allclose(grid.layer("box")[:, 1], 0.8)
    np.testing.assert_allclose(grid.observed("box")[:, 1], 1.0)
    np.testing.assert_allclose(grid.layer("box")[:, 0], 0.0)


def test_a_cell_files_a_view_under_the_direction_from_the_cell_to_the_camera():
    east, north, west, south = range(4)
    from_east = small_grid(direction_bins=4)
    # Far enough east that every cell sees the camera within 45 degrees of east.
    from_east.fuse("box", (9.0, 1.93), [LEFT], [1.0])
    by_direction = from_east.observed_by_direction("box")
    np.testing.assert_allclose(by_direction[east], 1.0)
    np.testing.assert_allclose(by_direction[[north, west, south]], 0.0)
    # One full-circle view from inside the grid sees each cell from its own direction.
    inside = small_grid(direction_bins=4)
    inside.fuse("box", (2.0, 1.93), [[0.0, 2 * math.pi]], [1.0])
    seen_from = inside.observed_by_direction("box").argmax(axis=0)
    assert seen_from[1, 0] == east  # cell centre (0.5, 1.5): the camera is east of it
    assert seen_from[1, 3] == west  # (3.5, 1.5)
    assert seen_from[3, 1] == south  # (1.5, 3.5)
    assert seen_from[0, 2] == north  # (2.5, 0.5)
    np.testing.assert_allclose(inside.observed_by_direction("box").sum(axis=0), 1.0)


def test_direction_bins_are_centred_on_the_compass_directions():
    dx = np.array([1.0, 0.0, -1.0, 0.0, 1.0, 1.0, 0.0])
    dy = np.array([0.0, 1.0, 0.0, -1.0, 0.99, -0.99, 0.0])
    np.testing.assert_array_equal(direction_bin(dx, dy, 4), [0, 1, 2, 3, 0, 0, 0])
    np.testing.assert_array_equal(direction_bin(dx, dy, 1), 0)


def test_the_prior_is_added_once_not_averaged_with_the_views():
    grid = small_grid(direction_bins=8, prior=2.0)
    for _ in range(4):
        grid.fuse("box", *FROM_WEST, [0.5])
    np.testing.assert_allclose(grid.layer("box"), 2.5)
    np.testing.assert_allclose(grid.evidence_by_direction("box").sum(axis=0), 2.0)


def test_fuse_all_with_bins_equals_fusing_each_object_alone():
    spec = GridSpec(0.0, 0.0, 4.5, 6.0, 0.1)
    edges = np.linspace(0.2, 1.0, 9)
    intervals = np.stack([edges[:-1], edges[1:]], axis=1)
    values = {"box": np.linspace(0, 1, 8), "cup": np.linspace(1, 0, 8)}
    together = AccumulatorGrid(["box", "cup"], spec, direction_bins=8)
    for origin in [(1.0, 1.5), (0.2, 0.3), (1.0, 1.5)]:
        together.fuse_all(origin, intervals, values)
    for name in values:
        alone = AccumulatorGrid([name], spec, direction_bins=8)
        for origin in [(1.0, 1.5), (0.2, 0.3), (1.0, 1.5)]:
            alone.fuse(name, origin, intervals, values[name])
        np.testing.assert_array_equal(together.layer(name), alone.layer(name))
        np.testing.assert_array_equal(
            together.evidence_by_direction(name), alone.evidence_by_direction(name)
        )


def test_save_and_load_round_trip_with_direction_bins(tmp_path):
    grid = scripted_grid(direction_bins=8)
    scripted_views(grid)
    path = grid.save(tmp_path / "grid.npz")
    header, _ = load_arrays(path, "accumulator-grid", 2)
    assert header["direction_bins"] == 8
    loaded = AccumulatorGrid.load(path)
    assert loaded.direction_bins == 8 and loaded.spec == grid.spec and loaded.rule == grid.rule
    for name in grid.objects:
        for kind in ("layer", "evidence", "observed", "evidence_by_direction"):
            np.testing.assert_array_equal(getattr(loaded, kind)(name), getattr(grid, kind)(name))
        np.testing.assert_array_equal(
            loaded.observed_by_direction(name), grid.observed_by_direction(name)
        )
        assert loaded.views(name) == grid.views(name)
    # A loaded grid keeps fusing as the original does.
    grid.fuse("box", (1.5, 1.0), [[0.0, 2 * math.pi]], [0.5])
    loaded.fuse("box", (1.5, 1.0), [[0.0, 2 * math.pi]], [0.5])
    np.testing.assert_array_equal(loaded.layer("box"), grid.layer("box"))


def test_a_version_2_file_of_one_bin_adds_its_prior_to_the_evidence(tmp_path):
    header = {
        "extent": [0.0, 0.0, 3.0, 2.0],
        "cell_size": 1.0,
        "supersample": 7,
        "objects": ["box"],
        "rule": {"name": "normalized", "min_observed": 0.0},
        "direction_bins": 1,
    }
    arrays = {
        "evidence": np.full((1, 1, 2, 3), 0.5),
        "observed": np.full((1, 1, 2, 3), 2.0),
        "prior": np.full((1, 2, 3), 0.25),
        "views": np.array([2]),
    }
    path = save_arrays(tmp_path / "one.npz", "accumulator-grid", 2, header, arrays)
    grid = AccumulatorGrid.load(path)
    assert grid.direction_bins == 1
    np.testing.assert_allclose(grid.evidence("box"), 0.75)
    np.testing.assert_allclose(grid.layer("box"), 0.375)


def _binned_file(tmp_path, **changes):
    grid = scripted_grid(direction_bins=4)
    scripted_views(grid)
    header, arrays = load_arrays(grid.save(tmp_path / "good.npz"), "accumulator-grid", 2)
    for key in ("format", "version"):
        header.pop(key)
    for key, value in changes.items():
        (header if key == "direction_bins" else arrays)[key] = value
    return save_arrays(tmp_path / "bad.npz", "accumulator-grid", 2, header, arrays)


@pytest.mark.parametrize(
    ("changes", "match"),
    [({"direction_bins": 8}, "not of shape"),
     ({"direction_bins": 0}, "direction_bins must be"),
     ({"direction_bins": "4"}, "direction_bins must be"),
     ({"prior": np.zeros((2, 3))}, "prior is not of shape"),
     ({"observed": -np.ones((2, 4, 2, 3))}, "non-negative"),
     ({"evidence": np.full((2, 4, 2, 3), np.nan)}, "not finite"),
     ({"views": np.zeros(2)}, "view counts")],
)  # fmt: skip
def test_an_inconsistent_binned_file_is_a_one_line_error(tmp_path, changes, match):
    path = _binned_file(tmp_path, **changes)
    with pytest.raises(FileFormatError, match=match) as caught:
        AccumulatorGrid.load(path)
    assert "\n" not in str(caught.value)


def test_a_binned_file_missing_its_bin_count_is_a_clear_error(tmp_path):
    path = _binned_file(tmp_path)
    header, arrays = load_arrays(path, "accumulator-grid", 2)
    del header["direction_bins"], header["format"], header["version"]
    broken = save_arrays(tmp_path / "nobins.npz", "accumulator-grid", 2, header, arrays)
    with pytest.raises(FileFormatError, match=r"inconsistent.*'direction_bins'"):
        AccumulatorGrid.load(broken)


@pytest.mark.parametrize("bins", [0, -1, 65, 2.0, 2.5, "8", None, True])
def test_bad_direction_bins_is_a_one_line_error(bins):
    with pytest.raises(
        InputError, match="direction_bins must be an integer from 1 to 64"
    ) as caught:
        small_grid(direction_bins=bins)
    assert "\n" not in str(caught.value)


def test_each_object_may_have_its_own_rule_parameters(tmp_path) -> None:
    # Two calibrated detectors: the same column value is strong evidence for one, weak for
    # the other; each layer must get its own model's log-likelihood ratio.
    edges = (0.0, 0.5, 1.0)
    rules = {
        "box": make_rule("calibrated", edges=edges, llr=(-1.0, 2.0)),
        "cup": make_rule("calibrated", edges=edges, llr=(-0.5, 0.5)),
    }
    spec = GridSpec(0.0, 0.0, 2.0, 2.0, 0.1)
    grid = AccumulatorGrid(["box", "cup"], spec, rules, 4)
    wedges = np.array([[-0.1, 0.1]])
    grid.fuse_all((0.05, 1.0), wedges, {"box": np.array([0.8]), "cup": np.array([0.8])})
    row, col = 10, 10  # on the wedge's axis
    seen = grid.observed("box")[row, col]
    assert seen > 0
    assert grid.layer("box")[row, col] == pytest.approx(2.0 * seen)
    assert grid.layer("cup")[row, col] == pytest.approx(0.5 * seen)
    grid.save(tmp_path / "g.npz")
    loaded = AccumulatorGrid.load(tmp_path / "g.npz")
    assert loaded.rules == grid.rules
    np.testing.assert_array_equal(loaded.layer("cup"), grid.layer("cup"))


def test_rules_per_object_must_cover_every_object_and_be_of_one_kind() -> None:
    spec = GridSpec(0.0, 0.0, 1.0, 1.0, 0.1)
    with pytest.raises(InputError, match="one fusion rule per object"):
        AccumulatorGrid(["box", "cup"], spec, {"box": Accumulate()})
    with pytest.raises(InputError, match="one kind"):
        AccumulatorGrid(["box", "cup"], spec, {"box": Accumulate(), "cup": Normalized()})


def test_a_room_baseline_is_taken_off_each_view_in_proportion_to_what_it_saw(tmp_path):
    from twin.core.visibility import ColumnVisibility

    spec = GridSpec(0.0, 0.0, 2.0, 2.0, 0.1)
    wedge = np.array([[-0.1, 0.1]])
    seen = ColumnVisibility(np.array([[1.0] * 20 + [0.5] * 20]), 0.05)  # half seen beyond 1 m
    baseline = np.full(spec.shape, 0.2)
    plain = AccumulatorGrid(["box"], spec, Accumulate(), 4)
    based = AccumulatorGrid(["box"], spec, Accumulate(), 4, baseline={"box": baseline})
    for grid in (plain, based):
        for _ in range(3):
            grid.fuse_all((0.05, 1.0), wedge, {"box": np.array([0.5])}, None, seen)
    # Each view's gain is its match less the room's usual, both in proportion to the share seen.
    np.testing.assert_allclose(based.layer("box"), plain.layer("box") * (0.5 - 0.2) / 0.5)
    assert set(based.baselines) == {"box"} and plain.baselines == {}
    based.save(tmp_path / "g.npz")
    loaded = AccumulatorGrid.load(tmp_path / "g.npz")
    np.testing.assert_array_equal(loaded.baselines["box"], baseline)
    loaded.fuse_all((0.05, 1.0), wedge, {"box": np.array([0.5])}, None, seen)
    based.fuse_all((0.05, 1.0), wedge, {"box": np.array([0.5])}, None, seen)
    np.testing.assert_array_equal(loaded.layer("box"), based.layer("box"))
    with pytest.raises(InputError, match="baseline of 'box' must be finite values >= 0"):
        AccumulatorGrid(["box"], spec, baseline={"box": -baseline})
