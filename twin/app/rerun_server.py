"""The Rerun viewer's server for ``--rerun serve``: started, found, and never left behind.

The server is the bundled viewer binary itself, not the ``python -m rerun`` wrapper (a signal to
the wrapper orphans the binary it runs), in its own process group (a Ctrl-C meant for the survey
does not reach it; stopping it ends the whole group), and on Linux it dies with the process that
started it, even by SIGKILL.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from twin.core.errors import TwinError

VIEWER_MEMORY_LIMIT = "1GiB"
SERVER_START_TIMEOUT = 10.0  # seconds for the Rerun server to listen
SERVER_STOP_TIMEOUT = 5.0  # seconds between SIGTERM and SIGKILL for the server's group


def has_display() -> bool:
    """Whether a native viewer window can open (on Linux/BSD: an X11 or Wayland display)."""
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _rerun_command() -> list[str]:
    """The bundled viewer binary itself, not the ``python -m rerun`` wrapper: the wrapper runs it
    as a child that a signal to the wrapper orphans."""
    try:
        import rerun_cli
    except ImportError:
        return [sys.executable, "-m", "rerun"]
    override = os.environ.get("RERUN_CLI_PATH")
    folder = Path(rerun_cli.__file__).parent
    suffix = ".exe" if sys.platform.startswith("win") else ""
    for candidate in (
        Path(override) if override else None,
        folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun",
        folder / f"rerun{suffix}",
    ):
        if candidate is not None and candidate.is_file():
            return [str(candidate)]
    return [sys.executable, "-m", "rerun"]


# Run by a fresh interpreter (one thread, so no pre-exec hook in this threaded process): ask the
# kernel to SIGTERM it when its parent dies, check that the parent is still the survey, then
# become the server. PR_SET_PDEATHSIG (1) survives the exec.
_EXEC_DYING_WITH_PARENT = (
    "import ctypes, os, sys; ctypes.CDLL(None).prctl(1, 15, 0, 0, 0); "
    "os.getppid() == int(sys.argv[1]) or sys.exit(1); os.execv(sys.argv[2], sys.argv[2:])"
)


def _server_command(arguments: Sequence[str]) -> list[str]:
    """The Rerun server's command; on Linux it dies with this process (even by SIGKILL), so a
    killed survey leaves no server behind."""
    command = [*_rerun_command(), *arguments]
    if not sys.platform.startswith("linux") or not os.path.isabs(command[0]):
        return command
    return [sys.executable, "-c", _EXEC_DYING_WITH_PARENT, str(os.getpid()), *command]


class RerunServer:
    """A Rerun gRPC server bound to ``bind`` (localhost unless told otherwise) on ``port``
    (a free one by default); ``url`` is what a viewer connects to."""

    def __init__(self, bind: str = "127.0.0.1", port: int | None = None) -> None:
        self._server: subprocess.Popen[bytes] | None = None
        self.url = self._start(bind, port or _free_port())

    @property
    def pid(self) -> int | None:
        """The server's process id (its process group's too), while it runs."""
        return self._server.pid if self._server is not None else None

    def wait(self) -> None:
        """Until the server ends (or Ctrl-C / SIGTERM reach this process); then it is stopped."""
        try:
            if self._server is not None:
                self._server.wait()
        finally:
            self.stop()

    def _start(self, bind: str, port: int) -> str:
        command = _server_command(
            [
                "--serve-grpc",
                "--bind",
                bind,
                "--port",
                str(port),
                "--server-memory-limit",
                VIEWER_MEMORY_LIMIT,
            ]
        )
        host = "127.0.0.1" if bind in ("0.0.0.0", "::", "127.0.0.1") else bind
        with tempfile.TemporaryFile() as log:
            self._server = subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=log,
                start_new_session=True,
            )
            atexit.register(self.stop)
            deadline = time.monotonic() + SERVER_START_TIMEOUT
            while time.monotonic() < deadline:
                if self._server.poll() is not None:
                    self.stop()
                    log.seek(0)
                    said = log.read().decode(errors="replace").strip().splitlines()
                    last = f" ({said[-1].strip()})" if said else ""
                    raise TwinError(
                        f"the Rerun server on {bind}:{port} exited{last}; is the port taken?"
                    )
                try:
                    with socket.create_connection((host, port), timeout=0.2):
                        return f"rerun+http://{host}:{port}/proxy"
                except OSError:
                    time.sleep(0.1)
        self.stop()
        raise TwinError(
            f"the Rerun server on {bind}:{port} did not start within {SERVER_START_TIMEOUT:g} s"
        )

    def stop(self) -> None:
        """End the server's whole process group: SIGTERM, then SIGKILL if it lingers."""
        server, self._server = self._server, None
        if server is None:
            return
        atexit.unregister(self.stop)
        if not hasattr(os, "killpg"):
            server.terminate()
            server.wait()
            return
        for sig in (signal.SIGTERM, signal.SIGKILL):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(server.pid, sig)
            try:
                server.wait(timeout=SERVER_STOP_TIMEOUT)
                break
            except (subprocess.TimeoutExpired, KeyboardInterrupt):
                continue
        with contextlib.suppress(ProcessLookupError):  # anything the leader left behind
            os.killpg(server.pid, signal.SIGKILL)
