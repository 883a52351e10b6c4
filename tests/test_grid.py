"""The accumulator grid: fusion rules on hand-computed cases, peaks, files and bad input."""

import math

import numpy as np
import pytest

from twin.core.errors import FileFormatError, InputError
from twin.core.fusion import Accumulate, LogOdds, Normalized, logodds_weights, make_rule
from twin.core.grid import AccumulatorGrid, GridSpec, local_maxima

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
    from twin.core.store import save_arrays

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
