"""Where independent tasks run: in this process, in local worker processes, or on a Ray cluster.

Results come back in completion order so callers can write each as it arrives (and resume an
interrupted run); callers that need a stable order sort by the task itself. Work must not depend
on which worker runs it: every task carries its own seed, so the same seed gives the same
results whatever the executor and the number of workers.

A worker process runs many tasks in turn (the local pool's and Ray's workers both stay alive
between tasks), so a task may keep expensive state, e.g. a MuJoCo world, with ``kept_in_worker``;
it must not let that state change its result.
"""

from __future__ import annotations

import multiprocessing
import os
import socket
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Protocol, TypeVar

from twin.core.errors import InputError, TwinError

T = TypeVar("T")
_DONE = object()
R = TypeVar("R")
EXECUTORS = ("local", "ray")
# A local Ray cluster's shared-object store: tasks pass small items and results, never arrays
# of images, so 100 MB (about Ray's minimum) leaves the memory to the workers.
LOCAL_OBJECT_STORE_BYTES = 100 * 1024 * 1024
IN_FLIGHT_PER_WORKER = 2  # queued tasks per worker: keeps workers busy, bounds what is lost


# What tasks keep in this worker process between tasks (``kept_in_worker``): the one place a
# worker's state lives, in the local pool's processes, Ray's workers and the inline executor.
_KEPT: dict[str, Any] = {}


def kept_in_worker(
    key: str, make: Callable[[], T], close: Callable[[T], None] | None = None
) -> tuple[T, bool]:
    """This worker's object for ``key`` and whether it was kept from an earlier task; made with
    ``make`` on first use. A worker keeps one object: a new key closes and replaces the last
    (a worker serving a new batch drops the old batch's world)."""
    if key in _KEPT:
        return _KEPT[key][0], True
    for old, closer in _KEPT.values():
        if closer is not None:
            closer(old)
    _KEPT.clear()
    value = make()
    _KEPT[key] = (value, close)
    return value, False


class Executor(Protocol):
    """Runs ``fn`` over ``items`` and yields (item, result) pairs as they complete."""

    workers: int

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        """Yield (item, fn(item)) in completion order; errors propagate to the caller."""
        ...

    def close(self) -> None:
        """Release what the executor started (a no-op unless it started a cluster)."""
        ...


class InlineExecutor:
    """Runs every task in the calling process, in order (one worker, easiest to debug)."""

    workers = 1

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        for item in items:
            yield item, fn(item)

    def close(self) -> None:
        pass


class ProcessExecutor:
    """Runs tasks in ``workers`` fresh ('spawn') processes, at most ``2 * workers`` queued.

    Spawned workers import the project anew rather than inheriting a forked copy of the parent,
    which keeps numba and OpenGL state clean; compiled kernels are cached on disk, so each
    worker loads them instead of compiling.
    """

    def __init__(self, workers: int) -> None:
        if workers < 1:
            raise InputError(f"--workers must be at least 1, got {workers}")
        self.workers = workers

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        context = multiprocessing.get_context("spawn")
        pending: dict[Future[R], T] = {}
        queue = iter(items)
        with ProcessPoolExecutor(self.workers, mp_context=context) as pool:
            try:
                for item in queue:
                    pending[pool.submit(fn, item)] = item
                    if len(pending) >= IN_FLIGHT_PER_WORKER * self.workers:
                        break
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        item = pending.pop(future)
                        yield item, future.result()
                        nxt = next(queue, _DONE)
                        if nxt is not _DONE:
                            pending[pool.submit(fn, nxt)] = nxt
            finally:
                for future in pending:
                    future.cancel()

    def close(self) -> None:
        pass


# Ray's switch for multi-machine clusters; off, the node uses the loopback address.
LOOPBACK_SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def _apply(fn: Callable[[Any], Any], item: Any) -> Any:
    """What a Ray task runs: ``fn`` arrives once through the object store, then per item."""
    return fn(item)


def _keep_local_cluster_on_loopback() -> None:
    """Make a local Ray cluster bind and talk on 127.0.0.1 only (see ``RayExecutor``)."""
    os.environ[LOOPBACK_SWITCH] = "0"
    constants = sys.modules.get("ray._private.ray_constants")
    if constants is not None:  # ray was imported before: its constant is already read
        constants.ENABLE_RAY_CLUSTER = False


def _import_ray():
    try:
        import ray
    except ImportError:
        raise TwinError(
            "--executor ray needs Ray, which is not installed; pip install '.[cluster]'"
        ) from None
    return ray


class RayExecutor:
    """Runs tasks as Ray tasks (one CPU each), at most ``2 * workers`` in flight.

    With ``address`` it joins a running cluster (``ray start --head`` printed the address; "auto"
    finds one started on this machine) and ``workers`` defaults to the cluster's CPUs; without it
    it starts a private local cluster of ``workers`` CPUs (default: this machine's cores) with
    no dashboard and a small object store, and shuts it down on ``close``. A Ray session that is
    already initialised in this process (tests, notebooks) is used as it is.

    A local cluster is kept on loopback: Ray maps 127.0.0.1 to the node's network address
    unless told the cluster is single-machine (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, read
    when ray is imported), so that is set before the import. A joined cluster listens on the
    network: run it on a trusted network only (docs/cluster.md).
    """

    def __init__(self, workers: int | None = None, address: str | None = None) -> None:
        if workers is not None and workers < 1:
            raise InputError(f"--workers must be at least 1, got {workers}")
        if address is None:
            _keep_local_cluster_on_loopback()
        ray = _import_ray()
        self._ray = ray
        self._owns_session = False
        if not ray.is_initialized():
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no phoning home
            if address is None:
                cpus = workers or os.cpu_count() or 1
                ray.init(
                    num_cpus=cpus,
                    include_dashboard=False,
                    object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                    log_to_driver=False,
                    configure_logging=False,
                )
            else:
                _reachable(address)
                try:
                    ray.init(address=address, log_to_driver=False, configure_logging=False)
                except (ConnectionError, RuntimeError, ValueError) as exc:
                    first = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
                    raise TwinError(
                        f"cannot join the Ray cluster at {address!r} ({first}); start one with "
                        "'ray start --head' or drop --address for a local one"
                    ) from None
            self._owns_session = True
        cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = workers or max(cluster_cpus, 1)
        self._remote = ray.remote(num_cpus=1, max_retries=0)(_apply)

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        ray = self._ray
        fn_ref = ray.put(fn)  # serialised once, not once per task
        pending: dict[Any, T] = {}
        queue = iter(items)
        try:
            for item in queue:
                pending[self._remote.remote(fn_ref, item)] = item
                if len(pending) >= IN_FLIGHT_PER_WORKER * self.workers:
                    break
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    item = pending.pop(ref)
                    yield item, _unwrap(ray, ref)
                    nxt = next(queue, _DONE)
                    if nxt is not _DONE:
                        pending[self._remote.remote(fn_ref, nxt)] = nxt
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)

    def close(self) -> None:
        if self._owns_session and self._ray.is_initialized():
            self._ray.shutdown()
        self._owns_session = False


def _reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast on a HOST:PORT nobody listens on (Ray itself would retry for minutes)."""
    host, _, port = address.rpartition(":")
    if "://" in address or not host or not port.isdigit():
        return  # "auto", "ray://...": Ray resolves these itself
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise TwinError(
            f"no Ray cluster answers at {address} ({exc.strerror or exc}); start one with "
            "'ray start --head' there, or drop --address for a local one"
        ) from None


def _unwrap(ray, ref):
    """The task's result; a task's own error is re-raised as itself, not as Ray's wrapper."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as exc:
        cause = getattr(exc, "cause", None)
        if isinstance(cause, TwinError):
            raise cause from None
        raise


def make_executor(workers: int | None, kind: str = "local", address: str | None = None) -> Executor:
    """The executor ``kind`` names ("local" or "ray") with ``workers`` concurrent tasks.

    local: an inline executor for one worker, a process pool for more (default: all cores);
    ``address`` is for Ray only. ray: see ``RayExecutor``.
    """
    if kind not in EXECUTORS:
        raise InputError(f"--executor must be one of {', '.join(EXECUTORS)}, got {kind!r}")
    if kind == "ray":
        return RayExecutor(workers, address)
    if address is not None:
        raise InputError("--address joins a Ray cluster; add --executor ray or drop --address")
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count < 1:
        raise InputError(f"--workers must be at least 1, got {count}")
    return InlineExecutor() if count == 1 else ProcessExecutor(count)
