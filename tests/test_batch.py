"""twin batch-survey: randomized missions end to end, resume, reused worlds, the factors."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from twin.app import executors
from twin.app.batch import (
    BatchSpec,
    MissionDraw,
    MissionWorld,
    ThresholdedDetector,
    draw_mission,
    run_batch_mission,
)
from twin.cli import main
from twin.core.errors import InputError

DETERMINISTIC = ("run", "lighting", "threshold", "objects", "views")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The shipped mission cut to 1 stop x 2 views, no recording, a shared model cache: the
    --set overrides every batch here runs with."""
    cache = tmp_path_factory.mktemp("batch") / "cache"
    return ("mission.stops=[[2.5, 3.3]]", "mission.views_per_stop=2", "run.rerun=off",
            f"run.cache={cache}")  # fmt: skip


def set_args(sets) -> list[str]:
    return [arg for setting in sets for arg in ("--set", setting)]


def spec_for(sets, seed: int, **kwargs) -> BatchSpec:
    return BatchSpec.from_config(None, sets, seed=seed, **kwargs)


def runs(out: Path) -> dict[int, dict]:
    done = {}
    for line in (out / "runs.jsonl").read_text().splitlines()[1:]:
        try:
            entry = json.loads(line)
        except json.JSONDecodeError:
            continue  # the torn line a test wrote
        done[entry["run"]] = entry
    return done


def deterministic(result: dict) -> dict:
    return {k: result[k] for k in DETERMINISTIC}


@pytest.fixture(scope="module")
def batch_run(tiny, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch-out") / "b"
    argv = ["batch-survey", "--runs", "2", "--seed", "4", *set_args(tiny), "--out",
            str(out), "--workers", "1", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    return out, argv


def test_a_batch_writes_runs_summary_and_plots(batch_run):
    out, _ = batch_run
    done = runs(out)
    assert sorted(done) == [0, 1]
    for r in done.values():
        assert 0.5 <= r["lighting"] <= 1.5 and 0.0 <= r["threshold"] <= 0.5
        assert r["views"] == 2 and "error_m" in r["objects"]["rice_box"]
    assert done[0]["lighting"] != done[1]["lighting"]
    assert done[0]["objects"]["rice_box"]["truth_m"] != done[1]["objects"]["rice_box"]["truth_m"]
    with (out / "summary.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["run"]) for r in rows] == [0, 1]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"] == 2 and summary["tolerance_m"] == 0.3
    hits = sum(float(r["error_m"]) <= 0.3 for r in rows)
    assert summary["success_rate"] == hits / 2
    assert summary["error_m"]["max"] == max(float(r["error_m"]) for r in rows)
    for name in ("errors", "success_vs_target", "success_vs_lighting", "success_vs_threshold"):
        assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_batch_resumes_running_only_missing_runs(batch_run, capsys):
    out, argv = batch_run
    before = (out / "runs.jsonl").read_text()
    with (out / "runs.jsonl").open("a") as handle:
        handle.write('{"run": 2, "lighting": 0.')  # torn by a crash
    capsys.readouterr()
    more = [a if a != "2" else "3" for a in argv]
    more.remove("--quiet")
    assert main(more) == 0
    assert "2 of 3 runs done" in capsys.readouterr().out
    text = (out / "runs.jsonl").read_text()
    assert text.startswith(before)  # the finished runs were neither rerun nor rewritten
    assert sorted(runs(out)) == [0, 1, 2]
    assert len(text.splitlines()) == 1 + 2 + 1 + 1  # header, 2 runs, the torn line, run 2


def test_a_reused_world_gives_the_same_mission_as_a_fresh_one(batch_run, tiny):
    out, _ = batch_run
    spec = spec_for(tiny, 4)
    reused = runs(out)[1]
    assert reused["reused_world"]  # run 1 ran in the world run 0 left behind
    executors._KEPT.clear()  # a worker that has not run a mission of this batch yet
    fresh = run_batch_mission(spec, 1)
    assert not fresh["reused_world"]
    assert deterministic(fresh) == deterministic(reused)


def test_a_batch_with_other_parameters_is_refused(batch_run, capsys):
    _, argv = batch_run
    other = [a if a != "4" else "5" for a in argv]
    assert main(other) == 2
    err = capsys.readouterr().err.strip()
    assert "other parameters (seed)" in err and len(err.splitlines()) == 1


def test_draws_depend_on_seed_run_and_factor_only(tiny):
    spec = spec_for(tiny, 9)
    assert draw_mission(spec, 3) == draw_mission(spec, 3)
    assert draw_mission(spec, 3) != draw_mission(spec, 4)
    lighting_only = spec_for(tiny, 9, vary=("lighting",))
    assert draw_mission(lighting_only, 3).lighting == draw_mission(spec, 3).lighting
    assert draw_mission(lighting_only, 3).threshold == 0.0
    assert not draw_mission(lighting_only, 3).place_target
    assert draw_mission(lighting_only, 3).camera_seed is None  # the config's camera seed
    cameras = {draw_mission(spec, run).camera_seed for run in range(5)}
    assert len(cameras) == 5 and None not in cameras


def test_lighting_scales_the_rendered_image(tiny):
    # the ideal camera: the realistic one's auto exposure makes up for the light, as it should
    spec = spec_for((*tiny, "robot.camera.effects=ideal"), 0, vary=("lighting",))
    world = MissionWorld(spec)
    try:
        means = []
        for scale in (0.5, 1.5):
            world.reset(spec, MissionDraw(0, scale, 0.0, False))
            means.append(float(world.robot.capture().image.mean()))
        assert means[1] > means[0] + 20  # out of 255
    finally:
        world.close()


def test_the_threshold_zeroes_patch_scores_below_it():
    class Fixed:
        names = ("a",)

        def scores(self, image):
            return np.array([[[0.1, 0.6], [0.3, 0.2]]])

    out = ThresholdedDetector(Fixed(), 0.25).scores(None)
    np.testing.assert_array_equal(out, [[[0.0, 0.6], [0.3, 0.0]]])
    np.testing.assert_array_equal(ThresholdedDetector(Fixed(), 0.0).scores(None), Fixed().scores(0))


@pytest.mark.parametrize(
    ("argv", "match"),
    [(["--vary", "target,weather"], "--vary: unknown factor 'weather'"),
     (["--lighting", "0,1"], "--lighting must be LOW,HIGH with 0 < LOW"),
     (["--threshold", "0.5,0.2"], "--threshold must be LOW,HIGH within [0, 1]"),
     (["--runs", "0"], "--runs must be at least 1")],
)  # fmt: skip
def test_bad_batch_input_is_one_line(tmp_path, capsys, tiny, argv, match):
    code = main(["batch-survey", *set_args(tiny), "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert match in err and len(err.splitlines()) == 1


def test_a_spec_rejects_a_hardware_config(tiny):
    with pytest.raises(InputError, match="simulation only"):
        spec_for((*tiny, "robot.camera.type=opencv"), 0)


def test_a_batch_out_that_is_not_a_batch_is_refused(tmp_path, tiny, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    code = main(["batch-survey", *set_args(tiny), "--out", str(tmp_path), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "holds files that are not a twin batch-survey (e.g. notes.txt)" in err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_an_interrupted_batch_summarizes_the_runs_it_finished(tmp_path, tiny, monkeypatch):
    import twin.app.batch as batch

    real = batch.run_batch_mission

    def second_run_interrupted(spec, run):
        if run == 1:
            raise KeyboardInterrupt
        return real(spec, run)

    monkeypatch.setattr(batch, "run_batch_mission", second_run_interrupted)
    out = tmp_path / "b"
    argv = ["batch-survey", "--runs", "3", "--seed", "4", *set_args(tiny), "--out", str(out),
            "--workers", "1", "--quiet"]  # fmt: skip
    assert main(argv) == 130
    assert sorted(runs(out)) == [0]
    with (out / "summary.csv").open() as handle:
        assert [int(r["run"]) for r in csv.DictReader(handle)] == [0]
    monkeypatch.setattr(batch, "run_batch_mission", real)
    assert main(argv) == 0  # the same command finishes the batch
    assert sorted(runs(out)) == [0, 1, 2]


def test_a_batch_of_searches_reports_views_path_time_and_why_each_stopped(tmp_path, tiny):
    out = tmp_path / "s"
    sets = (*tiny, "search.spacing_m=0.8", "search.max_views=3")
    argv = ["batch-survey", "--runs", "2", "--seed", "5", *set_args(sets), "--out", str(out),
            "--workers", "1", "--quiet", "--mission", "search",
            "--planner", "coverage"]  # fmt: skip
    assert main(argv) == 0
    for entry in runs(out).values():
        assert entry["search"]["planner"] == "coverage" and 1 <= entry["views"] <= 3
        assert entry["search"]["stopped"] and entry["time_s"] > 0 and entry["path_length_m"] >= 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mission"] == "search" and set(summary["views"]) == {"median", "p90", "mean"}
    assert main([*argv[:-2], "--planner", "random", "--mission", "survey"]) == 2


def test_a_run_the_robot_cannot_finish_is_a_failed_run_not_a_failed_batch(
    tmp_path, tiny, monkeypatch
):
    from twin.app.mission import Mission
    from twin.core.devices import DeviceFaultError

    real = Mission.observe

    def bumps_on_the_second_view(self, target):
        if self.views_done == 1:
            raise DeviceFaultError("sim base", "go to (1, 1) m", "contact", "choose a stop")
        return real(self, target)

    monkeypatch.setattr(Mission, "observe", bumps_on_the_second_view)
    out = tmp_path / "b"
    argv = ["batch-survey", "--runs", "2", "--seed", "4", *set_args(tiny), "--out", str(out),
            "--workers", "1", "--quiet", "--tolerance", "100"]  # fmt: skip
    assert main(argv) == 0
    for entry in runs(out).values():
        assert entry["views"] == 1 and "contact" in entry["failed"]
    with (out / "summary.csv").open() as handle:
        assert [r["success"] for r in csv.DictReader(handle)] == ["0", "0"]


def test_the_report_scores_every_object_in_the_plan_and_in_height():
    """Two objects in two runs: each object's own row and rate; a height tolerance fails an
    object whose height is off or unknown, however good its plan estimate."""
    from twin.app.batch import BatchSpec
    from twin.app.batch_report import summarize, summary_rows

    def entry(error, height_error):
        out = {"estimate_m": [1.0, 2.0, 0.5], "truth_m": [1.1, 2.0, 0.6], "error_m": error,
               "peak": 1.0, "peak_ratio": 2.0}  # fmt: skip
        if height_error is not None:
            out["height_error_m"] = height_error
        return out

    timings = dict.fromkeys(("setup", "move", "capture", "detect", "fuse", "mission"), 1.0)
    results = [
        {"run": 0, "lighting": 1.0, "threshold": 0.0, "views": 40, "reused_world": False,
         "timings_s": timings, "objects": {"box": entry(0.1, 0.05), "tin": entry(0.2, 0.3)}},
        {"run": 1, "lighting": 1.0, "threshold": 0.0, "views": 40, "reused_world": True,
         "timings_s": timings, "objects": {"box": entry(0.5, 0.01), "tin": entry(0.1, None)}},
    ]  # fmt: skip
    plan_only = summary_rows(results, 0.3)
    assert [(r["run"], r["object"], r["success"]) for r in plan_only] == [
        (0, "box", 1), (0, "tin", 1), (1, "box", 0), (1, "tin", 1),
    ]  # fmt: skip
    spec = BatchSpec("", "x.toml", ".", ".", height_tolerance=0.1)
    summary = summarize(spec, results)
    assert summary["runs"] == 2 and summary["target"] == ["box", "tin"]
    assert summary["objects"]["box"]["success_rate"] == 0.5  # run 1: 0.5 m off in the plan
    assert summary["objects"]["tin"]["success_rate"] == 0.0  # 0.3 m off in height; unknown
    assert summary["success_rate"] == 0.25
    assert summary["objects"]["tin"]["height_error_m"]["unknown"] == 1
    assert summary["height_error_m"]["max"] == 0.3
    with pytest.raises(InputError, match="--height-tolerance"):
        BatchSpec("", "x.toml", ".", ".", height_tolerance=0.0)
