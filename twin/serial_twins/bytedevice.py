"""What an emulated serial device is to whatever carries its bytes.

The same emulated VC-C4 can sit on its own pseudo-terminal (direct RS-232 wiring) or behind the
emulated ARCOS base's AUX port (bytes tunnelled in TTY2 / GETAUX / SERAUX packets): both
carriers only push the host's bytes in and pull the device's answers out.
"""

from __future__ import annotations

from typing import Protocol


class ByteDevice(Protocol):
    def receive(self, data: bytes, now: float) -> None:
        """Bytes from the host, arriving at ``now`` (``time.monotonic()`` seconds)."""
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
