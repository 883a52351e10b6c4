"""The paper's Section 3 Monte Carlo: its statements, reproducibility, resuming, the command."""

import csv
import math

import numpy as np
import pytest

from twin.app.executors import InlineExecutor, ProcessExecutor
from twin.app.montecarlo import (
    KERNEL_RULES,
    RESULT_COLUMNS,
    SweepConfig,
    SweepJournal,
    _wedge_meets_cell,
    draw_trial,
    run_setting,
    run_sweep,
    trial_rng,
)
from twin.cli import main
from twin.core.errors import InputError

# 400 trials: a 95 % interval of about +-5 points on a rate near 50 %.
FIRM = SweepConfig(trials=400, views=(10, 25, 150))


def rate(result, rule, views):
    return result.successes[KERNEL_RULES.index(rule), FIRM.checkpoints.index(views)] / FIRM.trials


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
    for rule in KERNEL_RULES:
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


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"pfp": (1.5,)}, "--pfp"), ({"pfn": (-0.1,)}, "--pfn"), ({"views": (0,)}, "--views"),
     ({"trials": 0}, "--trials"), ({"wedges": 0}, "--wedges"), ({"grid": 2}, "--grid"),
     ({"fov": 0.0}, "--fov-deg"), ({"supersample": 0}, "--supersample"),
     ({"fusion": ("bayes",)}, "--fusion"), ({"seed": -1}, "--seed")],
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
