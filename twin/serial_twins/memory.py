"""A serial line in memory, timed by a clock: drivers and serial twins in one process.

``MemoryLink`` is a ``PtyLink`` without the pseudo-terminal: the emulator reads and writes its
end exactly as it would a pty's master, and ``transport(name)`` plugs a driver in at the other
end (a ``hardware.transport.Transport``). Every wait is a wait on the link's clock, so with a
``twin.core.clock.ManualClock`` a driver, its reader thread, the emulator's server thread and
the world stepping the robot all run in virtual time: a test of a 2 s watchdog or a 30 s
timeout takes milliseconds and cannot be upset by a loaded machine. ``hangup`` cuts the line as
unplugging a cable would: the driver's transport then raises ``ConnectionLostError`` and a new
``transport()`` reaches the device again.
"""

from __future__ import annotations

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import ConnectionLostError


class MemoryLink:
    """Two byte queues and a condition on ``clock``; ``name`` appears in errors."""

    def __init__(self, clock: Clock = SYSTEM_CLOCK, name: str = "memory line") -> None:
        self.clock, self.name = clock, name
        self._cond = clock.condition()
        self._to_device = bytearray()
        self._to_host = bytearray()
        self._generation = 0  # counts hangups: a transport from before one is dead
        self._closed = False

    # -- the device's end (what a server pumps, like PtyLink) ----------------------------------
    def read(self, size: int, timeout: float) -> bytes:
        """Up to ``size`` bytes the driver wrote, as soon as any are there; b"" after
        ``timeout`` seconds (clock time) without any."""
        with self._cond:
            self._cond.wait_for(lambda: bool(self._to_device) or self._closed, timeout)
            out = bytes(self._to_device[:size])
            del self._to_device[:size]
            return out

    def write(self, data: bytes) -> None:
        """Send bytes to the driver (dropped once the line is closed, like a pty's)."""
        with self._cond:
            if not self._closed and data:
                self._to_host += data
                self._cond.notify_all()

    def hangup(self) -> None:
        """Unplug and replug: bytes in flight are lost and the driver's transport is dead."""
        with self._cond:
            self._generation += 1
            self._to_device.clear()
            self._to_host.clear()
            self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    # -- the driver's end ----------------------------------------------------------------------
    def transport(self, name: str) -> MemoryTransport:
        """A ``Transport`` on the line as it is now (``name`` names the device in errors): what a
        driver's opener returns, e.g. ``VCC4(opener=lambda: link.transport("VC-C4"))``."""
        return MemoryTransport(self, name)


class MemoryTransport:
    """The driver's end of a ``MemoryLink``: a ``hardware.transport.Transport``."""

    def __init__(self, link: MemoryLink, name: str) -> None:
        self.link, self.name = link, name
        self._generation = link._generation
        self._closed = False

    def _check(self, asked: str) -> None:
        link = self.link
        if self._closed:
            raise ConnectionLostError(self.name, asked, "the transport is closed", "open it again")
        if link._closed or self._generation != link._generation:
            raise ConnectionLostError(
                self.name, asked, f"{link.name} was hung up", "check that the device is plugged in"
            )

    def write(self, data: bytes) -> None:
        link = self.link
        with link._cond:
            self._check(f"write {len(data)} bytes to {link.name}")
            link._to_device += data
            link._cond.notify_all()

    def read(self, size: int, timeout: float) -> bytes:
        """Up to ``size`` bytes, early only when ``size`` arrived (as pyserial's read)."""
        link = self.link
        asked = f"read from {link.name}"
        with link._cond:
            self._check(asked)
            link._cond.wait_for(
                lambda: (
                    len(link._to_host) >= size
                    or self._closed
                    or link._closed
                    or self._generation != link._generation
                ),
                timeout,
            )
            self._check(asked)
            out = bytes(link._to_host[:size])
            del link._to_host[:size]
            return out

    def reset_input(self) -> None:
        link = self.link
        with link._cond:
            self._check(f"flush {link.name}")
            link._to_host.clear()

    def close(self) -> None:
        with self.link._cond:
            self._closed = True
            self.link._cond.notify_all()  # a read blocked in another thread ends now
