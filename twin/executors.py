"""Where independent tasks run: in this process, or in a pool of local worker processes.

Results come back in completion order so callers can write each as it arrives (and resume an
interrupted run); callers that need a stable order sort by the task itself. Work must not depend
on which worker runs it: every task carries its own seed.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Protocol, TypeVar

from twin.errors import InputError

T = TypeVar("T")
_DONE = object()
R = TypeVar("R")


class Executor(Protocol):
    """Runs ``fn`` over ``items`` and yields (item, result) pairs as they complete."""

    workers: int

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        """Yield (item, fn(item)) in completion order; errors propagate to the caller."""
        ...


class InlineExecutor:
    """Runs every task in the calling process, in order (one worker, easiest to debug)."""

    workers = 1

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[T, R]]:
        for item in items:
            yield item, fn(item)


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
                    if len(pending) >= 2 * self.workers:
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


def make_executor(workers: int | None) -> Executor:
    """An inline executor for one worker, a process pool for more (default: all cores)."""
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count < 1:
        raise InputError(f"--workers must be at least 1, got {count}")
    return InlineExecutor() if count == 1 else ProcessExecutor(count)
