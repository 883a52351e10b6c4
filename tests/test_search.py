"""Active search (twin.app.candidates, twin.app.search, twin search): candidates, costs,
planners, stopping, and the command end to end."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from twin.app.candidates import (
    Candidates,
    build_candidates,
    candidates_key,
    detection_rates,
    disjoint_columns,
    lattice_places,
    load_candidates,
    save_candidates,
)
from twin.app.search import (
    GainPlanner,
    Moves,
    RandomPlanner,
    Situation,
    TimeModel,
    moves,
    path_length,
)
from twin.cli import main
from twin.core.devices import VCC4_LIMITS, BaseLimits
from twin.core.geometry import CameraModel, Pose2D
from twin.core.grid import GridSpec
from twin.rfch.calibration import ScoreCalibration

CAMERA = CameraModel()  # 320 x 240, 45 degrees
SPANS = np.array([[u, u + 32] for u in range(0, 289, 16)], dtype=float)  # the detector's
SPEC = GridSpec(0.0, 0.0, 10.0, 10.0, 0.1)


@pytest.fixture(scope="module")
def open_floor() -> Candidates:
    """Two places in an empty 10 m square, 8 headings, wedges reaching 2 m, all seen."""
    places = np.array([[5.0, 5.0], [2.0, 5.0]])
    return build_candidates(places, 8, SPEC, CAMERA, SPANS, None, reach=2.0)


def test_only_columns_that_do_not_overlap_are_kept():
    keep = disjoint_columns(SPANS)
    spans = SPANS[keep]
    assert len(keep) == 10 and spans[0, 0] == 0 and spans[-1, 1] == 320
    assert np.all(spans[1:, 0] >= spans[:-1, 1])


def test_a_views_footprint_is_its_wedge(open_floor):
    """Every view of the open floor covers the wedge's area (45 degrees, 2 m: 1.57 m^2), each
    cell at most once, and only cells within 2 m of its place."""
    f = open_floor.footprints
    per_view = np.bincount(f.row_view[np.repeat(np.arange(f.rows), np.diff(f.indptr))],
                           weights=f.share, minlength=f.n_views)  # fmt: skip
    wedge = math.pi * 2.0**2 * 45 / 360 / 0.1**2
    assert np.allclose(per_view[:8], wedge, rtol=0.06)
    assert np.all(open_floor.distance <= 2.0 + 0.08)
    view = 3  # place 0 facing 135 degrees: its cells lie up and to the left
    rows = np.flatnonzero(f.row_view == view)
    cells = np.concatenate([f.cells[f.indptr[r] : f.indptr[r + 1]] for r in rows])
    ys, xs = np.divmod(cells, SPEC.nx)
    assert np.all(xs <= 50) and np.all(ys >= 50)
    dense = np.zeros(SPEC.nx * SPEC.ny)
    for r in rows:
        np.add.at(
            dense, f.cells[f.indptr[r] : f.indptr[r + 1]], f.share[f.indptr[r] : f.indptr[r + 1]]
        )
    assert dense.max() <= 1.0 + 1e-9


def test_candidates_are_cached_by_key(tmp_path, open_floor):
    path = tmp_path / "c.npz"
    save_candidates(path, open_floor, "abc")
    loaded = load_candidates(path, "abc")
    assert loaded is not None and loaded.n_views == open_floor.n_views
    assert np.allclose(loaded.footprints.share, open_floor.footprints.share, atol=1e-6)
    assert load_candidates(path, "other") is None  # stale: rebuilt, never misused
    path.write_bytes(b"not a cache")
    assert load_candidates(path, "abc") is None
    scene = tmp_path / "scene.xml"
    scene.write_text("<mujoco/>")
    assert candidates_key(scene, spacing=0.4) != candidates_key(scene, spacing=0.5)


def test_the_lattice_keeps_only_places_the_robot_fits():
    blocked = np.zeros((40, 40), dtype=bool)
    blocked[:, 20:] = True
    places = lattice_places(blocked, (0.0, 0.0), 0.05, 0.4)
    assert len(places) == 2 * 5 and np.all(places[:, 0] < 1.0)  # 2 m square, left half free


def test_detection_rates_take_the_best_threshold_and_each_bands_rate():
    calibration = ScoreCalibration(
        edges=(0.0, 0.25, 0.5, 0.75, 1.0),
        on_counts=(5, 5, 40, 50),
        off_counts=(500, 300, 20, 5),
        ranges=(2.0,),
        range_on_counts=((1, 1, 20, 30), (4, 4, 20, 20)),
    )
    rates = detection_rates(calibration)
    assert rates.threshold == 0.5
    assert rates.fpr == pytest.approx(25 / 825)
    assert rates.tpr == pytest.approx((50 / 52, 40 / 48))
    assert rates.tpr_at(np.array([1.0, 3.0])) == pytest.approx([50 / 52, 40 / 48])


TIMING = TimeModel(BaseLimits(), VCC4_LIMITS, leg_overhead=1.0, drive_speed=1.0)


def test_drive_and_turn_times_follow_the_speed_profile():
    short, ramp, long = TIMING.drive(np.array([0.1, 0.5**2 / 0.6, 3.0]))
    assert short == pytest.approx(2 * math.sqrt(0.1 / 0.6))
    assert ramp == pytest.approx(
        2 * math.sqrt(ramp * 0.6 / 0.6**2) * 0 + 0.5 / 0.6 * 2
    )  # continuous
    assert long == pytest.approx(3.0 / 0.5 + 0.5 / 0.6)
    assert TIMING.pan(np.array([math.pi / 2]))[0] == pytest.approx(1.0)  # 90 deg/s


def test_a_view_from_here_is_a_pan_within_reach_and_a_turn_beyond(open_floor):
    here = Pose2D(5.0, 5.0, 0.0)
    m = moves(open_floor, here, 0.0, np.array([0.0, 3.0]), TIMING)
    # place 0 is here: heading 45 deg is a pan, 180 deg needs the base to turn 85 deg
    assert m.metres[1] == 0 and m.pan[1] == pytest.approx(math.pi / 4)
    assert m.seconds[1] == pytest.approx(TIMING.pan(np.array([math.pi / 4]))[0])
    reach = TIMING.pan_reach
    assert abs(m.pan[4]) == pytest.approx(reach)
    assert abs(m.base_yaw[4]) == pytest.approx(math.pi - reach)
    assert m.seconds[4] > m.seconds[1]
    # place 1 is 3 m away: a drive, facing the heading with the head straight
    assert m.metres[8] == 3.0 and m.pan[8] == 0.0 and m.base_yaw[8] == 0.0
    assert m.seconds[8] > TIMING.drive(np.array([3.0]))[0]
    unreachable = moves(open_floor, here, 0.0, np.array([0.0, np.inf]), TIMING)
    assert np.all(np.isinf(unreachable.seconds[8:])) and np.all(
        np.isfinite(unreachable.seconds[:8])
    )


def situation(candidates: Candidates, posterior: np.ndarray | None, taken=()) -> Situation:
    n = candidates.n_views
    mask = np.zeros(n, dtype=bool)
    mask[list(taken)] = True
    m = Moves(np.full(n, 2.0), np.zeros(n), np.zeros(n), np.zeros(n))
    posteriors = {} if posterior is None else {"box": posterior}
    return Situation(0, Pose2D(5.0, 5.0, 0.0), m, mask, 1, posteriors, np.zeros(SPEC.shape))


def test_the_information_planner_looks_where_the_belief_is_unsure(open_floor):
    """Half the mass in one cell 1 m north-east of place 0, half spread elsewhere: the view
    that can settle it faces north-east from place 0; once taken, it is not taken again."""
    rates = {"box": detection_rates(ScoreCalibration((0.0, 0.5, 1.0), (10, 90), (90, 10)))}
    prints = {"box": open_floor.for_detector(rates["box"])}
    planner = GainPlanner("information", open_floor, prints, rates, view_time=1.0)
    cells = np.full(SPEC.shape, 0.5 / (SPEC.nx * SPEC.ny - 1))
    row, col = 57, 57  # (5.75, 5.75) m
    cells[row, col] = 0.5
    choice = planner.choose(situation(open_floor, cells))
    assert choice.index == 1 and "information" in choice.why  # place 0, heading 45 degrees
    again = planner.choose(situation(open_floor, cells, taken=[1]))
    assert again.index != 1
    assert planner.choose(situation(open_floor, cells, taken=range(16))) is None


def test_the_random_planner_is_reproducible_per_view(open_floor):
    planner = RandomPlanner(open_floor, seed=3)
    first = planner.choose(situation(open_floor, None))
    assert planner.choose(situation(open_floor, None)).index == first.index
    other = RandomPlanner(open_floor, seed=4)
    base = situation(open_floor, None)
    draws = {other.choose(replace(base, views_done=k)).index for k in range(8)}
    assert len(draws) > 1


def test_path_length_follows_the_map_round_obstacles():
    from twin.nav.maps import OccupancyMap
    from twin.nav.planner import PathPlanner

    cells = np.zeros((60, 60))
    cells[0:50, 29:31] = 1.0  # a wall from the bottom, open at the top
    planner = PathPlanner(OccupancyMap(cells, 0.05), radius=0.1, margin=0.0)
    straight = path_length(planner, [(0.5, 0.5, 0.0), (2.5, 0.5, 0.0)])
    assert straight > 2 * (2.5 - 0.5)  # up round the wall's end and down again
    assert path_length(planner, [(0.5, 0.5, 0.0), (0.55, 0.5, 1.0)]) == pytest.approx(0.05)


# -- the command in the twin -------------------------------------------------------------------

SMALL = ("search.spacing_m=0.8", "search.max_views=6")


def search_argv(out, cache, *sets: str) -> list[str]:
    argv = ["search", "--out", str(out), "--quiet"]
    for setting in (f"run.cache={cache}", "run.rerun=off", *SMALL, *sets):
        argv += ["--set", setting]
    return argv


@pytest.fixture(scope="module")
def search_run(tmp_path_factory, model_cache):
    out = tmp_path_factory.mktemp("search") / "run"
    assert main(search_argv(out, model_cache, "run.rerun=save")) == 0
    return out


def test_a_search_reports_its_views_path_time_and_why_it_stopped(search_run):
    result = json.loads((search_run / "result.json").read_text())
    assert result["status"] == "complete" and result["mission"] == "search"
    assert 1 <= result["views"] <= 6
    search = result["search"]
    assert search["planner"] == "information"
    if result["views"] < 6:
        assert search["stopped"].startswith("found rice_box")
        assert result["objects"]["rice_box"]["confidence"] >= 0.95
    else:
        assert search["stopped"] in ("view budget spent (6 views)",) or "found" in search["stopped"]
    assert result["path_length_m"] >= 0 and result["time_s"] == result["robot_time_s"] > 0


def test_the_recording_says_why_each_view_was_chosen(search_run):
    from rerun.chunk import RrdReader

    store = RrdReader(search_run / "recording.rrd").store()
    entities = set(store.schema().entity_paths())
    assert {"/plan/why", "/top/map/plan/next", "/top/map/plan/options"} <= entities


def test_every_planner_runs_and_a_finished_search_is_not_run_again(
    tmp_path, model_cache, search_run, capsys
):
    for planner in ("coverage", "random", "survey", "detection"):
        out = tmp_path / planner
        assert (
            main([*search_argv(out, model_cache, "search.max_views=2"), "--planner", planner]) == 0
        )
        result = json.loads((out / "result.json").read_text())
        assert result["search"]["planner"] == planner and 1 <= result["views"] <= 2
    capsys.readouterr()
    assert main(["search", "--resume", str(search_run)]) == 0
    assert "nothing to resume" in capsys.readouterr().out


def test_search_without_a_map_is_refused_in_one_line(tmp_path, model_cache, capsys):
    code = main(search_argv(tmp_path / "x", model_cache, "robot.base.pose_source=truth"))
    err = capsys.readouterr().err
    assert code == 2 and "pose_source" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_a_cell_seen_facing_one_way_is_worth_less_seen_that_way_again(open_floor):
    """The same belief; once the cells north-east of place 0 were seen facing north-east, the
    same view again is worth less, and views facing elsewhere are not discounted."""
    rates = {"box": detection_rates(ScoreCalibration((0.0, 0.5, 1.0), (10, 90), (90, 10)))}
    prints = {"box": open_floor.for_detector(rates["box"])}
    planner = GainPlanner("information", open_floor, prints, rates, 1.0, repeat_discount=0.5)
    cells = np.full(SPEC.nx * SPEC.ny, 1.0 / (SPEC.nx * SPEC.ny))
    before = situation(open_floor, cells)
    fresh = planner.gains(before)
    repeats = np.zeros((SPEC.nx * SPEC.ny, 8))
    f = open_floor.footprints
    rows = np.flatnonzero(f.row_view == 1)  # place 0 facing 45 degrees
    span = slice(f.indptr[rows[0]], f.indptr[rows[-1] + 1])
    np.add.at(repeats[:, 1], f.cells[span], f.share[span])
    after = planner.gains(replace(before, views_done=1, repeats=repeats))
    assert after[1] < 0.6 * fresh[1]  # the same view again: half its news or less
    assert after[8 + 1] == pytest.approx(fresh[8 + 1])  # place 1's cells were not seen
    assert after[4] == pytest.approx(fresh[4])  # facing the other way: all news


def test_a_place_the_base_refuses_is_struck_off_and_the_search_goes_on(
    tmp_path, model_cache, monkeypatch
):
    from twin.app.mission import Mission
    from twin.core.devices import DeviceFaultError

    real, refused = Mission.observe, []

    def refuses_once(self, target):
        if self.views_done == 1 and not refused:
            refused.append(target)
            raise DeviceFaultError("sim base", "go to", "the laser sees something", "clear it")
        return real(self, target)

    monkeypatch.setattr(Mission, "observe", refuses_once)
    out = tmp_path / "run"
    assert main(search_argv(out, model_cache, "search.max_views=3", "search.confidence=1.0")) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["views"] == 3 and result["search"]["stopped"] == "view budget spent (3 views)"
    (entry,) = result["search"]["unreachable"]
    assert entry["view"] == 1 and "laser sees something" in entry["reason"]
    assert math.dist(entry["place_m"], (refused[0].base.x, refused[0].base.y)) < 0.2


def test_the_command_lines_planners_are_the_configs():
    import typing

    from twin.app.config import SearchOptions
    from twin.app.planner_names import PLANNERS

    hints = typing.get_type_hints(SearchOptions)
    assert typing.get_args(hints["planner"]) == PLANNERS


def test_a_search_not_sure_after_its_views_flies_the_fixed_plan(open_floor):
    from twin.app.search import FallingBackPlanner
    from twin.app.survey import PlannedView

    plan = [PlannedView(k, k // 2, Pose2D(1.0 + k, 2.0, 0.0), 0.1 * k) for k in range(4)]
    planner = FallingBackPlanner(RandomPlanner(open_floor, seed=1), plan, after=3)
    base = situation(open_floor, None)

    def at(views: int):
        return planner.choose(replace(base, views_done=views))

    assert at(2).index >= 0 and at(2).why.startswith("random")
    for views, k in ((3, 0), (4, 1), (6, 3)):
        choice = at(views)
        assert choice.index == -1 and choice.base == plan[k].base and choice.pan == plan[k].pan
        assert "had not settled after 3 views" in choice.why
    assert at(7) is None  # the plan is spent: the search stops with no view left


# -- the survey's follow-up --------------------------------------------------------------------

ONE_STOP = ("mission.stops=[[2.5, 3.3]]", "mission.views_per_stop=4", "search.spacing_m=0.8")


def survey_argv(out, cache, *sets: str) -> list[str]:
    argv = ["survey", "--out", str(out), "--quiet"]
    for setting in (f"run.cache={cache}", "run.rerun=off", *ONE_STOP, *sets):
        argv += ["--set", setting]
    return argv


def test_a_surveys_follow_up_looks_again_while_in_doubt_within_its_budget(tmp_path, model_cache):
    """In doubt at any ratio (100): exactly the budget's views after the plan's, each a view
    the planner chose and said why."""
    from rerun.chunk import RrdReader

    doubtful = tmp_path / "doubtful"
    sets = ("search.follow_up_views=2", "search.follow_up_ratio=100", "run.rerun=save")
    assert main(survey_argv(doubtful, model_cache, *sets)) == 0
    result = json.loads((doubtful / "result.json").read_text())
    assert result["status"] == "complete" and result["views_planned"] == 4 + 2
    assert result["views"] == 6 and result["follow_up"]["views"] == 2
    assert result["follow_up"]["planner"] == "detection"
    assert result["follow_up"]["stopped"] == "view budget spent (6 views)"
    reader = RrdReader(doubtful / "recording.rrd")
    assert {"/plan/why", "/top/map/plan/next"} <= set(reader.store().schema().entity_paths())
    said = [
        line
        for chunk in reader.stream()
        if chunk.entity_path == "/plan/why"
        for (line,) in chunk.to_record_batch().column("TextLog:text").to_pylist()
    ]
    assert len(said) == 2, said
    assert all("rice_box's contenders" in line for line in said), said
    seen = [int(line.split(" % of rice_box")[0].rsplit(" ", 1)[1]) for line in said]
    assert all(0 <= share <= 100 for share in seen), said  # a cell seen twice is seen once
    # The layout shows the log once the follow-up chooses (sent again then): first without.
    layouts = [_view_names(reader.stream(store=store)) for store in reader.blueprints()]
    why = "why this view (detection, after the plan)"
    assert any(why in names for names in layouts) and not all(why in n for n in layouts)


def _view_names(stream) -> set[str]:
    """The names of the views in one of a recording's layouts (blueprints)."""
    names = set()
    for chunk in stream:
        batch = chunk.to_record_batch()
        for column in batch.schema.names:
            if column.endswith("display_name") or column.endswith(":name"):
                for value in batch.column(column).to_pylist():
                    names |= set(value) if isinstance(value, list) else {value}
    return names


def test_a_surveys_follow_up_resumes_where_it_stopped(tmp_path, model_cache, monkeypatch):
    """Interrupted after the plan and one follow-up view, the run resumes with the follow-up
    (the plan is not flown again) and ends with the budget's views."""
    from twin.app import search

    out = tmp_path / "run"
    sets = ("search.follow_up_views=2", "search.follow_up_ratio=100")
    real_take = search.Searcher.take

    def interrupted(self, choice):
        if self.mission.views_done >= 5:
            raise KeyboardInterrupt
        return real_take(self, choice)

    monkeypatch.setattr(search.Searcher, "take", interrupted)
    assert main(survey_argv(out, model_cache, *sets)) != 0
    assert json.loads((out / "result.json").read_text())["views"] == 5
    monkeypatch.setattr(search.Searcher, "take", real_take)
    assert main(["survey", "--resume", str(out), "--quiet"]) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["status"] == "complete" and result["views"] == 6
    assert result["follow_up"]["views"] == 1  # this session's: the plan was not flown again


def test_doubts_weigh_the_peaks_that_come_within_the_ratio_equally():
    """An object whose peaks read 0.6, 0.5, 0.3 is in doubt between the first two at ratio 1.5
    (0.3 is not within it), and not in doubt at ratio 1.1; one at 0.9 over 0.3 is in none. A
    chosen peak that is not the strongest is the one compared, and the stronger one passed
    over (its height fits no surface there) is no contender."""
    from types import SimpleNamespace

    from twin.app.mission import Located
    from twin.app.search import doubts
    from twin.core.grid import AccumulatorGrid, Peak, Peaks

    grid = AccumulatorGrid(["box", "tin"], GridSpec(0.0, 0.0, 2.0, 2.0, 0.1))
    box = Peaks((Peak(3, 3, 0.35, 0.35, 0.6), Peak(15, 4, 0.45, 1.55, 0.5),
                 Peak(9, 9, 0.95, 0.95, 0.3)))  # fmt: skip
    tin = Peaks((Peak(1, 1, 0.15, 0.15, 0.9), Peak(12, 12, 1.25, 1.25, 0.3)))
    located = {"box": Located(box.peaks[0], None, box), "tin": Located(tin.peaks[0], None, tin)}
    mission = SimpleNamespace(grid=grid, located=lambda separation: located)
    out = doubts(mission, 1.5, 0.5)
    assert set(out) == {"box"}
    assert out["box"][3, 3] == out["box"][15, 4] == 0.5 and out["box"].sum() == 1.0
    assert doubts(mission, 1.1, 0.5) == {}
    passed_over = {"box": Located(box.peaks[1], None, box, ((box.peaks[0], 1.9),))}
    mission = SimpleNamespace(grid=grid, located=lambda separation: passed_over)
    assert doubts(mission, 1.5, 0.5) == {}  # 0.5 over its next, 0.3: 1.67
    chosen = doubts(mission, 2.0, 0.5)["box"]
    assert chosen[15, 4] == chosen[9, 9] == 0.5 and chosen[3, 3] == 0.0


def test_a_follow_up_weighs_each_contender_by_the_looks_it_has_had():
    """Each view adds what it sees, a look-alike's score too: once the follow-up has looked at
    one contender, the other weighs more, until both have had their look."""
    from types import SimpleNamespace

    from twin.app.mission import Located
    from twin.app.search import DoubtSearcher
    from twin.core.grid import AccumulatorGrid, Peak, Peaks

    grid = AccumulatorGrid(["box"], GridSpec(0.0, 0.0, 4.0, 4.0, 0.1))
    near, far = Peak(5, 5, 0.55, 0.55, 0.6), Peak(35, 5, 0.55, 3.55, 0.5)
    peaks = Peaks((near, far))
    mission = SimpleNamespace(
        grid=grid, located=lambda _: {"box": Located(near, None, peaks)}, views_done=0
    )
    searcher = DoubtSearcher.__new__(DoubtSearcher)  # its planning parts are not needed here
    searcher.mission, searcher.ratio, searcher.peak_separation = mission, 1.5, 0.5
    searcher._seen_before, searcher._doubts = {"box": grid.observed("box")}, None
    even = searcher.contenders()["box"]
    assert even[5, 5] == even[35, 5] == 0.5
    # a look from beside the near contender, toward it (a wedge of 0.2 rad)
    bearing = math.atan2(0.55 - 0.2, 0.55 - 0.2)
    wedge = np.array([[bearing - 0.1, bearing + 0.1]])
    grid.fuse_all((0.2, 0.2), wedge, {"box": np.ones(1)}, max_range=1.0)
    assert grid.observed("box")[5, 5] > 0.5 and grid.observed("box")[35, 5] == 0.0
    looked = searcher.contenders()["box"]
    assert looked[35, 5] > 0.6 > looked[5, 5] > 0.0 and looked.sum() == pytest.approx(1.0)


def test_a_survey_in_no_doubt_takes_no_follow_up_view():
    """Every object's first peak over the ratio times its next: no view is taken, and no
    candidate view is priced (no map is needed for it)."""
    from types import SimpleNamespace

    from twin.app.config import load_config
    from twin.app.mission import Located
    from twin.app.search import follow_up
    from twin.core.grid import AccumulatorGrid, Peak, Peaks

    config = load_config(None, overrides=["search.follow_up_views=2"])
    grid = AccumulatorGrid(["box"], GridSpec(0.0, 0.0, 4.0, 4.0, 0.1))
    peaks = Peaks((Peak(5, 5, 0.55, 0.55, 0.9), Peak(35, 5, 0.55, 3.55, 0.5)))
    mission = SimpleNamespace(
        grid=grid, located=lambda _: {"box": Located(peaks.peaks[0], None, peaks)}, views_done=4
    )
    done = follow_up(config, mission, world=None, plan=[])
    assert done == {"planner": "detection", "stopped": "no doubt left (every object's first "
                    "peak over 1.5x its next)", "views": 0, "unreachable": []}  # fmt: skip
    assert follow_up(load_config(None), mission, world=None, plan=[]) is None  # none asked


def test_a_follow_up_needs_every_model_calibrated():
    """It weighs views by each model's detection rates: a model without a calibration is named,
    with the remedy, in one line."""
    from types import SimpleNamespace

    from twin.app.search import check_follow_up
    from twin.core.errors import InputError

    calibration = ScoreCalibration((0.0, 0.5, 1.0), (10, 90), (90, 10))
    calibrated = SimpleNamespace(name="box", calibration=calibration)
    check_follow_up(SimpleNamespace(models=[calibrated]))
    bare = SimpleNamespace(name="tin", calibration=None)
    with pytest.raises(InputError, match=r"'tin' has none: store one with 'twin roc --store'"):
        check_follow_up(SimpleNamespace(models=[calibrated, bare]))
