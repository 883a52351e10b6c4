"""Pseudo-terminal links: the driver opens ``path``, the emulator reads and writes the master.

The slave side is put in raw mode (no echo, no line editing, 8 bits through) like a serial
line, and the emulator keeps its own handle on it so that a driver closing and reopening the
port does not end the link. ``hangup`` replaces the pseudo-terminal by a new one, as a device
unplugged and plugged in again would; a stable ``link`` path (a symlink) follows it.

A pseudo-terminal's reads wait in real time (``select``): serve one with the system clock. For
tests in virtual time, ``twin.serial_twins.memory.MemoryLink`` is the same line without a pty.
"""

from __future__ import annotations

import contextlib
import os
import select
import termios
import threading
import tty
from pathlib import Path

from twin.core.clock import Clock, SystemClock


def check_clock(link: object, clock: Clock) -> None:
    """Refuse to serve a pseudo-terminal on anything but the system clock: its ``select``
    waits in real time, so a manual clock would stand still while the server waits."""
    if isinstance(link, PtyLink) and not isinstance(clock, SystemClock):
        raise ValueError(
            "a pseudo-terminal's reads wait in real time: serve it with the system clock, "
            "or use a MemoryLink on this clock"
        )


class PtyLink:
    """One pseudo-terminal pair; the emulator's end has timed reads and plain writes."""

    def __init__(self, link: str | os.PathLike[str] | None = None) -> None:
        self.link = Path(link) if link is not None else None
        self._master = self._slave = -1
        # a hangup from a test's thread must not close the descriptors under a read or write
        self._fd_lock = threading.Lock()
        self._open()

    def _open(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.device)
            tmp.replace(self.link)

    @property
    def path(self) -> str:
        """What a driver should open: the stable link if there is one, else the device."""
        return str(self.link) if self.link is not None else self.device

    def read(self, size: int, timeout: float) -> bytes:
        """Up to ``size`` bytes the driver wrote; b"" when none arrive within ``timeout`` s."""
        with self._fd_lock:
            if self._master < 0:
                return b""
            ready, _, _ = select.select([self._master], [], [], max(timeout, 0.0))
            if not ready:
                return b""
            try:
                return os.read(self._master, size)
            except (BlockingIOError, OSError):
                return b""

    def write(self, data: bytes) -> None:
        """Send bytes to the driver. If nobody drains the other end for 50 ms the rest is
        dropped, as a serial line drops what a receiver has no room for."""
        view = memoryview(data)
        with self._fd_lock:
            while view and self._master >= 0:
                try:
                    view = view[os.write(self._master, view) :]
                except BlockingIOError:
                    _, ready, _ = select.select([], [self._master], [], 0.05)
                    if not ready:
                        return
                except OSError:
                    return

    def hangup(self) -> None:
        """Close this pseudo-terminal and open a new one (the link, if any, moves to it)."""
        with self._fd_lock:
            self._close()
            self._open()

    def close(self) -> None:
        with self._fd_lock:
            self._close()

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
