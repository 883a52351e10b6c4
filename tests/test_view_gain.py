"""What a prospective view is worth (twin.core.view_gain): the formulas' invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.core.errors import InputError
from twin.core.view_gain import (
    Footprints,
    detection_probability,
    information_gain,
    unseen_coverage,
)


def entropy(p: float) -> float:
    return 0.0 if p in (0.0, 1.0) else -p * math.log(p) - (1 - p) * math.log(1 - p)


def one_column(cells: list[int], n_cells: int = 9, lift: float = 1.0) -> Footprints:
    dense = np.zeros((1, n_cells))
    dense[0, cells] = 1.0
    return Footprints.from_dense([dense.reshape(1, 3, 3)], [lift * dense.reshape(1, 3, 3)])


def test_a_perfect_column_tells_whether_the_object_is_in_its_wedge():
    """Perfect detector (no false positives, lift 1): the information is the entropy of "in the
    wedge or not", h(mass in the wedge)."""
    prints = one_column([0, 1, 2])
    uniform = np.full(9, 1 / 9)
    assert information_gain(prints, uniform, 0.0)[0] == pytest.approx(entropy(1 / 3))
    half = np.zeros(9)
    half[[0, 5]] = 0.5
    assert information_gain(prints, half, 0.0)[0] == pytest.approx(math.log(2))


def test_nothing_is_learnt_where_the_answer_is_known_or_out_of_view():
    prints = one_column([0, 1, 2])
    outside = np.zeros(9)
    outside[8] = 1.0
    inside = np.zeros(9)
    inside[1] = 1.0
    for cells in (outside, inside):
        assert information_gain(prints, cells, 0.1)[0] == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 1.0), min_size=9, max_size=9),
    st.floats(0.0, 0.4),
    st.floats(0.05, 1.0),
    st.floats(0.0, 0.3),
)
def test_information_is_bounded_and_grows_with_the_lift(weights, fpr, lift, absent):
    mass = np.asarray(weights) + 1e-3
    cells = (1.0 - absent) * mass / mass.sum()
    strong = information_gain(one_column([0, 4, 5], lift=lift), cells, fpr)[0]
    weak = information_gain(one_column([0, 4, 5], lift=lift / 2), cells, fpr)[0]
    assert 0.0 <= weak <= strong + 1e-12
    assert strong <= math.log(2) + 1e-12  # one binary answer tells at most one bit


def test_detection_probability_is_the_mass_seen_times_the_lift():
    prints = one_column([0, 1, 2], lift=0.6)
    cells = np.zeros(9)
    cells[[1, 7]] = 0.5
    assert detection_probability(prints, cells, 0.6)[0] == pytest.approx(0.5)
    assert detection_probability(prints, cells, 1.0)[0] == pytest.approx(0.3)


def test_coverage_prefers_cells_seen_least():
    dense = np.zeros((2, 1, 3, 3))
    dense[0, 0, 0, :] = 1.0  # view 0 sees the top row
    dense[1, 0, 2, :] = 1.0  # view 1 the bottom row
    prints = Footprints.from_dense(list(dense))
    observed = np.zeros((3, 3))
    observed[0, :] = 2.0  # the top row was seen twice already
    gains = unseen_coverage(prints, observed)
    assert gains[1] == pytest.approx(3.0) and gains[0] == pytest.approx(3 * math.exp(-2))


def test_columns_of_a_view_add_up_and_views_stay_apart():
    dense = np.zeros((2, 2, 3, 3))
    dense[0, 0, 0, 0] = dense[0, 1, 1, 1] = 1.0
    dense[1, 0, 2, 2] = 1.0
    prints = Footprints.from_dense(list(dense))
    assert prints.n_views == 2 and prints.rows == 4  # an empty column is a row too
    cells = np.full(9, 1 / 9)
    gains = information_gain(prints, cells, 0.0)
    assert gains[0] == pytest.approx(2 * entropy(1 / 9)) and gains[1] == pytest.approx(
        entropy(1 / 9)
    )


def test_bad_footprints_and_posteriors_are_one_line_errors():
    prints = one_column([0])
    with pytest.raises(InputError, match="cells"):
        information_gain(prints, np.ones(4) / 4, 0.1)
    with pytest.raises(InputError, match="fpr"):
        information_gain(prints, np.ones(9) / 9, 1.0)
    with pytest.raises(InputError, match="NaN"):
        detection_probability(prints, np.full(9, np.nan), 1.0)
    with pytest.raises(InputError, match="indptr"):
        Footprints(np.array([0, 5]), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), 1, 9)
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        Footprints(np.array([0, 1]), np.zeros(1), np.array([2.0]), np.zeros(1), np.zeros(1), 1, 9)


def test_novelty_scales_what_a_view_can_still_tell():
    prints = one_column([0, 1, 2])
    cells = np.full(9, 1 / 9)
    fresh = information_gain(prints, cells, 0.05)[0]
    entries = len(prints.cells)
    assert information_gain(prints, cells, 0.05, np.ones(entries))[0] == pytest.approx(fresh)
    assert information_gain(prints, cells, 0.05, np.zeros(entries))[0] == pytest.approx(0.0)
    half = information_gain(prints, cells, 0.05, np.full(entries, 0.5))[0]
    assert 0.0 < half < fresh
    assert detection_probability(prints, cells, 1.0, np.full(entries, 0.5))[0] == pytest.approx(
        0.5 * detection_probability(prints, cells, 1.0)[0]
    )
    with pytest.raises(InputError, match="novelty"):
        information_gain(prints, cells, 0.05, np.ones(entries + 1))


def test_a_views_entries_are_its_rows_cells():
    dense = np.zeros((3, 2, 3, 3))
    dense[0, 0, 0, 0] = dense[1, 1, 1, :] = dense[2, 0, 2, 2] = 1.0
    prints = Footprints.from_dense(list(dense))
    assert [prints.cells[prints.entries_of(v)].tolist() for v in range(3)] == [[0], [3, 4, 5], [8]]
