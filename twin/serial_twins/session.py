"""The serial twins of one robot: the sim world stepped in time with a clock, the emulated ARCOS
base and VC-C4 head on their lines, started and stopped together.

``twin serve-hardware`` runs one for users' own tools; the device factory starts one when a
config gives a hardware device ``port = "twin"``, so the real drivers fly the mission against it.
Both use pseudo-terminals and the system clock; tests may put the lines in memory and run the
whole set on a ``ManualClock`` instead.
"""

from __future__ import annotations

from pathlib import Path

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.bytedevice import DeviceLine
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.pty import PtyLink
from twin.serial_twins.runner import WorldRunner
from twin.serial_twins.vcc4 import SimHeadActuator, VCC4Emulator, serve_vcc4
from twin.sim.robot import SimRobot

VCC4_WIRINGS = ("direct", "aux")


class SerialTwins:
    """An ARCOS emulator, and a VC-C4 emulator on its own line (``direct``) or behind the base's
    AUX1 port (``aux``), both driving ``sim``, whose world a ``WorldRunner`` steps.

    The lines are pseudo-terminals (``lines="pty"``, stable symlinks in ``link_dir`` if given)
    or ``MemoryLink``s (``lines="memory"``: drivers plug in with ``arcos_link.transport()``);
    everything runs on ``clock``, which for pseudo-terminals must be the system clock."""

    def __init__(self, sim: SimRobot, time_scale: float = 1.0, vcc4_wiring: str = "direct",
                 link_dir: Path | None = None, *, clock: Clock = SYSTEM_CLOCK,
                 lines: str = "pty") -> None:  # fmt: skip
        if vcc4_wiring not in VCC4_WIRINGS:
            raise ValueError(f"vcc4_wiring must be one of {VCC4_WIRINGS}, got {vcc4_wiring!r}")
        if lines not in ("pty", "memory"):
            raise ValueError(f"lines must be 'pty' or 'memory', got {lines!r}")
        self.sim, self.vcc4_wiring = sim, vcc4_wiring
        self._runner = WorldRunner(sim, time_scale, clock=clock)

        def link(name: str) -> DeviceLine:
            if lines == "memory":
                return MemoryLink(clock, f"{name} memory line")
            if link_dir is None:
                return PtyLink()
            link_dir.mkdir(parents=True, exist_ok=True)
            return PtyLink(link_dir / name)

        self._vcc4 = None
        aux1 = None
        if vcc4_wiring == "aux":
            aux1 = VCC4Emulator(SimHeadActuator(sim))
        else:
            self._vcc4 = serve_vcc4(sim, link("vcc4"), clock=clock)
        self._arcos = serve_arcos(sim, link("arcos"), aux1=aux1, clock=clock)
        self._runner.start()

    @property
    def arcos_path(self) -> str:
        return self._arcos.path

    @property
    def vcc4_path(self) -> str | None:
        """The VC-C4's own line, or None when it hangs off the base's AUX1 port."""
        return self._vcc4.path if self._vcc4 is not None else None

    @property
    def arcos_link(self) -> DeviceLine:
        """The ARCOS emulator's line (a ``MemoryLink`` with ``lines="memory"``)."""
        return self._arcos.link

    @property
    def vcc4_link(self) -> DeviceLine | None:
        """The VC-C4's own line, or None when it hangs off the base's AUX1 port."""
        return self._vcc4.link if self._vcc4 is not None else None

    def hangup(self, device: str) -> None:
        """Unplug and replug ``device`` ("arcos" or "vcc4"): its pseudo-terminal is replaced
        (a stable link follows it), as a cable pulled mid-mission would (fault injection)."""
        server = {"arcos": self._arcos, "vcc4": self._vcc4}.get(device)
        if server is None:
            raise ValueError(f"no serial twin {device!r} on its own line here")
        server.hangup()

    def stop(self) -> None:
        for server in (self._vcc4, self._arcos):
            if server is not None:
                server.stop()
        self._runner.stop()

    def __enter__(self) -> SerialTwins:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
