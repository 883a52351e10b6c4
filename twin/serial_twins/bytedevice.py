"""What an emulated serial device is to whatever carries its bytes.

The same emulated VC-C4 can sit on its own pseudo-terminal (direct RS-232 wiring) or behind the
emulated ARCOS base's AUX port (bytes tunnelled in TTY2 / GETAUX / SERAUX packets): both
carriers only push the host's bytes in and pull the device's answers out. A carrier's line is
a ``DeviceLine``: a pseudo-terminal (``PtyLink``) or a line in memory (``MemoryLink``).
"""

from __future__ import annotations

from typing import Protocol


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
