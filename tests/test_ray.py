"""Ray against the local executor: the same seed gives the same results (one local cluster)."""

from functools import partial
from pathlib import Path

import numpy as np
import pytest

from twin.app.batch import run_batch
from twin.app.executors import InlineExecutor, RayExecutor
from twin.app.montecarlo import SweepConfig, plan_chunks, run_sweep
from twin.core.errors import InputError

pytest.importorskip("ray")

from test_batch import deterministic, spec_for


@pytest.fixture(scope="module")
def ray_executor():
    """A private local cluster of 2 CPUs on loopback, no dashboard, 100 MB object store."""
    executor = RayExecutor(workers=2)
    yield executor
    executor.close()


def test_a_ray_sweep_equals_the_local_one(ray_executor):
    config = SweepConfig(pfp=(0.0, 0.3, 0.6), pfn=(0.0, 0.5), views=(5, 15), trials=12, seed=11)
    local = run_sweep(config, InlineExecutor())
    arrived = []
    remote = run_sweep(config, ray_executor, chunk_trials=5, on_chunk=arrived.append)
    assert len(arrived) == len(config.settings()) * 3  # 5 + 5 + 2 trials per setting
    for a, b in zip(local, remote, strict=True):
        assert (a.pfp, a.pfn) == (b.pfp, b.pfn)
        np.testing.assert_array_equal(a.successes, b.successes)


def test_a_task_error_reaches_the_caller_as_itself(ray_executor):
    # A module-level function of the package (workers import it; a test module they cannot).
    plan_zero = partial(plan_chunks, chunk_trials=0)
    with pytest.raises(InputError, match="--chunk must be at least 1"):
        list(ray_executor.map_unordered(plan_zero, [SweepConfig(trials=1)]))


def test_a_ray_batch_equals_the_local_one(ray_executor, tmp_path):
    sets = ("mission.stops=[[2.5, 3.3]]", "mission.views_per_stop=2", "run.rerun=off",
            f"run.cache={tmp_path / 'cache'}")  # fmt: skip
    spec = spec_for(sets, 2)
    from twin.app.batch import prepare

    prepare(spec, lambda _: None)  # train once, as the command does
    local = run_batch(spec, 2, InlineExecutor())
    remote = run_batch(spec, 2, ray_executor)
    assert [deterministic(r) for r in remote] == [deterministic(r) for r in local]
    assert all(Path(tmp_path / "cache").iterdir())
