"""Clocks: where the drivers and the serial twins read the time, wait, and run their threads.

Every driver (``hardware/``) and emulator (``twin.serial_twins``) takes a ``Clock`` and never
calls ``time.monotonic`` or ``time.sleep`` itself. In use that is ``SYSTEM_CLOCK``. A test hands
them all one ``ManualClock`` instead: virtual seconds that pass only while every thread of the
clock waits on it, so a 2 s watchdog or a 30 s timeout costs no wall time, and a loaded machine
can neither make a timeout fire early (a starved reader thread) nor late.

Why time may only move when every thread waits: a driver's reader thread and the caller share
the clock. If each sleep simply moved time on, a caller waiting for a SIP could run through its
whole timeout while the reader thread was not scheduled, and the test would fail on a busy
machine; if time moved only when the test said so, a caller blocked inside ``go_to`` could
never be woken. Jumping to the earliest wake-up once nobody runs makes the threads' order in
virtual time independent of how the operating system schedules them.

Seconds throughout; the origin of ``now()`` means nothing, only differences do.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Protocol


class Condition(Protocol):
    """The part of ``threading.Condition`` the drivers use; timeouts in the clock's seconds."""

    def __enter__(self) -> bool: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...

    def wait(self, timeout: float | None = None) -> bool: ...

    def wait_for(self, predicate: Callable[[], bool], timeout: float | None = None) -> bool: ...

    def notify_all(self) -> None: ...


class Clock(Protocol):
    """Time for a device: read it, wait on it, and run threads whose waits it governs."""

    def now(self) -> float:
        """Seconds since an arbitrary origin; never decreases."""
        ...

    def sleep(self, seconds: float) -> None:
        """Return after ``seconds`` of this clock's time (at once for zero or less)."""
        ...

    def condition(self) -> Condition:
        """A condition variable (re-entrant lock) whose timed waits run on this clock."""
        ...

    def start_thread(self, target: Callable[[], None], name: str) -> threading.Thread:
        """Start a daemon thread whose waits on this clock the clock knows about."""
        ...

    def join(self, thread: threading.Thread, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for ``thread`` to end; True if it did."""
        ...


class SystemClock:
    """The machine's monotonic clock: what the drivers run on outside tests."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0.0:
            time.sleep(seconds)

    def condition(self) -> Condition:
        return threading.Condition()

    def start_thread(self, target: Callable[[], None], name: str) -> threading.Thread:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        return thread

    def join(self, thread: threading.Thread, timeout: float) -> bool:
        thread.join(max(timeout, 0.0))
        return not thread.is_alive()


SYSTEM_CLOCK = SystemClock()


class ClockStalledError(RuntimeError):
    """A ``ManualClock`` could not move: a thread of it blocked on something else for long."""


@dataclass(eq=False)
class _Waiter:
    thread: threading.Thread
    wake: float  # clock time at which the wait times out; inf: only a notify ends it
    released: threading.Event = field(default_factory=threading.Event)
    notified: bool = False


# Real seconds between a waiting thread's checks that the clock can still move (a thread
# started elsewhere may have ended without a word); short, since nothing else wakes it then.
_POLL = 0.02


class ManualClock:
    """Virtual time for tests: it stands still while any thread of the clock runs and jumps to
    the earliest wake-up once all of them wait on it (sleep, a condition, a join).

    A thread belongs to the clock from its first wait, or from birth when the clock started it
    (``start_thread``); the thread that starts one belongs too, so time cannot run ahead while
    a test is still setting up. Threads woken at the same instant run in the order the operating
    system picks, but time moves on only after all of them wait again.

    ``advance(seconds)`` moves the hands by hand, for a test that steps an emulator itself.
    Waits that happen outside the clock (a pseudo-terminal's ``select``, a real ``sleep``)
    freeze it: after ``stall_timeout`` real seconds without progress a waiting thread that the
    clock did not start (the test's) raises ``ClockStalledError`` naming the threads that never
    came back, instead of hanging the test; the clock's own threads just idle meanwhile.
    """

    def __init__(self, start: float = 0.0, stall_timeout: float = 30.0) -> None:
        self._lock = threading.Lock()
        self._now = float(start)
        self.stall_timeout = stall_timeout
        self._threads: set[threading.Thread] = set()  # the clock's threads, alive
        self._waiting: dict[threading.Thread, _Waiter] = {}  # those blocked on it now
        self._joiners: dict[threading.Thread, list[_Waiter]] = {}
        self._started: set[threading.Thread] = set()  # made by start_thread: workers
        self._progress = 0  # counts waits begun and ended: what stall detection watches

    def now(self) -> float:
        return self._now

    def sleep(self, seconds: float) -> None:
        with self._lock:
            waiter = self._enter(self._now + max(seconds, 0.0))
        self._block(waiter)

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds`` at once, waking the waits that end by then."""
        if not seconds >= 0.0:
            raise ValueError(f"a clock only moves forward; got {seconds!r} s")
        with self._lock:
            self._now += seconds
            self._release_due()

    def condition(self) -> Condition:
        return _ManualCondition(self)

    def start_thread(self, target: Callable[[], None], name: str) -> threading.Thread:
        def run() -> None:
            try:
                target()
            finally:
                with self._lock:
                    self._threads.discard(thread)
                    self._started.discard(thread)
                    for waiter in self._joiners.pop(thread, []):
                        self._release(waiter, notified=True)
                    self._step()  # the last running thread ended: time may move

        thread = threading.Thread(target=run, name=name, daemon=True)
        with self._lock:
            self._threads.update((thread, threading.current_thread()))
            self._started.add(thread)
        thread.start()
        return thread

    def join(self, thread: threading.Thread, timeout: float) -> bool:
        waiter: _Waiter | None = None
        with self._lock:
            if thread in self._started:
                waiter = self._enter(self._now + max(timeout, 0.0))
                self._joiners.setdefault(thread, []).append(waiter)
        if waiter is None:  # ended already, or not started by this clock
            thread.join(max(timeout, 0.0))
            return not thread.is_alive()
        self._block(waiter)
        if not waiter.notified:
            return False
        thread.join(5.0)  # past its target: only the thread's own exit is left
        return not thread.is_alive()

    # -- the machinery; methods with a leading underscore run holding ``self._lock`` ---------

    def _enter(self, wake: float) -> _Waiter:
        me = threading.current_thread()
        waiter = _Waiter(me, wake)
        self._progress += 1
        if wake <= self._now:
            waiter.released.set()  # nothing to wait for
            return waiter
        self._threads.add(me)
        self._waiting[me] = waiter
        self._step()
        return waiter

    def _release(self, waiter: _Waiter, notified: bool) -> None:
        if self._waiting.get(waiter.thread) is waiter:
            del self._waiting[waiter.thread]
        if not waiter.released.is_set():
            waiter.notified = notified
            waiter.released.set()
            self._progress += 1

    def _release_due(self) -> None:
        for waiter in [w for w in self._waiting.values() if w.wake <= self._now]:
            self._release(waiter, notified=False)

    def _step(self) -> None:
        """If every live thread of the clock waits, jump to the earliest wake-up."""
        if len(self._waiting) < len(self._threads):
            return  # someone runs: time stands still until it waits too
        wake = min((w.wake for w in self._waiting.values()), default=math.inf)
        if wake == math.inf:
            return  # nothing will ever happen: a deadlock, as it would be in real time
        self._now = max(self._now, wake)
        self._release_due()

    def _block(self, waiter: _Waiter) -> None:
        seen, since = -1, time.monotonic()
        while not waiter.released.wait(_POLL):
            with self._lock:
                if waiter.released.is_set():
                    return
                # threads started elsewhere that ended without waiting again (the clock's own
                # leave in start_thread's wrapper; one not started yet is not alive either)
                gone = {t for t in self._threads - self._started if not t.is_alive()}
                if gone:
                    self._threads -= gone
                    self._step()
                    continue
                if self._progress != seen:
                    seen, since = self._progress, time.monotonic()
                    continue
                stalled = time.monotonic() - since > self.stall_timeout
                if waiter.thread in self._started or not stalled:
                    continue  # a worker idles while the test is away; the test must not hang
                running = sorted(t.name for t in self._threads if t not in self._waiting)
                self._release(waiter, notified=False)
            raise ClockStalledError(
                f"manual clock stood still for {self.stall_timeout:g} s of real time at "
                f"t={self._now:g} s: thread(s) {', '.join(running) or '?'} neither wait on it "
                "nor end (blocked in a real read, sleep or join?)"
            )


class _ManualCondition:
    """``threading.Condition`` whose timed waits are waits on a ``ManualClock``."""

    def __init__(self, clock: ManualClock) -> None:
        self._clock = clock
        self._lock = threading.RLock()
        self._waiters: list[_Waiter] = []  # guarded by the clock's lock

    def __enter__(self) -> bool:
        return self._lock.__enter__()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._lock.__exit__(exc_type, exc, tb)

    def wait(self, timeout: float | None = None) -> bool:
        clock = self._clock
        if not self._lock._is_owned():  # type: ignore[attr-defined]
            raise RuntimeError("cannot wait on un-acquired lock")
        with clock._lock:
            wake = math.inf if timeout is None else clock._now + max(timeout, 0.0)
            waiter = clock._enter(wake)
            self._waiters.append(waiter)
        # release the re-entrant lock however deep it is held, as threading.Condition does
        saved = self._lock._release_save()  # type: ignore[attr-defined]
        try:
            clock._block(waiter)
        finally:
            self._lock._acquire_restore(saved)  # type: ignore[attr-defined]
            with clock._lock:
                if waiter in self._waiters:
                    self._waiters.remove(waiter)
        return waiter.notified

    def wait_for(self, predicate: Callable[[], bool], timeout: float | None = None) -> bool:
        end = None if timeout is None else self._clock.now() + timeout
        result = predicate()
        while not result:
            if end is None:
                self.wait()
            else:
                left = end - self._clock.now()
                if left <= 0.0:
                    break
                self.wait(left)
            result = predicate()
        return result

    def notify_all(self) -> None:
        if not self._lock._is_owned():  # type: ignore[attr-defined]
            raise RuntimeError("cannot notify on un-acquired lock")
        clock = self._clock
        with clock._lock:
            for waiter in self._waiters:
                clock._release(waiter, notified=True)
            self._waiters.clear()
