"""Output folders: checked before anything is written, never overwritten, removed on a false start.

Every command that writes a folder (``twin survey``, ``montecarlo``, ``batch-survey``) checks
its ``--out`` before it does any work: a path that is a file, lies inside a file or cannot be
created is a one-line error; a folder that holds files but is not one of that command's own is
refused, never overwritten. A folder is created only once every check that can fail has
passed, and a run that fails before it has saved anything worth resuming removes what it wrote.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from twin.core.errors import InputError


def check_output_folder(path: Path, flag: str, is_ours: Callable[[Path], bool], what: str) -> bool:
    """Whether ``path`` already is one of ours (``is_ours``); ``False`` if it is new or empty.

    Raises a one-line ``InputError`` naming ``flag`` when ``path`` is a file, lies inside a
    file, cannot be made or written, or is a folder holding files that are not ``what``.
    Nothing is left behind by the check.
    """
    if path.exists() and not path.is_dir():
        raise InputError(f"{flag} {path}: is a file, not a folder; give a folder to write into")
    if path.is_dir():
        if is_ours(path):
            return True
        try:
            entries = sorted(p.name for p in path.iterdir())
        except OSError as exc:
            raise InputError(f"{flag} {path}: cannot read the folder ({exc.strerror})") from None
        if entries:
            raise InputError(
                f"{flag} {path}: holds files that are not {what} (e.g. {entries[0]}); "
                "choose a new or empty folder (it is never overwritten)"
            )
    _probe(path, flag, path)
    return False


def check_output_file(path: Path, flag: str) -> None:
    """A one-line ``InputError`` naming ``flag`` unless a file can be written at ``path``: it is
    not a folder, does not lie inside a file, and its folder exists or can be made, writable.
    Nothing is left behind by the check."""
    if path.is_dir():
        raise InputError(f"{flag} {path}: is a folder; give a file name to write")
    _probe(path.parent, flag, path)


def _probe(folder: Path, flag: str, shown: Path) -> None:
    """Make ``folder`` (if missing) and a scratch file in it, then remove both: the one honest
    test that a place can be written (permissions, read-only mounts, /proc, a file in the way)."""
    ancestor = folder
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(
            f"{flag} {shown}: lies inside {ancestor}, which is a file; choose a folder"
        )
    created: list[Path] = []
    try:
        created = make_output_folder(folder, flag, shown)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise InputError(
            f"{flag} {shown}: cannot write there ({exc.strerror}); choose another folder"
        ) from None
    finally:
        for made in reversed(created):
            with contextlib.suppress(OSError):
                made.rmdir()


def make_output_folder(path: Path, flag: str, shown: Path | None = None) -> list[Path]:
    """Create ``path`` (and missing parents); returns the folders this made, outermost first."""
    missing = []
    probe = path
    while not probe.exists():
        missing.append(probe)
        if probe == probe.parent:
            break
        probe = probe.parent
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        for made in missing:  # innermost first: whatever mkdir made before it failed
            with contextlib.suppress(OSError):
                made.rmdir()
        raise InputError(
            f"{flag} {shown or path}: cannot create the folder ({exc.strerror}); "
            "choose another folder"
        ) from None
    return list(reversed(missing))


@contextlib.contextmanager
def removed_on_false_start(
    folder: Path, created: list[Path], started: Callable[[], bool]
) -> Iterator[None]:
    """Remove ``folder``'s contents (and the folders ``created``) if the body fails before
    ``started()`` says anything worth keeping was saved; only for folders that were new or
    empty when claimed, so everything in them is ours."""
    try:
        yield
    except BaseException:
        if not started():
            _empty(folder)
            for made in reversed(created):
                with contextlib.suppress(OSError):
                    made.rmdir()
        raise


def _empty(folder: Path) -> None:
    if not folder.is_dir():
        return
    for entry in folder.iterdir():
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                entry.unlink()
