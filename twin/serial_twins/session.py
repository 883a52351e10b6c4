"""The serial twins of one robot: the sim world stepped in time with a clock, the emulated ARCOS
base and VC-C4 head on their lines, and optionally the emulated SICK LMS200 laser on its own,
started and stopped together.

``twin serve-hardware`` runs one for users' own tools; the device factory starts one when a
config gives a hardware device ``port = "twin"``, so the real drivers fly the mission against it.
Both use pseudo-terminals and the system clock; tests may put the lines in memory and run the
whole set on a ``ManualClock`` instead.
"""

from __future__ import annotations

from pathlib import Path

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.bytedevice import DeviceLine, LineServer
from twin.serial_twins.lms2xx import BaudMemoryLink, RangeSource, serve_lms2xx
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.pty import PtyLink
from twin.serial_twins.runner import WorldRunner
from twin.serial_twins.vcc4 import SimHeadActuator, VCC4Emulator, serve_vcc4
from twin.sim.robot import SimRobot

VCC4_WIRINGS = ("direct", "aux")


class SerialTwins:
    """An ARCOS emulator, and a VC-C4 emulator on its own line (``direct``) or behind the base's
    AUX1 port (``aux``), both driving ``sim``, whose world a ``WorldRunner`` steps; with a
    ``laser_source`` (``source(angles_rad) -> ranges_m``, see ``twin.serial_twins.lms2xx``) also
    an LMS200 emulator on a line named ``lms2xx``, ``laser_options`` going to its emulator.

    The lines are pseudo-terminals (``lines="pty"``, stable symlinks in ``link_dir`` if given)
    or ``MemoryLink``s (``lines="memory"``: drivers plug in with ``arcos_link.transport()``; the
    laser's is a ``BaudMemoryLink``, which knows the rate the driver set);
    everything runs on ``clock``, which for pseudo-terminals must be the system clock."""

    def __init__(self, sim: SimRobot, time_scale: float = 1.0, vcc4_wiring: str = "direct",
                 link_dir: Path | None = None, *, clock: Clock = SYSTEM_CLOCK,
                 lines: str = "pty", laser_source: RangeSource | None = None,
                 laser_options: dict[str, object] | None = None) -> None:  # fmt: skip
        if vcc4_wiring not in VCC4_WIRINGS:
            raise ValueError(f"vcc4_wiring must be one of {VCC4_WIRINGS}, got {vcc4_wiring!r}")
        if lines not in ("pty", "memory"):
            raise ValueError(f"lines must be 'pty' or 'memory', got {lines!r}")
        self.sim, self.vcc4_wiring = sim, vcc4_wiring
        self._runner = WorldRunner(sim, time_scale, clock=clock)

        def link(name: str) -> DeviceLine:
            if lines == "memory":
                kind = BaudMemoryLink if name == "lms2xx" else MemoryLink
                return kind(clock, f"{name} memory line")
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
        self._lms2xx: LineServer | None = None
        if laser_source is not None:
            self._lms2xx = serve_lms2xx(
                laser_source, link("lms2xx"), clock=clock, **(laser_options or {})
            )
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

    @property
    def lms2xx_path(self) -> str | None:
        """The laser's line, or None when the twins run without one."""
        return self._lms2xx.path if self._lms2xx is not None else None

    @property
    def lms2xx_link(self) -> DeviceLine | None:
        """The laser's line (a ``BaudMemoryLink`` with ``lines="memory"``), or None."""
        return self._lms2xx.link if self._lms2xx is not None else None

    @property
    def lms2xx(self) -> LineServer | None:
        """The laser's server (its ``emulator`` for fault injection), or None."""
        return self._lms2xx

    def hangup(self, device: str) -> None:
        """Unplug and replug ``device`` ("arcos", "vcc4" or "lms2xx"): its pseudo-terminal is
        replaced (a stable link follows it), as a cable pulled mid-mission would."""
        server = {"arcos": self._arcos, "vcc4": self._vcc4, "lms2xx": self._lms2xx}.get(device)
        if server is None:
            raise ValueError(f"no serial twin {device!r} on its own line here")
        server.hangup()

    def stop(self) -> None:
        for server in (self._lms2xx, self._vcc4, self._arcos):
            if server is not None:
                server.stop()
        self._runner.stop()

    def __enter__(self) -> SerialTwins:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
