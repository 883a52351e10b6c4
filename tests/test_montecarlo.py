"""The paper's Section 3 Monte Carlo: its statements, reproducibility, resuming, the command."""

import csv
import json
import math
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np
import pytest

from twin.app.executors import InlineExecutor, ProcessExecutor
from twin.app.montecarlo import (
    _NO_SCORES,
    RESULT_COLUMNS,
    ScoreModel,
    SweepConfig,
    SweepJournal,
    _fuse_view,
    _wedge_meets_cell,
    _wedge_values,
    draw_trial,
    evidence_layers,
    in_view,
    run_setting,
    run_sweep,
    run_trial,
    sweep_rules,
    trial_rng,
)
from twin.app.plots import _diagonal_triangles, draw_figure3, draw_figure3_3d
from twin.cli import main
from twin.core import fusion
from twin.core.coverage import add_coverage
from twin.core.errors import InputError
from twin.core.grid import AccumulatorGrid, GridSpec

# 400 trials: a 95 % interval of about +-5 points on a rate near 50 %.
FIRM = SweepConfig(trials=400, views=(10, 25, 150))


def rate(result, rule, views):
    return result.successes[FIRM.fusion.index(rule), FIRM.checkpoints.index(views)] / FIRM.trials


@pytest.fixture(scope="module")
def firm_results():
    settings = [(0.0, 0.0), (0.0, 0.6), (0.6, 0.0), (0.0, 1.0)]
    return {s: run_setting(FIRM, s) for s in settings}


def test_noise_free_detector_finds_the_object_about_40_percent_at_10_views(firm_results):
    assert 0.30 <= rate(firm_results[(0.0, 0.0)], "accumulate", 10) <= 0.55


def test_noise_free_detector_is_reliable_at_25_views(firm_results):
    assert rate(firm_results[(0.0, 0.0)], "accumulate", 25) >= 0.80


def test_many_views_tolerate_false_negatives_when_false_positives_are_rare(firm_results):
    assert rate(firm_results[(0.0, 0.6)], "accumulate", 150) >= 0.90


def test_false_positives_hurt_more_than_false_negatives(firm_results):
    fp_heavy = rate(firm_results[(0.6, 0.0)], "accumulate", 150)
    fn_heavy = rate(firm_results[(0.0, 0.6)], "accumulate", 150)
    assert fp_heavy < fn_heavy - 0.15
    assert fp_heavy > 0.25  # "the converse also holds, though to a lesser degree"


def test_a_silent_detector_scores_chance_not_a_tie_breaking_bias(firm_results):
    chance = 9 / FIRM.grid**2
    for rule in FIRM.fusion:
        assert rate(firm_results[(0.0, 1.0)], rule, 150) < chance + 0.04


def test_wedge_meets_cell_exactly():
    # Robot at (0.5, 0.5) looking along +x: the cell (col 3, row 0) spans bearings
    # atan2(-0.5, 2.5) .. atan2(0.5, 2.5), about +-11.3 degrees.
    edge = math.atan2(0.5, 2.5)
    assert _wedge_meets_cell(0.5, 0.5, edge - 0.01, edge + 0.3, 3, 0)
    assert not _wedge_meets_cell(0.5, 0.5, edge + 0.001, edge + 0.3, 3, 0)
    assert _wedge_meets_cell(0.5, 0.5, -0.1 + 2 * math.pi, 0.1 + 2 * math.pi, 3, 0)
    assert not _wedge_meets_cell(0.5, 0.5, math.pi - 0.1, math.pi + 0.1, 3, 0)


def test_draws_depend_only_on_seed_setting_and_trial():
    config = SweepConfig(trials=3, views=(20,))
    a = draw_trial(config, trial_rng(7, 0.3, 0.1, 2))
    b = draw_trial(config, trial_rng(7, 0.3, 0.1, 2))
    c = draw_trial(config, trial_rng(7, 0.3, 0.1, 1))
    np.testing.assert_array_equal(a.x, b.x)
    assert not np.array_equal(a.x, c.x)
    assert 1 <= a.object_row <= config.grid - 2 and 1 <= a.object_col <= config.grid - 2
    in_object_cell = (np.floor(a.x) == a.object_col) & (np.floor(a.y) == a.object_row)
    assert not in_object_cell.any()


SMALL = SweepConfig(pfp=(0.0, 0.3), pfn=(0.0, 0.5), views=(5, 12), trials=6, seed=3)


def test_results_do_not_depend_on_workers_or_other_settings():
    inline = run_sweep(SMALL, InlineExecutor())
    pooled = run_sweep(SMALL, ProcessExecutor(2))
    for a, b in zip(inline, pooled, strict=True):
        assert (a.pfp, a.pfn) == (b.pfp, b.pfn)
        np.testing.assert_array_equal(a.successes, b.successes)
    alone = run_setting(SweepConfig(pfp=(0.3,), pfn=(0.5,), views=(5, 12), trials=6, seed=3),
                        (0.3, 0.5))  # fmt: skip
    np.testing.assert_array_equal(alone.successes, inline[-1].successes)


# Successes (accumulate, normalized, logodds) x (10, 25 views) recorded before the sweep drove
# the rules through twin.core.fusion, when its kernel coded them itself.
PINNED = SweepConfig(pfp=(0.0, 0.3, 0.7), pfn=(0.0, 0.5), views=(10, 25), trials=20, seed=3,
                     min_observed=2.0)  # fmt: skip
PINNED_SUCCESSES = {
    (0.0, 0.0): [[11, 18], [5, 15], [12, 18]],
    (0.0, 0.5): [[6, 13], [4, 14], [4, 14]],
    (0.3, 0.0): [[3, 6], [2, 10], [3, 12]],
    (0.3, 0.5): [[0, 1], [0, 0], [0, 1]],
    (0.7, 0.0): [[2, 2], [2, 7], [4, 5]],
    (0.7, 0.5): [[0, 0], [0, 0], [1, 1]],
}


def test_the_three_rules_give_the_results_recorded_before_they_came_from_fusion():
    results = run_sweep(PINNED, InlineExecutor())
    assert {(r.pfp, r.pfn): r.successes.tolist() for r in results} == PINNED_SUCCESSES


def direct_successes(config, pfp, pfn, trial):
    """One trial recomputed through the grid's own API: an AccumulatorGrid per rule fused view
    by view, its ``layer`` read, and the arg-max tie broken as the module documents."""
    draws = draw_trial(config, trial_rng(config.seed, pfp, pfn, trial))
    spec = GridSpec(0.0, 0.0, config.grid, config.grid, 1.0)
    rules = sweep_rules(config, pfp, pfn)
    grids = [AccumulatorGrid(["object"], spec, rule, config.supersample) for rule in rules]
    wedge = config.fov / config.wedges
    out = np.zeros((len(rules), len(config.checkpoints)), dtype=bool)
    c = 0
    for v in range(config.checkpoints[-1]):
        top = draws.yaw[v] + 0.5 * config.fov - wedge * np.arange(config.wedges)
        intervals = np.stack([top - wedge, top], axis=1)
        values = np.zeros(config.wedges)
        for w, (a0, a1) in enumerate(intervals):
            hit = _wedge_meets_cell(draws.x[v], draws.y[v], a0, a1, draws.object_col,
                                    draws.object_row)  # fmt: skip
            values[w] = draws.fire[v, w] < ((1.0 - pfn) if hit else pfp)
        for grid in grids:
            grid.fuse("object", (draws.x[v], draws.y[v]), intervals, values)
        if v + 1 == config.checkpoints[c]:
            for r, grid in enumerate(grids):
                layer = grid.layer("object")
                top_value = layer.max()
                tied = np.flatnonzero(layer >= top_value - 1e-9 * max(1.0, abs(top_value)))
                pick = tied[min(int(draws.tie[c] * len(tied)), len(tied) - 1)]
                row, col = divmod(pick, config.grid)
                near = abs(row - draws.object_row) <= 1 and abs(col - draws.object_col) <= 1
                out[r, c] = near
            c += 1
    return out


@pytest.mark.parametrize("setting", [(0.0, 0.0), (0.3, 0.5), (0.2, 0.1)])
def test_each_trial_matches_a_direct_computation_through_the_grid(setting):
    config = SweepConfig(views=(6, 15, 40), trials=4, seed=9, min_observed=1.5)
    for trial in range(config.trials):
        expected = direct_successes(config, *setting, trial)
        np.testing.assert_array_equal(run_trial(config, *setting, trial), expected)


@dataclass(frozen=True)
class Silences:
    """A rule fusion.py does not have: cells seen by many silent wedges, scaled by P_fn."""

    name: ClassVar[str] = "silences"
    p_fn: float = 0.5

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return 1.0 - np.asarray(values, dtype=float)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return (1.0 - self.p_fn) * evidence - observed

    def params(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Echo:
    """The paper's weights read another way: shares accumulate's evidence sum."""

    name: ClassVar[str] = "echo"

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return 2.0 * evidence


def test_a_rule_registered_in_fusion_runs_through_the_sweep(monkeypatch):
    monkeypatch.setitem(fusion.RULES, "silences", Silences)
    monkeypatch.setitem(fusion.RULES, "echo", Echo)
    config = SweepConfig(pfp=(0.1, 0.4), pfn=(0.2,), views=(5, 20), trials=3, seed=2,
                         fusion=("silences", "accumulate", "echo", "logodds"))  # fmt: skip
    rules = sweep_rules(config, 0.1, 0.2)
    assert rules[0] == Silences(p_fn=0.2)  # the setting's true rate, as logodds gets it
    weights, layer_of = evidence_layers(rules)
    assert layer_of == (0, 1, 1, 2) and len(weights) == 3  # echo shares accumulate's sum
    results = run_sweep(config, InlineExecutor())
    for result in results:
        direct = sum(direct_successes(config, result.pfp, result.pfn, t) for t in range(3))
        np.testing.assert_array_equal(result.successes, direct)
        np.testing.assert_array_equal(result.successes[2], result.successes[1])
    assert {row["fusion"] for row in results[0].rows()} == set(config.fusion)


@dataclass(frozen=True)
class NeedsGain:
    name: ClassVar[str] = "gain"
    gain: float

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return self.gain * np.asarray(values, dtype=float)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return evidence


def test_a_rule_whose_parameters_the_sweep_cannot_supply_is_a_one_line_error(
    monkeypatch, tmp_path, capsys
):
    monkeypatch.setitem(fusion.RULES, "gain", NeedsGain)
    with pytest.raises(InputError, match=r"cannot supply its parameter\(s\) gain"):
        SweepConfig(fusion=("accumulate", "gain"))
    code = main(["montecarlo", "--trials", "1", "--fusion", "gain", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "gain" in err


def test_a_rule_that_writes_into_the_shared_sums_fails_instead_of_corrupting_others(
    monkeypatch,
):
    @dataclass(frozen=True)
    class Scribble(Echo):
        name: ClassVar[str] = "scribble"

        def read(self, evidence, observed):
            evidence += 1.0
            return evidence

    monkeypatch.setitem(fusion.RULES, "scribble", Scribble)
    config = SweepConfig(pfp=(0.1,), pfn=(0.1,), views=(3,), trials=1, fusion=("scribble",))
    with pytest.raises(ValueError, match="read-only"):
        run_setting(config, (0.1, 0.1))


def test_an_interrupted_sweep_resumes_without_rerunning_finished_settings(tmp_path):
    journal_path = tmp_path / "settings.jsonl"

    class Interrupt(Exception):
        pass

    def stop_after_two(result, seen=[]):  # noqa: B006 - counts calls across this test only
        seen.append(result)
        if len(seen) == 2:
            raise Interrupt

    with pytest.raises(Interrupt):
        run_sweep(SMALL, InlineExecutor(), SweepJournal(journal_path, SMALL), stop_after_two)
    with journal_path.open("a") as handle:
        handle.write('{"pfp": 0.3, "pfn": 0.0, "succ')  # a torn line from a crash
    resumed_journal = SweepJournal(journal_path, SMALL)
    assert len(resumed_journal.done) == 2
    ran = []
    resumed = run_sweep(SMALL, InlineExecutor(), resumed_journal, ran.append)
    assert len(ran) == len(SMALL.settings()) - 2
    fresh = run_sweep(SMALL, InlineExecutor())
    for a, b in zip(resumed, fresh, strict=True):
        np.testing.assert_array_equal(a.successes, b.successes)


def test_a_journal_of_another_sweep_is_refused(tmp_path):
    path = tmp_path / "settings.jsonl"
    SweepJournal(path, SMALL)
    other = SweepConfig(pfp=SMALL.pfp, pfn=SMALL.pfn, views=SMALL.views, trials=7, seed=3)
    with pytest.raises(InputError, match="other parameters"):
        SweepJournal(path, other)
    assert SweepJournal(path, other, fresh=True).done == {}


def test_a_journal_that_did_not_record_its_rules_is_refused_in_one_line(tmp_path):
    path = tmp_path / "settings.jsonl"
    SweepJournal(path, SMALL)
    lines = path.read_text().splitlines()
    header = json.loads(lines[0])
    del header["sweep"]["fusion"]  # as sweeps wrote it when every rule always ran
    path.write_text(json.dumps(header) + "\n")
    with pytest.raises(InputError, match="older twin that did not record its rules") as info:
        SweepJournal(path, SMALL)
    assert "--fresh" in str(info.value) and "\n" not in str(info.value)
    assert SweepJournal(path, SMALL, fresh=True).done == {}
    narrower = SweepConfig(pfp=SMALL.pfp, pfn=SMALL.pfn, views=SMALL.views, trials=6, seed=3,
                           fusion=("logodds",))  # fmt: skip
    with pytest.raises(InputError, match=r"other parameters \(fusion\)"):
        SweepJournal(path, narrower)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"pfp": (1.5,)}, "--pfp"), ({"pfn": (-0.1,)}, "--pfn"), ({"views": (0,)}, "--views"),
     ({"trials": 0}, "--trials"), ({"wedges": 0}, "--wedges"), ({"grid": 2}, "--grid"),
     ({"fov": 0.0}, "--fov-deg"), ({"supersample": 0}, "--supersample"),
     ({"fusion": ("bayes",)}, "--fusion"), ({"seed": -1}, "--seed"),
     ({"fusion": ("logodds", "logodds")}, "--fusion names a rule twice"),
     ({"min_observed": -1.0}, "--min-observed")],
)  # fmt: skip
def test_bad_sweep_parameters_are_named(kwargs, match):
    with pytest.raises(InputError, match=match):
        SweepConfig(**kwargs)


def test_command_writes_the_csv_and_figure(tmp_path, capsys):
    out = tmp_path / "mc"
    argv = ["montecarlo", "--pfp", "0,0.5", "--pfn", "0.2", "--views", "4,8", "--trials", "3",
            "--fusion", "accumulate,logodds", "--workers", "1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    with (out / "results.csv").open() as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
    assert tuple(reader.fieldnames) == RESULT_COLUMNS
    assert len(rows) == 2 * 2 * 1 * 2
    assert {r["fusion"] for r in rows} == {"accumulate", "logodds"}
    for r in rows:
        assert float(r["success_rate"]) == int(r["successes"]) / int(r["trials"])
    assert (out / "figure3.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (out / "figure3_3d.png").exists()  # one P_fn: curves, no surface
    printed = capsys.readouterr().out
    assert "accumulate" in printed and "logodds" in printed
    assert main(argv) == 0  # a finished sweep in the same folder is reused, not refused
    assert "2 of 2 settings done" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "match"),
    [(["--pfp", "0,1.5"], "--pfp must be rates in [0, 1]"),
     (["--fusion", "bayes"], "--fusion: unknown rule"),
     (["--workers", "0"], "--workers must be at least 1")],
)  # fmt: skip
def test_command_reports_bad_input_in_one_line(tmp_path, capsys, argv, match):
    code = main(["montecarlo", "--trials", "1", "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert match in err and len(err.splitlines()) == 1


def test_command_rejects_malformed_lists_in_one_line(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["montecarlo", "--views", "ten"])
    assert exit_info.value.code == 2
    assert "comma-separated list of view counts" in capsys.readouterr().err


def test_command_writes_heat_maps_and_surfaces_when_both_rates_vary(tmp_path, capsys):
    out = tmp_path / "mc"
    argv = ["montecarlo", "--pfp", "0,0.5", "--pfn", "0,0.5", "--views", "3", "--trials", "2",
            "--workers", "1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    for name in ("figure3.png", "figure3_3d.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(out / name) in printed


FIGURE_RULES, FIGURE_VIEWS = ("accumulate", "logodds"), (10, 150)
FIGURE_PFP, FIGURE_PFN = (0.0, 0.5, 1.0), (0.0, 0.3)


def figure_rows(pfn=FIGURE_PFN):
    """Rows as results.csv holds them, each success rate distinct: 3 * k % for the k-th row."""
    rows = []
    for rule in FIGURE_RULES:
        for pfp in FIGURE_PFP:
            for fn in pfn:
                for views in FIGURE_VIEWS:
                    k = len(rows)
                    rows.append({"fusion": rule, "pfp": pfp, "pfn": fn, "views": views,
                                 "trials": 100, "successes": 3 * k,
                                 "success_rate": 3 * k / 100})  # fmt: skip
    return rows


def test_figure3_is_one_heat_map_per_rule_and_view_count_with_every_number_printed():
    from matplotlib.textpath import TextPath

    rows = figure_rows()
    table = {(r["fusion"], r["pfp"], r["pfn"], r["views"]): r["success_rate"] for r in rows}
    fig = draw_figure3(rows, FIGURE_RULES, FIGURE_PFP, FIGURE_PFN, FIGURE_VIEWS)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == len(FIGURE_RULES) * len(FIGURE_VIEWS)
    for ax, (rule, views) in zip(
        panels, [(r, v) for r in FIGURE_RULES for v in FIGURE_VIEWS], strict=True
    ):
        assert ax.images[0].get_clim() == (0.0, 100.0)
        assert rule in ax.get_title() and str(views) in ax.get_title()
        (numbers,) = ax.collections  # the printed numbers, as glyph outlines
        placed = numbers.get_offsets()
        assert len(placed) == len(numbers.get_paths()) == len(FIGURE_PFP) * len(FIGURE_PFN)
        for (col, row), glyphs in zip(placed, numbers.get_paths(), strict=True):
            rate = table[(rule, FIGURE_PFP[int(col)], FIGURE_PFN[int(row)], views)]
            expected = TextPath((0, 0), f"{100 * rate:.0f}")
            assert list(glyphs.codes) == list(expected.codes)  # same digits, any size
    assert any("success" in ax.get_ylabel() for ax in fig.axes if not ax.images)  # colour bar


def test_figure3_falls_back_to_curves_when_one_rate_axis_is_fixed():
    rows = figure_rows(pfn=(0.2,))
    fig = draw_figure3(rows, FIGURE_RULES, FIGURE_PFP, (0.2,), FIGURE_VIEWS)
    assert not any(ax.images for ax in fig.axes)
    curves = [ax.lines[0].get_xdata() for ax in fig.axes]
    assert len(curves) == 4 and all(list(x) == list(FIGURE_PFP) for x in curves)
    assert draw_figure3_3d(rows, FIGURE_RULES, FIGURE_PFP, (0.2,), FIGURE_VIEWS) is None


def test_figure3_3d_draws_each_surface_as_flat_triangles():
    fig = draw_figure3_3d(figure_rows(), FIGURE_RULES, FIGURE_PFP, FIGURE_PFN, FIGURE_VIEWS)
    surfaces = [ax for ax in fig.axes if hasattr(ax, "get_zlim")]
    assert len(surfaces) == len(FIGURE_RULES) * len(FIGURE_VIEWS)
    cells = (len(FIGURE_PFP) - 1) * (len(FIGURE_PFN) - 1)
    fig.canvas.draw()  # mplot3d projects (and depth-sorts) its polygons when drawn
    for ax in surfaces:
        (collection,) = ax.collections
        polygons = collection.get_paths()
        assert len(polygons) == 2 * cells
        assert all(len(np.unique(path.vertices, axis=0)) == 3 for path in polygons)


def test_surface_cells_are_cut_along_the_diagonal_across_the_line_of_sight():
    triangles = _diagonal_triangles(3, 2)  # vertices 0 1 2 / 3 4 5, two cells
    assert len(triangles) == 4
    for i in range(2):  # cell i: corners i, i + 1, i + 4, i + 3
        cut = {i + 1, i + 3}
        halves = [set(t) for t in triangles if set(t) <= {i, i + 1, i + 3, i + 4}]
        assert halves == [{i, i + 1, i + 3}, {i + 1, i + 4, i + 3}]
        assert halves[0] & halves[1] == cut


def test_a_folder_that_is_not_a_sweep_is_refused_never_written(tmp_path, capsys):
    (tmp_path / "results.csv").write_text("someone else's")
    code = main(["montecarlo", "--trials", "1", "--out", str(tmp_path), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "holds files that are not a twin montecarlo sweep (e.g. results.csv)" in err
    assert [p.name for p in tmp_path.iterdir()] == ["results.csv"]


def test_an_interrupted_sweep_command_writes_the_finished_settings(tmp_path, monkeypatch):
    import twin.app.montecarlo as montecarlo

    real = montecarlo.run_chunk

    def interrupted_at_the_second_setting(config, chunk):
        if (chunk.pfp, chunk.pfn) != (0.0, 0.0):
            raise KeyboardInterrupt
        return real(config, chunk)

    monkeypatch.setattr(montecarlo, "run_chunk", interrupted_at_the_second_setting)
    argv = ["montecarlo", "--pfp", "0,0.5", "--pfn", "0", "--trials", "3", "--views", "5",
            "--workers", "1", "--out", str(tmp_path / "mc"), "--quiet"]  # fmt: skip
    assert main(argv) == 130
    with (tmp_path / "mc" / "results.csv").open() as handle:
        assert {(r["pfp"], r["pfn"]) for r in csv.DictReader(handle)} == {("0.0", "0.0")}
    monkeypatch.setattr(montecarlo, "run_chunk", real)
    assert main(argv) == 0
    with (tmp_path / "mc" / "results.csv").open() as handle:
        assert {r["pfp"] for r in csv.DictReader(handle)} == {"0.0", "0.5"}


# -- occluders, continuous scores, the kernel's arithmetic ------------------------------------


def segment_blocked(occluded, px, py, col, row):
    """Brute force: whether the segment to the centre of (col, row) meets any occluder cell's
    square other than the target's (exact slab test per cell)."""
    tx, ty = col + 0.5, row + 0.5
    for r, c in zip(*np.nonzero(occluded), strict=True):
        if (r, c) == (row, col):
            continue
        t0, t1 = 0.0, 1.0
        for p, d, lo in ((px, tx - px, c), (py, ty - py, r)):
            if d == 0.0:
                if not lo <= p <= lo + 1:
                    t0, t1 = 1.0, 0.0
                continue
            a, b = sorted(((lo - p) / d, (lo + 1 - p) / d))
            t0, t1 = max(t0, a), min(t1, b)
        if t0 < t1:
            return True
    return False


def test_in_view_is_the_exact_line_of_sight_to_a_cell_centre():
    rng = np.random.default_rng(4)
    for _ in range(30):
        occluded = rng.random((12, 12)) < 0.2
        free = np.argwhere(~occluded)
        row, col = free[rng.integers(len(free))]
        px, py = col + rng.random(), row + rng.random()
        for r in range(12):
            for c in range(12):
                if (r, c) == (row, col):
                    continue
                seen = in_view(occluded, px, py, c, r)
                assert seen == (not segment_blocked(occluded, px, py, c, r)), (px, py, c, r)


def test_the_sweep_kernel_adds_exactly_what_add_coverage_adds():
    # The same floats to the last bit: the normalized rule's min_observed compares sums of
    # coverage with whole numbers, where a different summation order changes the result.
    rng = np.random.default_rng(8)
    n, s, wedges = 20, 10, 8
    weights = np.stack([rng.choice([0.0, 1.0], wedges), rng.normal(size=wedges),
                        np.ones(wedges)])  # fmt: skip
    expected = np.zeros((3, n, n))
    got = np.zeros((3, n, n))
    scratch = (
        np.empty((n, n), np.int8),
        np.empty(n * s),
        np.empty((wedges, 4, n * s), np.int64),
        np.empty((wedges, 4, n * s), np.int64),
    )
    for view in range(40):
        px, py = rng.uniform(0, n, size=2)
        if view == 0:
            py = 7.25  # a sample row through the robot
        top = rng.uniform(-math.pi, math.pi) + math.pi / 8 - np.arange(wedges) * math.pi / 32
        a0, a1 = top - math.pi / 32, top
        add_coverage(expected, px, py, a0, a1, weights, 0.0, 0.0, 1.0, s, 0.0)
        _fuse_view(got, px, py, a0, a1, weights, s, False, np.zeros((n, n), bool), *scratch)
        assert np.array_equal(got, expected)


def test_knowing_visibility_in_an_open_world_changes_nothing():
    n, s, wedges = 20, 10, 8
    weights = np.stack([np.linspace(-1, 1, wedges), np.ones(wedges)])
    state = np.zeros((4, n, n))
    known = np.full((n, n), -1, np.int8)
    scratch = (np.empty(n * s), np.empty((wedges, 4, n * s), np.int64),
               np.empty((wedges, 4, n * s), np.int64))  # fmt: skip
    top = 0.3 - np.arange(wedges) * 0.1
    _fuse_view(state, 5.5, 6.2, top - 0.1, top, weights, s, True, np.zeros((n, n), bool), known,
               *scratch)  # fmt: skip
    np.testing.assert_array_equal(state[2:], state[:2])


def wall_world(config):
    """A trial with a wall of occluders at column 10 (rows 0..18) between the robot, always
    at x < 10, and the object at (row 9, col 15)."""
    n = config.grid
    occluded = np.zeros((n, n), bool)
    occluded[: n - 1, 10] = True
    views = config.checkpoints[-1]
    rng = np.random.default_rng(1)
    x, y = rng.uniform(0, 10, views), rng.uniform(0, n - 1, views)
    yaw = np.arctan2(9.5 - y, 15.5 - x)  # looking straight at the object
    return occluded, x, y, yaw


def test_an_object_behind_an_occluder_is_not_seen():
    config = SweepConfig(pfp=(0.0,), pfn=(0.0,), views=(30,), occluders=0.05)
    occluded, x, y, yaw = wall_world(config)
    values = np.empty((30, config.wedges))
    fire = np.zeros((30, config.wedges))  # a wedge that sees the object fires for sure
    args = (config.fov, config.wedges, 9, 15, x, y, yaw, fire, 0.0, 0.0)
    _wedge_values(*args, occluded, True, _NO_SCORES, _NO_SCORES, False, values)
    reached_over = y >= config.grid - 2  # only the top row's gap in the wall shows the object
    assert not values[~reached_over].any()
    _wedge_values(*args, np.zeros_like(occluded), True, _NO_SCORES, _NO_SCORES, False, values)
    assert values.any(axis=1).all()  # without the wall every view sees it


def test_occluders_are_drawn_apart_from_the_object_and_the_robot():
    config = SweepConfig(views=(200,), occluders=0.2)
    for trial in range(5):
        d = draw_trial(config, trial_rng(0, 0.1, 0.1, trial))
        assert d.occluded.sum() == config.occluder_count == 80
        assert not d.occluded[d.object_row, d.object_col]
        assert not d.occluded[np.floor(d.y).astype(int), np.floor(d.x).astype(int)].any()


def test_without_occluders_the_sweep_draws_and_writes_exactly_the_papers(tmp_path):
    paper = SweepConfig(pfp=(0.3,), pfn=(0.5,), views=(8,), trials=2)
    assert paper == SweepConfig(pfp=(0.3,), pfn=(0.5,), views=(8,), trials=2, occluders=0.0,
                                scores="binary")  # fmt: skip
    assert paper.evaluations == (("accumulate", "none"), ("normalized", "none"),
                                 ("logodds", "none"))  # fmt: skip
    assert paper.result_columns == RESULT_COLUMNS
    a = draw_trial(paper, trial_rng(0, 0.3, 0.5, 1))
    rng = trial_rng(0, 0.3, 0.5, 1)  # the draws as the paper's sweep made them
    assert (a.object_row, a.object_col) == tuple(int(v) for v in rng.integers(1, 19, size=2))
    cell = rng.integers(0, 399, size=8)
    cell += cell >= a.object_row * 20 + a.object_col
    np.testing.assert_array_equal(a.x, cell % 20 + rng.random((8, 2))[:, 0])
    assert not a.occluded.any()
    journal = SweepJournal(tmp_path / "settings.jsonl", paper)
    header = json.loads((tmp_path / "settings.jsonl").read_text().splitlines()[0])["sweep"]
    assert set(header) == {"fusion", "trials", "wedges", "fov", "grid", "supersample", "seed",
                           "min_observed", "checkpoints"}  # fmt: skip
    assert journal.done == {}


FOGGY = SweepConfig(pfp=(0.1,), pfn=(0.1,), views=(75,), trials=100, occluders=0.15, seed=1)


def test_with_occluders_the_probabilistic_rule_loses_blind_and_wins_knowing_what_it_saw():
    result = run_setting(FOGGY, (0.1, 0.1))
    rates = dict(zip(FOGGY.evaluations, result.successes[:, 0] / FOGGY.trials, strict=True))
    assert rates[("logodds", "known")] > rates[("logodds", "none")] + 0.25
    assert rates[("logodds", "known")] > rates[("accumulate", "none")] + 0.25
    rows = result.rows()
    assert {(r["fusion"], r["visibility"]) for r in rows} == set(FOGGY.evaluations)


def test_scores_rates_and_calibration_are_the_beta_distributions():
    stats = pytest.importorskip("scipy.stats")
    model = ScoreModel(on=(4.0, 8.0), off=(2.0, 20.0))
    for threshold in (0.05, 0.16, 0.4):
        pfp, pfn = model.rates(threshold)
        assert pfp == pytest.approx(stats.beta.sf(threshold, 2, 20), abs=1e-7)
        assert pfn == pytest.approx(stats.beta.cdf(threshold, 4, 8), abs=1e-7)
    edges, llr = model.calibration(50)
    assert len(edges) == 51 and len(llr) == 50
    on = np.diff(stats.beta.cdf(edges[:21], 4, 8))  # beyond 0.4 the off mass is ~1e-10 and
    off = np.diff(stats.beta.cdf(edges[:21], 2, 20))  # the CDF's differences lose it
    np.testing.assert_allclose(llr[:20], np.log(on / off), atol=1e-6)
    assert np.all(np.isfinite(llr)) and np.all(np.diff(llr) > 0)  # more on-like as it rises


SCORED = SweepConfig(views=(25,), trials=200, scores="beta", thresholds=(0.16, 0.35),
                     fusion=("accumulate", "normalized", "logodds", "calibrated"))  # fmt: skip


def test_continuous_scores_get_their_own_layers():
    @dataclass(frozen=True)
    class Fired:  # the paper's weights on 0 and 1, another weight for a score of 0.3
        name: ClassVar[str] = "fired"

        def column_weights(self, values):
            return (np.asarray(values) >= 0.5).astype(float)

        def read(self, evidence, observed):
            return evidence

    rules = (*sweep_rules(SCORED, *SCORED.settings()[0]), Fired())
    assert evidence_layers(rules)[1] == (0, 0, 1, 2, 0)  # on [0, 1] fired weighs as the paper
    assert evidence_layers(rules, np.array([0.0, 0.3, 1.0]))[1] == (0, 0, 1, 2, 3)
    binary = sweep_rules(SweepConfig(fusion=("logodds", "calibrated")), 0.2, 0.3)
    assert evidence_layers(binary)[1] == (0, 0)  # a binary detector's LLR is logodds' weights


def test_the_calibrated_rule_beats_a_thresholded_detector_on_the_same_worlds():
    low, high = (run_setting(SCORED, s) for s in SCORED.settings())
    rates = {t: dict(zip(SCORED.fusion, r.successes[:, 0] / SCORED.trials, strict=True))
             for t, r in ((0.16, low), (0.35, high))}  # fmt: skip
    for rule in ("accumulate", "normalized", "calibrated"):  # the threshold changes no world
        assert rates[0.16][rule] == rates[0.35][rule]
    assert rates[0.35]["calibrated"] > rates[0.35]["logodds"] + 0.08
    assert rates[0.16]["calibrated"] >= rates[0.16]["logodds"]
    assert (low.threshold, high.threshold) == (0.16, 0.35)
    assert low.pfp == pytest.approx(0.13, abs=0.01) and low.pfn == pytest.approx(0.08, abs=0.01)


def test_command_with_occluders_and_scores_writes_their_columns(tmp_path, capsys):
    out = tmp_path / "fog"
    argv = ["montecarlo", "--pfp", "0.1", "--pfn", "0.1,0.3", "--views", "5", "--trials", "2",
            "--occluders", "0.1", "--workers", "1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    with (out / "results.csv").open() as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
    assert reader.fieldnames[:2] == ["fusion", "visibility"]
    assert {r["visibility"] for r in rows} == {"none", "known"} and len(rows) == 3 * 2 * 2
    assert "logodds+visibility" in capsys.readouterr().out
    out = tmp_path / "scores"
    argv = ["montecarlo", "--scores", "beta", "--threshold", "0.2,0.3", "--views", "5",
            "--trials", "2", "--fusion", "logodds,calibrated", "--workers", "1", "--out",
            str(out)]  # fmt: skip
    assert main(argv) == 0
    with (out / "results.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert {r["threshold"] for r in rows} == {"0.2", "0.3"}
    assert (out / "thresholds.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "t=0.2" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "match"),
    [(["--scores", "beta", "--pfp", "0.1"], "with --scores beta the rates follow"),
     (["--occluders", "0.95"], "--occluders must be a fraction"),
     (["--scores", "beta", "--score-off", "0.5,2"], "--score-off must be Beta shape"),
     (["--scores", "beta", "--threshold", "0,0.5"], "--threshold must be distinct values")],
)  # fmt: skip
def test_bad_occluder_and_score_options_are_one_line_errors(tmp_path, capsys, argv, match):
    code = main(["montecarlo", "--trials", "1", "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2 and match in err and len(err.splitlines()) == 1
