"""Executors and chunked Monte Carlo sweeps: chunking, journaled resume, executor choice."""

import json

import numpy as np
import pytest

from twin.app.executors import InlineExecutor, ProcessExecutor, make_executor
from twin.app.montecarlo import (
    Chunk,
    SweepConfig,
    SweepJournal,
    missing_ranges,
    plan_chunks,
    run_setting,
    run_sweep,
)
from twin.cli import main
from twin.core.errors import InputError, TwinError

SWEEP = SweepConfig(pfp=(0.0, 0.4), pfn=(0.1, 0.5), views=(4, 9), trials=13, seed=5)


def successes(results):
    return [((r.pfp, r.pfn), r.successes.tolist()) for r in results]


def test_missing_ranges_are_the_uncovered_trials():
    assert missing_ranges(10, []) == [(0, 10)]
    assert missing_ranges(10, [(0, 3), (5, 7)]) == [(3, 5), (7, 10)]
    assert missing_ranges(10, [(0, 10)]) == []


def test_chunks_cover_every_missing_trial_once():
    chunks = plan_chunks(SWEEP, 5, {(0.0, 0.1): [(0, 5), (10, 13)]})
    first = [(c.start, c.stop) for c in chunks if c.setting == (0.0, 0.1)]
    assert first == [(5, 10)]
    other = [(c.start, c.stop) for c in chunks if c.setting == (0.4, 0.5)]
    assert other == [(0, 5), (5, 10), (10, 13)]
    with pytest.raises(InputError, match="--chunk"):
        plan_chunks(SWEEP, 0)


def test_results_do_not_depend_on_chunk_size_or_workers():
    whole = [run_setting(SWEEP, s) for s in SWEEP.settings()]
    for chunk in (1, 4, 13):
        assert successes(run_sweep(SWEEP, InlineExecutor(), chunk_trials=chunk)) == successes(whole)
    pooled = run_sweep(SWEEP, ProcessExecutor(2), chunk_trials=3)
    assert successes(pooled) == successes(whole)


def test_an_interrupted_chunked_sweep_runs_only_the_missing_trials(tmp_path):
    path = tmp_path / "settings.jsonl"

    class Interrupt(Exception):
        pass

    seen = []

    def stop_after_five(result):
        seen.append(result)
        if len(seen) == 5:
            raise Interrupt

    with pytest.raises(Interrupt):
        run_sweep(SWEEP, InlineExecutor(), SweepJournal(path, SWEEP), chunk_trials=4,
                  on_chunk=stop_after_five)  # fmt: skip
    lines = path.read_text().splitlines()
    assert len(lines) == 1 + 5  # the identity, then one line per finished chunk
    assert json.loads(lines[-1])["trials"] == [0, 4]  # the second setting's first chunk
    with path.open("a") as handle:
        handle.write('{"pfp": 0.4, "pfn": 0.1, "trials": [4, ')  # torn by a crash
    journal = SweepJournal(path, SWEEP)
    assert list(journal.done) == [(0.0, 0.1)]
    assert journal.ranges()[(0.0, 0.5)] == [(0, 4)]
    ran = []
    resumed = run_sweep(SWEEP, InlineExecutor(), journal, chunk_trials=5, on_chunk=ran.append)
    assert sum(c.chunk.stop - c.chunk.start for c in ran) == 4 * SWEEP.trials - 13 - 4
    assert successes(resumed) == successes(run_sweep(SWEEP, InlineExecutor()))
    again = []
    run_sweep(SWEEP, InlineExecutor(), SweepJournal(path, SWEEP), on_chunk=again.append)
    assert again == []  # a finished sweep runs nothing


def test_a_journal_of_whole_settings_still_resumes(tmp_path):
    path = tmp_path / "settings.jsonl"
    SweepJournal(path, SWEEP)
    first = run_setting(SWEEP, (0.0, 0.1))
    with path.open("a") as handle:  # the format before chunks: one line per setting
        entry = {"pfp": 0.0, "pfn": 0.1, "successes": first.successes.tolist()}
        handle.write(json.dumps(entry) + "\n")
    journal = SweepJournal(path, SWEEP)
    assert list(journal.done) == [(0.0, 0.1)]
    plan = plan_chunks(SWEEP, 100, journal.ranges())
    assert {c.setting for c in plan} == set(SWEEP.settings()) - {(0.0, 0.1)}


def test_a_duplicated_chunk_counts_once(tmp_path):
    journal = SweepJournal(None, SWEEP)
    from twin.app.montecarlo import run_chunk

    part = run_chunk(SWEEP, Chunk(0.0, 0.1, 0, 7))
    assert journal.record(part) is None
    assert journal.record(part) is None  # the same trials again: dropped
    done = journal.record(run_chunk(SWEEP, Chunk(0.0, 0.1, 7, 13)))
    np.testing.assert_array_equal(done.successes, run_setting(SWEEP, (0.0, 0.1)).successes)


def test_executor_choice_errors_are_one_line():
    with pytest.raises(InputError, match="--executor must be one of local, ray"):
        make_executor(2, "dask")
    with pytest.raises(InputError, match="add --executor ray"):
        make_executor(2, "local", "127.0.0.1:6379")
    assert isinstance(make_executor(1), InlineExecutor)


def test_joining_an_absent_cluster_fails_fast_in_one_line(tmp_path, capsys):
    pytest.importorskip("ray")
    code = main(["montecarlo", "--trials", "1", "--pfp", "0", "--pfn", "0", "--executor", "ray",
                 "--address", "127.0.0.1:9", "--out", str(tmp_path / "x")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "no Ray cluster answers at 127.0.0.1:9" in err


def test_ray_missing_is_a_one_line_error_naming_the_extra(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray":
            raise ImportError("no ray")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    with pytest.raises(TwinError, match=r"pip install '\.\[cluster\]'"):
        make_executor(2, "ray")


def test_command_resumes_a_chunked_sweep_and_reports_trials(tmp_path, capsys):
    out = tmp_path / "mc"
    argv = ["montecarlo", "--pfp", "0", "--pfn", "0,0.5", "--views", "3", "--trials", "6",
            "--chunk", "4", "--workers", "1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    lines = (out / "settings.jsonl").read_text().splitlines()
    assert len(lines) == 1 + 2 * 2  # two chunks (4 + 2 trials) per setting
    assert main(argv) == 0
    assert "2 of 2 settings done (12 of 12 trials)" in capsys.readouterr().out
