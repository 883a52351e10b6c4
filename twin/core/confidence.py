"""How sure the search is: a posterior over the map's cells, and the mass near the estimate.

Input: a layer ``L`` (ny, nx) of summed log-likelihood ratios, the ``calibrated`` fusion rule's
evidence (``twin.core.fusion.Calibrated``): each column that covered a cell added
log(p(score | on object) / p(score | off object)), weighted by how much of the cell it covered.

Derivation. Hypotheses: H_c, "the object is in cell c" (c = 1..N), and H_0, "the object is not
in the mapped area". Priors: P(H_c) = (1 - p_absent) / N (uniform over cells), P(H_0) =
p_absent. The data D are all column scores s_k. Take the columns as independent given the
hypothesis, each drawn from p_on if its wedge covers the object's cell and from p_off if not.
Under H_0 every column is off the object:

    P(D | H_0) = prod_k p_off(s_k).

Under H_c only the columns covering c change their factor from p_off to p_on:

    P(D | H_c) = P(D | H_0) * prod_{k covers c} p_on(s_k) / p_off(s_k) = P(D | H_0) * exp(L(c)).

So relative to "absent", cell c has likelihood ratio exp(L(c)), and "absent" itself has ratio
exp(0) = 1 (as does a cell no column covered: nothing distinguishes the two). Bayes:

    P(H_c | D) = (1 - p_absent) / N * exp(L(c)) / Z,    P(H_0 | D) = p_absent / Z,
    Z = p_absent + (1 - p_absent) / N * sum_c exp(L(c)).

Temperature. The columns are not independent: neighbouring columns see the same object, and
repeated views of one scene repeat the same errors, so the summed L counts evidence several
times and the posterior is too sharp. The tempered posterior replaces exp(L) by exp(L / T),
T > 0 (T = 1: the independent model; T > 1: each unit of evidence counts 1/T). "Absent" keeps
ratio 1 at every T, since its L is 0. T is fitted on development runs (``fit_temperature``).

Everything is computed with log-sum-exp, so layers of hundreds of nats do not overflow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError
from twin.core.grid import GridSpec

DEFAULT_RADIUS = 0.2  # metres: the search counts an estimate within 0.2 m of the object a hit
DEFAULT_TEMPERATURES = tuple(np.geomspace(0.25, 64.0, 81).tolist())


def _check_probability(p_absent: float) -> None:
    if not (math.isfinite(p_absent) and 0.0 <= p_absent < 1.0):
        raise InputError(f"p_absent must be a probability in [0, 1), got {p_absent!r}")


def _check_temperature(temperature: float) -> None:
    if not (math.isfinite(temperature) and temperature > 0.0):
        raise InputError(f"temperature must be a positive number, got {temperature!r}")


def _log_posterior(
    layer: np.ndarray, temperature: float, p_absent: float
) -> tuple[np.ndarray, float]:
    """(log P(H_c | D) per cell, log P(H_0 | D)): the module docstring's formula in logs."""
    layer = np.asarray(layer, dtype=float)
    if layer.ndim != 2 or layer.size == 0:
        raise InputError(f"a posterior needs a 2-D layer (ny, nx), got shape {layer.shape}")
    if not np.all(np.isfinite(layer)):
        raise InputError("the log-odds layer holds NaN or infinite values; check the fusion")
    _check_temperature(temperature)
    _check_probability(p_absent)
    cells = layer / temperature + math.log((1.0 - p_absent) / layer.size)
    absent = math.log(p_absent) if p_absent > 0.0 else -math.inf
    top = max(float(cells.max()), absent)
    total = top + math.log(float(np.exp(cells - top).sum()) + math.exp(absent - top))
    return cells - total, absent - total


def posterior(
    layer: np.ndarray, temperature: float = 1.0, p_absent: float = 0.0
) -> tuple[np.ndarray, float]:
    """Posterior over cells and of "absent" from a layer of log-likelihood ratios (nats).

    ``layer`` (ny, nx): the calibrated rule's evidence; ``temperature`` > 0 divides it (see the
    module docstring); ``p_absent`` in [0, 1): the prior that the object is not in the mapped
    area. Returns ``(cell_probs, p_absent_post)``: (ny, nx) probabilities and a float that sum
    to 1.
    """
    log_cells, log_absent = _log_posterior(layer, temperature, p_absent)
    return np.exp(log_cells), math.exp(log_absent)


def _centres(spec_or_centres: GridSpec | np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """(ny, nx, 2) cell centres in metres from a ``GridSpec`` or an array of that shape."""
    if isinstance(spec_or_centres, GridSpec):
        xs, ys = spec_or_centres.cell_centers()
        centres = np.stack([xs, ys], axis=-1)
    else:
        centres = np.asarray(spec_or_centres, dtype=float)
    if centres.shape != (*shape, 2):
        raise InputError(
            f"cell centres have shape {centres.shape}, the probabilities {shape}; give the "
            "layer's GridSpec or an (ny, nx, 2) array of centres in metres"
        )
    return centres


def confidence_within(
    cell_probs: np.ndarray,
    spec_or_centres: GridSpec | np.ndarray,
    xy: tuple[float, float],
    radius: float = DEFAULT_RADIUS,
) -> float:
    """Posterior mass of the cells whose centre lies within ``radius`` metres of ``xy``.

    This is the probability that the estimate ``xy`` (metres) is a hit at that radius, given
    the model; ``cell_probs`` comes from ``posterior`` (its "absent" mass counts as a miss).
    """
    cell_probs = np.asarray(cell_probs, dtype=float)
    if not (math.isfinite(radius) and radius >= 0.0):
        raise InputError(f"radius must be a distance >= 0 m, got {radius!r}")
    if isinstance(spec_or_centres, GridSpec) and spec_or_centres.shape == cell_probs.shape:
        # Only the cells around xy can be within the radius: on a large floor, building every
        # centre cost far more than the sum (7 ms a call on 30 m x 30 m).
        spec = spec_or_centres
        cols = _window(xy[0], radius, spec.x_min, spec.cell_size, spec.nx)
        rows = _window(xy[1], radius, spec.y_min, spec.cell_size, spec.ny)
        xs = spec.x_min + (np.arange(*cols) + 0.5) * spec.cell_size
        ys = spec.y_min + (np.arange(*rows) + 0.5) * spec.cell_size
        near = np.hypot(xs[None, :] - xy[0], ys[:, None] - xy[1]) <= radius
        window = cell_probs[rows[0] : rows[1], cols[0] : cols[1]]
        return float(np.clip(window[near].sum(), 0.0, 1.0))
    centres = _centres(spec_or_centres, cell_probs.shape)
    near = np.hypot(centres[..., 0] - xy[0], centres[..., 1] - xy[1]) <= radius
    return float(np.clip(cell_probs[near].sum(), 0.0, 1.0))


def _window(centre: float, radius: float, start: float, cell: float, n: int) -> tuple[int, int]:
    """[first, last) indices of the cells whose centres may lie within ``radius`` of ``centre``
    along one axis (one cell of margin each side)."""
    lo = math.floor((centre - radius - start) / cell) - 1
    hi = math.ceil((centre + radius - start) / cell) + 1
    return min(max(lo, 0), n), min(max(hi, 0), n)


def _log_within(
    log_cells: np.ndarray, centres: np.ndarray, xy: tuple[float, float], radius: float
) -> tuple[float, float]:
    """(log P(hit), log P(miss)) of an estimate, both from log masses (no 1 - p cancellation)."""
    near = np.hypot(centres[..., 0] - xy[0], centres[..., 1] - xy[1]) <= radius
    return _logsumexp(log_cells[near]), _logsumexp(log_cells[~near])


def _logsumexp(values: np.ndarray) -> float:
    if values.size == 0:
        return -math.inf
    top = float(values.max())
    if top == -math.inf:
        return -math.inf
    return top + math.log(float(np.exp(values - top).sum()))


@dataclass(frozen=True)
class TemperatureFit:
    """The fitted temperature and the log-likelihood (nats, summed over runs) at each tried."""

    temperature: float
    temperatures: tuple[float, ...]
    log_likelihood: tuple[float, ...]


def fit_temperature(
    layers: Sequence[np.ndarray],
    truths: Sequence[tuple[float, float] | None],
    spec: GridSpec | np.ndarray,
    radius: float = DEFAULT_RADIUS,
    p_absent: float = 0.0,
    estimates: Sequence[tuple[float, float]] | None = None,
    objective: str = "within",
    temperatures: Sequence[float] = DEFAULT_TEMPERATURES,
) -> TemperatureFit:
    """The temperature that best explains development runs, searched over ``temperatures``.

    ``layers``: one (ny, nx) log-odds layer per run; ``truths``: the object's true (x, y) in
    metres per run, or None where it was not in the mapped area; ``spec``: the layers' grid.
    ``objective``:

    * "within" (default): maximise the likelihood of each run's outcome "the truth lies within
      ``radius`` of the estimate" under the predicted ``confidence_within``, i.e. fit exactly
      the number the result reports. ``estimates`` default to each layer's best cell centre.
      (If every run is a hit the likelihood keeps rising as T falls: the smallest T tried wins;
      give runs with misses.)
    * "cell": maximise the posterior probability of the true cell (of "absent" for None), a
      proper score of the whole map that needs no estimate.
    """
    if objective not in ("within", "cell"):
        raise InputError(f"objective must be 'within' or 'cell', got {objective!r}")
    if len(layers) == 0 or len(layers) != len(truths):
        raise InputError(
            f"fit_temperature needs one truth per layer and at least one run, got "
            f"{len(layers)} layers and {len(truths)} truths"
        )
    if estimates is not None and len(estimates) != len(layers):
        raise InputError(f"got {len(estimates)} estimates for {len(layers)} layers")
    if not temperatures:
        raise InputError("fit_temperature needs at least one temperature to try")
    for t in temperatures:
        _check_temperature(t)
    shape = np.asarray(layers[0]).shape
    centres = _centres(spec, shape)
    flat = centres.reshape(-1, 2)
    runs = []
    for index, (layer, truth) in enumerate(zip(layers, truths, strict=True)):
        layer = np.asarray(layer, dtype=float)
        if layer.shape != shape:
            raise InputError(f"layer {index} has shape {layer.shape}, the first {shape}")
        if estimates is not None:
            estimate = tuple(estimates[index])
        else:
            estimate = tuple(flat[int(np.argmax(layer))])
        if objective == "within":
            hit = truth is not None and math.dist(estimate, truth) <= radius
            runs.append((layer, estimate, hit))
        else:
            cell = None if truth is None else int(np.argmin(np.hypot(*(flat - truth).T)))
            runs.append((layer, cell, None))
    totals = []
    for t in temperatures:
        total = 0.0
        for layer, where, hit in runs:
            log_cells, log_absent = _log_posterior(layer, t, p_absent)
            if objective == "cell":
                total += log_absent if where is None else float(log_cells.ravel()[where])
            else:
                log_hit, log_miss_cells = _log_within(log_cells, centres, where, radius)
                total += log_hit if hit else float(np.logaddexp(log_miss_cells, log_absent))
        totals.append(total)
    best = int(np.argmax(totals))
    return TemperatureFit(float(temperatures[best]), tuple(map(float, temperatures)), tuple(totals))


@dataclass(frozen=True)
class ReliabilityRow:
    """One confidence bin: [lo, hi), how many results fell in it, their mean confidence and
    the fraction that were hits (a calibrated confidence has mean_confidence ~ hit_rate)."""

    lo: float
    hi: float
    n: int
    mean_confidence: float
    hit_rate: float


def reliability_table(
    confidences: Sequence[float], hits: Sequence[bool], bins: int | Sequence[float] = 5
) -> list[ReliabilityRow]:
    """Rows of (bin range, n, mean confidence, hit rate) over confidence bins in [0, 1].

    ``bins``: a number of equal bins, or increasing edges; the last bin includes 1. Empty bins
    are kept (n = 0, NaN means) so tables of different runs line up.
    """
    conf = np.asarray(confidences, dtype=float).ravel()
    hit = np.asarray(hits, dtype=bool).ravel()
    if conf.shape != hit.shape:
        raise InputError(f"got {conf.size} confidences but {hit.size} hit flags; give one each")
    if np.any(~np.isfinite(conf)) or np.any((conf < 0.0) | (conf > 1.0)):
        raise InputError("confidences must be probabilities in [0, 1]")
    if isinstance(bins, (int, np.integer)):
        if bins < 1:
            raise InputError(f"reliability_table needs at least 1 bin, got {bins}")
        edges = np.linspace(0.0, 1.0, int(bins) + 1)
    else:
        edges = np.asarray(bins, dtype=float)
        if edges.size < 2 or np.any(np.diff(edges) <= 0.0):
            raise InputError("reliability bin edges must be >= 2 increasing numbers")
    index = np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, len(edges) - 2)
    rows = []
    for b in range(len(edges) - 1):
        member = index == b
        n = int(member.sum())
        rows.append(
            ReliabilityRow(
                float(edges[b]),
                float(edges[b + 1]),
                n,
                float(conf[member].mean()) if n else math.nan,
                float(hit[member].mean()) if n else math.nan,
            )
        )
    return rows
