"""What an emulated serial device is to whatever carries its bytes.

The same emulated VC-C4 can sit on its own pseudo-terminal (direct RS-232 wiring) or behind the
emulated ARCOS base's AUX port (bytes tunnelled in TTY2 / GETAUX / SERAUX packets): both
carriers only push the host's bytes in and pull the device's answers out. A carrier's line is
a ``DeviceLine``: a pseudo-terminal (``PtyLink``) or a line in memory (``MemoryLink``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

from twin.core.clock import SYSTEM_CLOCK, Clock


class DeviceLine(Protocol):
    """The device's end of a serial line, as an emulator's server pumps it."""

    def read(self, size: int, timeout: float) -> bytes:
        """Up to ``size`` bytes from the host as soon as any arrive; b"" after ``timeout`` s."""
        ...

    def write(self, data: bytes) -> None: ...

    def hangup(self) -> None:
        """Unplug and replug: the host's open port dies and the device is reachable anew."""
        ...

    def close(self) -> None: ...


class ByteDevice(Protocol):
    def receive(self, data: bytes, now: float) -> None:
        """Bytes from the host, arriving at ``now`` (the carrier's clock, seconds)."""
        ...

    def transmit(self, now: float) -> bytes:
        """The bytes the device has sent by ``now`` and nobody has taken yet (taken now)."""
        ...


class LineServer:
    """A thread serving an emulated device on a line (``PtyLink`` or a memory line), on
    ``clock``: the host's bytes go in as they come, the device is ticked (``tick(now)``, if it
    has one), and what it sends goes out. Between rounds it waits on the line until the device
    is next due (``next_wake(now)``, if it has one) but at most ``max_wait`` seconds, so a
    stream's or an answer's timing follows the clock. ``path`` is what a driver opens on a pty;
    ``hangup()`` unplugs and replugs the line (the device keeps its state); ``on_stop`` runs
    when the server stops (e.g. stopping the wheels a base was driving)."""

    def __init__(
        self,
        device: ByteDevice,
        link: DeviceLine,
        clock: Clock = SYSTEM_CLOCK,
        *,
        name: str,
        max_wait: float = 0.05,
        read_size: int = 4096,
        on_stop: Callable[[], None] | None = None,
    ) -> None:
        from twin.serial_twins.pty import check_clock

        check_clock(link, clock)
        self.emulator, self.link, self.clock = device, link, clock
        self.max_wait, self.read_size, self._on_stop = max_wait, read_size, on_stop
        self._tick = getattr(device, "tick", None)
        self._next_wake = getattr(device, "next_wake", None)
        self._stop = threading.Event()
        self._thread = clock.start_thread(self._run, name=name)

    @property
    def path(self) -> str:
        """The pseudo-terminal's path (``Driver.open(server.path)``)."""
        from twin.serial_twins.pty import PtyLink

        if not isinstance(self.link, PtyLink):
            raise TypeError("a memory line has no path: plug a driver in with link.transport()")
        return self.link.path

    def _run(self) -> None:
        device, link, clock = self.emulator, self.link, self.clock
        while not self._stop.is_set():
            wait = self.max_wait
            if self._next_wake is not None:
                now = clock.now()
                due = self._next_wake(now)
                if due is not None:
                    wait = min(max(due - now, 0.0), self.max_wait)
            data = link.read(self.read_size, wait)
            now = clock.now()
            device.receive(data, now)
            if self._tick is not None:
                self._tick(now)
            out = device.transmit(now)
            if out:
                link.write(out)

    def hangup(self) -> None:
        self.link.hangup()

    def stop(self) -> None:
        self._stop.set()
        self.clock.join(self._thread, 2.0)
        if self._on_stop is not None:
            self._on_stop()
        self.link.close()

    def __enter__(self) -> LineServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class EchoDevice:
    """A device that sends back every byte it gets: a loopback plug for testing a carrier
    (e.g. the ARCOS AUX tunnel) without any protocol on top."""

    def __init__(self) -> None:
        self.pending = bytearray()

    def receive(self, data: bytes, now: float) -> None:
        self.pending += data

    def transmit(self, now: float) -> bytes:
        out, self.pending = bytes(self.pending), bytearray()
        return out
