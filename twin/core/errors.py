"""The project's error types.

Every error a user can cause is a ``TwinError``: its message is one line that names what is wrong
and what to do. The command line prints that line and exits with status 2 instead of a traceback.
"""


class TwinError(Exception):
    """Base of all errors meant for the user: one line, names the problem and the remedy."""


class InputError(TwinError, ValueError):
    """An argument or file content is out of its range, of the wrong shape, or not finite."""


class FileFormatError(TwinError):
    """A saved file is corrupt, of another kind, or of an unsupported format version."""


class Terminated(KeyboardInterrupt):
    """The process was asked to stop (SIGTERM). Raised in the main thread by the command line's
    handler, so that it unwinds exactly as Ctrl-C does: results written, devices stopped."""
