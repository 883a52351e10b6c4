"""Posterior over cells from calibrated log-odds: confidence, temperature, absence, reliability."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.core.confidence import (
    confidence_within,
    fit_temperature,
    posterior,
    reliability_table,
)
from twin.core.errors import InputError
from twin.core.grid import GridSpec

SPEC = GridSpec(0.0, 0.0, 2.0, 2.0, 0.1)  # 20 x 20 cells of 0.1 m


def test_bayes_by_hand_on_two_cells():
    # Cell 1 gathered log 4 of evidence, cell 0 none; prior absent 0.2, so 0.4 per cell.
    cells, absent = posterior(np.array([[0.0, math.log(4.0)]]), 1.0, 0.2)
    np.testing.assert_allclose(cells, [[0.4 / 2.2, 1.6 / 2.2]])
    assert absent == pytest.approx(0.2 / 2.2)


def test_a_peaked_layer_is_confident_a_flat_one_is_not():
    layer = np.zeros(SPEC.shape)
    layer[10, 5] = 40.0  # cell centre (0.55, 1.05)
    cells, absent = posterior(layer)
    assert confidence_within(cells, SPEC, (0.55, 1.05), 0.2) > 0.999
    assert absent == 0.0
    flat, _ = posterior(np.full(SPEC.shape, 3.0))
    xs, ys = SPEC.cell_centers()
    near = np.hypot(xs - 1.0, ys - 1.0) <= 0.2
    assert near.sum() > 4
    assert confidence_within(flat, SPEC, (1.0, 1.0), 0.2) == pytest.approx(near.sum() / near.size)
    # Centres may be given as an array too.
    centres = np.stack([xs, ys], axis=-1)
    assert confidence_within(flat, centres, (1.0, 1.0)) == confidence_within(flat, SPEC, (1, 1))


def test_temperature_flattens_monotonically_and_large_layers_do_not_overflow():
    rng = np.random.default_rng(0)
    layer = 30.0 * rng.standard_normal(SPEC.shape) + 900.0
    peaks, entropies = [], []
    for t in (0.5, 1.0, 2.0, 4.0, 16.0, 1e3):
        cells, absent = posterior(layer, t, 0.1)
        assert np.all(np.isfinite(cells)) and cells.sum() + absent == pytest.approx(1.0)
        peaks.append(cells.max())
        entropies.append(-np.sum(cells * np.log(np.maximum(cells, 1e-300))))
    assert np.all(np.diff(peaks) < 0) and np.all(np.diff(entropies) > 0)


def test_absence_rises_with_negative_evidence_and_falls_with_positive():
    prior = 0.3
    _, unchanged = posterior(np.zeros(SPEC.shape), 1.0, prior)
    assert unchanged == pytest.approx(prior)
    _, negative = posterior(np.full(SPEC.shape, -2.0), 1.0, prior)
    assert negative > 0.7
    _, cooler = posterior(np.full(SPEC.shape, -2.0), 4.0, prior)
    assert prior < cooler < negative  # tempered evidence moves it less
    peak = np.zeros(SPEC.shape)
    peak[3, 3] = 12.0
    _, positive = posterior(peak, 1.0, prior)
    assert positive < 0.05


def test_bad_inputs_are_one_line_errors():
    for call, match in (
        (lambda: posterior(np.zeros(SPEC.shape), 0.0), "temperature"),
        (lambda: posterior(np.zeros(SPEC.shape), 1.0, 1.0), "p_absent"),
        (lambda: posterior(np.zeros(5)), "2-D"),
        (lambda: confidence_within(np.zeros((3, 3)), SPEC, (0, 0)), "centres"),
        (lambda: reliability_table([0.5, 1.2], [True, False]), "probabilities"),
    ):
        with pytest.raises(InputError, match=match) as info:
            call()
        assert "\n" not in str(info.value)


def synthetic_runs(temperature: float, runs: int, seed: int):
    """Layers of a few blobs of evidence, and truths drawn from their posterior at
    ``temperature``: the model the fit assumes, with a known T."""
    rng = np.random.default_rng(seed)
    xs, ys = SPEC.cell_centers()
    centres = np.stack([xs, ys], axis=-1).reshape(-1, 2)
    layers, truths = [], []
    for _ in range(runs):
        layer = np.zeros(SPEC.shape)
        for _ in range(3):
            cx, cy = rng.uniform(0.0, 2.0, 2)
            height = rng.uniform(5.0, 40.0)
            layer += height * np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * 0.15**2))
        layer += rng.normal(0.0, 2.0, SPEC.shape)
        cells, _ = posterior(layer, temperature)
        truths.append(tuple(centres[rng.choice(cells.size, p=cells.ravel())]))
        layers.append(layer)
    return layers, truths


@pytest.mark.parametrize("objective", ["cell", "within"])
def test_fit_temperature_recovers_the_temperature_of_the_data(objective):
    true_t = 6.0
    layers, truths = synthetic_runs(true_t, 300, seed=1)
    fit = fit_temperature(layers, truths, SPEC, radius=0.2, objective=objective)
    assert true_t / 1.5 < fit.temperature < true_t * 1.5
    assert len(fit.log_likelihood) == len(fit.temperatures)
    assert max(fit.log_likelihood) == fit.log_likelihood[fit.temperatures.index(fit.temperature)]


def test_fit_temperature_counts_an_absent_object():
    # The object was never in the area; all layers are mildly negative: the fit should prefer
    # a posterior that keeps the absent mass high, i.e. the smallest T in both objectives.
    layers = [np.full(SPEC.shape, -1.0) + 0.1 * i for i in range(3)]
    for objective in ("cell", "within"):
        fit = fit_temperature(
            layers, [None] * 3, SPEC, p_absent=0.5, objective=objective, temperatures=(0.5, 1, 4)
        )
        assert fit.temperature == 0.5


def test_reliability_table_bins_confidences():
    rows = reliability_table([0.1, 0.15, 0.55, 0.9, 1.0], [False, True, True, True, True], 4)
    assert [(r.lo, r.hi, r.n) for r in rows] == [
        (0.0, 0.25, 2),
        (0.25, 0.5, 0),
        (0.5, 0.75, 1),
        (0.75, 1.0, 2),
    ]
    assert rows[0].mean_confidence == pytest.approx(0.125) and rows[0].hit_rate == 0.5
    assert math.isnan(rows[1].mean_confidence) and math.isnan(rows[1].hit_rate)
    assert rows[3].hit_rate == 1.0


def test_the_mass_within_a_radius_is_the_same_from_the_spec_or_from_every_centre():
    """The spec's shortcut (only the cells around the estimate) against every cell's centre,
    near edges and corners too."""
    spec = GridSpec(0.0, 0.0, 3.0, 2.0, 0.1)
    rng = np.random.default_rng(3)
    probs = rng.random(spec.shape)
    probs /= probs.sum()
    xs, ys = spec.cell_centers()
    centres = np.stack([xs, ys], axis=-1)
    for xy in [(0.0, 0.0), (1.52, 0.97), (3.0, 2.0), (2.95, 0.05), (-0.5, 1.0)]:
        for radius in (0.0, 0.15, 0.2, 0.55):
            fast = confidence_within(probs, spec, xy, radius)
            assert fast == pytest.approx(confidence_within(probs, centres, xy, radius), abs=1e-12)
