"""The active mode of the paper's abstract-world Monte Carlo: planners, worlds, the command."""

import csv
import math
import re

import numpy as np
import pytest

from twin.app.executors import InlineExecutor
from twin.app.montecarlo import run_trial
from twin.app.montecarlo_active import (
    HEADINGS,
    PLANNERS,
    SURVEY_VIEWS,
    ActiveConfig,
    _lattice_values,
    _Setting,
    _wedge_edges,
    candidate_views,
    lattice_view,
    run_active,
    run_active_trial,
    survey_plan,
)
from twin.cli import main
from twin.core.errors import InputError

# A small world keeps every planner's trials fast; the rules are the paper's and logodds.
SMALL = ActiveConfig(grid=10, views=12, trials=6, settings=((0.1, 0.1), (0.3, 0.1)), seed=21)


def mass_covered(grid: int) -> np.ndarray:
    """(n_views,) the cells each candidate covers, summed over its wedges (the uniform prior's
    mass it sees, times the number of cells)."""
    f = candidate_views(grid, 8, math.radians(45.0), 10).footprints
    rows = np.repeat(f.row_view, np.diff(f.indptr))
    return np.bincount(rows, weights=f.share, minlength=f.n_views)


def views_to_reach(result, rule: str, level: float) -> int:
    """The fewest views after which ``rule`` succeeds in at least ``level`` of the trials."""
    rates = result.successes[result.fusion.index(rule)] / result.trials
    reached = np.flatnonzero(rates >= level)
    return int(reached[0]) + 1 if reached.size else 10**6


def test_survey_takes_the_40_planned_views_five_places_eight_headings():
    config = ActiveConfig(grid=20, views=40, trials=1, seed=21)
    trial = run_active_trial(config, (0.1, 0.1), "survey", 0)
    plan = survey_plan(20)
    assert len(plan) == SURVEY_VIEWS == 40
    assert trial.views.tolist() == plan.tolist()
    places = [(5, 5), (15, 5), (10, 10), (5, 15), (15, 15)]
    assert plan.tolist() == [lattice_view(20, x, y, h) for x, y in places for h in range(8)]
    # Travel only between stops: two legs of 10 cells and two of 5 sqrt(2).
    legs = np.diff(np.array(places, dtype=float), axis=0)
    assert trial.path[-1] == pytest.approx(np.hypot(*legs.T).sum())
    assert np.count_nonzero(np.diff(trial.path)) == 4


def test_survey_stops_at_its_40_views_when_more_are_asked():
    config = ActiveConfig(grid=10, views=45, trials=2, planners=("survey", "random"), seed=21)
    survey, random = run_active(config, InlineExecutor())
    assert survey.successes.shape[1] == 40 and random.successes.shape[1] == 45


def test_results_repeat_and_do_not_depend_on_the_planner_set_or_chunks():
    everything = run_active(SMALL, InlineExecutor(), chunk_trials=4)
    again = run_active(SMALL, InlineExecutor(), chunk_trials=6)
    alone = ActiveConfig(**{**SMALL.__dict__, "planners": ("information",),
                            "settings": ((0.3, 0.1),)})  # fmt: skip
    (single,) = run_active(alone, InlineExecutor(), chunk_trials=5)
    for a, b in zip(everything, again, strict=True):
        assert (a.planner, a.setting) == (b.planner, b.setting)
        np.testing.assert_array_equal(a.successes, b.successes)
        np.testing.assert_array_equal(a.path, b.path)
    [same] = [r for r in everything if (r.planner, r.setting) == ("information", (0.3, 0.1))]
    np.testing.assert_array_equal(single.successes, same.successes)
    np.testing.assert_array_equal(single.path, same.path)


def test_every_planner_faces_the_same_object_and_random_is_the_sweeps_trial():
    cells = {p: [run_active_trial(SMALL, (0.1, 0.1), p, t).object_cell for t in range(4)]
             for p in PLANNERS}  # fmt: skip
    assert len({tuple(v) for v in cells.values()}) == 1
    assert len(set(cells["random"])) > 1  # the trials do differ
    for t in range(3):
        trial = run_active_trial(SMALL, (0.1, 0.1), "random", t)
        sweep = SMALL.sweep((0.1, 0.1))
        np.testing.assert_array_equal(trial.hits, run_trial(sweep, 0.1, 0.1, t))


def test_information_first_view_covers_the_most_mass_on_the_uniform_prior():
    for grid in (10, 20):
        config = ActiveConfig(grid=grid, views=1, trials=1, seed=21)
        first = run_active_trial(config, (0.1, 0.1), "information", 0).views[0]
        mass = mass_covered(grid)
        assert mass[first] >= mass.max() * (1.0 - 1e-9)
        assert mass[first] > 2.0 * np.median(mass)  # not a tie of everything


def test_greedy_planners_never_repeat_a_view_and_pay_for_travel():
    config = ActiveConfig(grid=10, views=30, trials=2, seed=21)
    for planner in ("coverage", "detection", "information"):
        for t in range(2):
            trial = run_active_trial(config, (0.1, 0.1), planner, t)
            assert len(set(trial.views.tolist())) == len(trial.views)
    free = ActiveConfig(**{**config.__dict__, "travel_cost": 0.0})
    dear = ActiveConfig(**{**config.__dict__, "travel_cost": 5.0})
    walked = {
        cost: sum(run_active_trial(c, (0.1, 0.1), "information", t).path[-1] for t in range(2))
        for cost, c in ((0.0, free), (5.0, dear))
    }
    assert walked[5.0] < 0.5 * walked[0.0]


def test_noise_free_information_planner_finds_the_object_far_sooner_than_random():
    config = ActiveConfig(grid=10, views=20, trials=30, settings=((0.0, 0.0),),
                          planners=("random", "information"), seed=21)  # fmt: skip
    random, information = run_active(config, InlineExecutor())
    for rule in ("accumulate", "logodds"):
        fast = views_to_reach(information, rule, 0.8)
        slow = views_to_reach(random, rule, 0.8)
        assert 2 * fast <= slow, (rule, fast, slow)
        assert information.success_rate(rule, 5) >= random.success_rate(rule, 5) + 0.2


def test_a_lattice_view_on_the_objects_corner_fires_only_wedges_meeting_its_quarter():
    # Standing on the lower-left corner of cell (row 4, col 4) facing +x: the cell spans bearings
    # 0..90 degrees, so exactly the 4 wedges left of the optical axis meet it.
    config = ActiveConfig(grid=10, views=1, trials=1, settings=((0.0, 0.0),), seed=21)
    context = _Setting(config, (0.0, 0.0))
    view = lattice_view(10, 4, 4, 0)
    values = np.empty(8, dtype=np.int64)
    _lattice_values(4.0, 4.0, 0.0, config.fov, 8, 4, 4, np.full(8, 0.5), 0.0, 0.0, values)
    assert values.tolist() == [1, 1, 1, 1, 0, 0, 0, 0]
    # ... and those are the wedges whose footprint covers the cell.
    f = context.candidates.footprints
    covered = [4 * 10 + 4 in f.cells[f.indptr[r] : f.indptr[r + 1]] for r in range(view * 8,
               view * 8 + 8)]  # fmt: skip
    assert covered == [True] * 4 + [False] * 4
    a0, a1 = _wedge_edges(0.0, config.fov, 8)
    assert a1[0] == pytest.approx(math.radians(22.5)) and a0[3] == pytest.approx(0.0)


def test_candidates_cover_the_lattice_and_their_wedges_tile_each_view():
    cands = candidate_views(10, 8, math.radians(45.0), 10)
    assert cands.n_views == 9 * 9 * HEADINGS
    f = cands.footprints
    per_view = np.zeros((cands.n_views, 100))
    np.add.at(per_view, (np.repeat(f.row_view, np.diff(f.indptr)), f.cells), f.share)
    assert per_view.max() <= 1.0 + 1e-12  # disjoint half-open wedges count a point once


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"planners": ("random", "greedy")}, "unknown planner(s) greedy"),
     ({"planners": ()}, "unknown planner(s) (none given)"),
     ({"planners": ("survey", "survey")}, "names a planner twice"),
     ({"views": 0}, "at least 1 view"),
     ({"travel_cost": -0.5}, "--travel-cost must be a number >= 0"),
     ({"settings": ((0.1, 1.5),)}, "--pfn must be rates in [0, 1]"),
     ({"settings": ()}, "at least one detector setting"),
     ({"fusion": ("bayes",)}, "--fusion: unknown rule")],
)  # fmt: skip
def test_bad_configs_are_one_line_input_errors(kwargs, match):
    with pytest.raises(InputError, match=re.escape(match)) as info:
        ActiveConfig(**kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("argv", "match"),
    [(["--active", "random,astar"], "unknown planner(s) astar"),
     (["--active", "random", "--occluders", "0.1"], "leave out --occluders"),
     (["--active", "random", "--scores", "beta"], "leave out --occluders and --scores"),
     (["--travel-cost", "0.2"], "give --active too"),
     (["--active", "survey", "--views", "0,5"], "--views must be positive")],
)  # fmt: skip
def test_command_reports_bad_active_input_in_one_line(tmp_path, capsys, argv, match):
    code = main(["montecarlo", "--trials", "1", "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert match in err and len(err.splitlines()) == 1


def test_command_writes_the_comparison_csv_and_figure(tmp_path, capsys):
    out = tmp_path / "active"
    argv = ["montecarlo", "--active", "random,survey,coverage", "--grid", "8", "--views", "3,6",
            "--trials", "2", "--pfp", "0,0.2", "--pfn", "0.1", "--workers", "1", "--seed", "21",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "| 0.2, 0.1 | coverage | logodds |" in printed
    with (out / "active.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    keys = {(r["planner"], r["fusion"], r["pfp"], r["views"]) for r in rows}
    assert len(rows) == len(keys) == 3 * 2 * 2 * 6
    assert {r["trials"] for r in rows} == {"2"}
    assert all(0.0 <= float(r["success_rate"]) <= 1.0 for r in rows)
    survey = [r for r in rows if r["planner"] == "survey" and r["views"] == "6"]
    assert all(float(r["path_length"]) == 0.0 for r in survey)  # still at its first stop
    assert (out / "active.png").stat().st_size > 10_000
