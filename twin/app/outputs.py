"""Output folders: checked before anything is written, never overwritten, removed on a false start.

Every command that writes a folder (``twin survey``, ``montecarlo``, ``batch-survey``) checks
its ``--out`` before it does any work: a path that is a file, lies inside a file or cannot be
created is a one-line error; a folder that holds files but is not one of that command's own is
refused, never overwritten. A folder is created only once every check that can fail has
passed, and a run that fails before it has saved anything worth resuming removes what it wrote.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

from twin.core.errors import InputError


def check_output_folder(path: Path, flag: str, is_ours: Callable[[Path], bool], what: str) -> bool:
    """Whether ``path`` already is one of ours (``is_ours``); ``False`` if it is new or empty.

    Raises a one-line ``InputError`` naming ``flag`` when ``path`` is a file, lies inside a
    file, cannot be made, or is a folder holding files that are not ``what``.
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
        _require_writable(path, flag, path)
        return False
    _require_creatable(path, flag)
    return False


def check_output_file(path: Path, flag: str) -> None:
    """A one-line ``InputError`` naming ``flag`` unless a file can be written at ``path``: it is
    not a folder, does not lie inside a file, and its folder exists or can be made, writable."""
    if path.is_dir():
        raise InputError(f"{flag} {path}: is a folder; give a file name to write")
    if path.parent.is_dir():
        _require_writable(path.parent, flag, path)
    else:
        _require_creatable(path.parent, flag)


def _require_creatable(path: Path, flag: str) -> None:
    """``path`` does not exist: its nearest existing ancestor must be a writable folder."""
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"{flag} {path}: lies inside {ancestor}, which is a file; choose a folder")
    _require_writable(ancestor, flag, path)


def _require_writable(folder: Path, flag: str, path: Path) -> None:
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(
            f"{flag} {path}: cannot write there ({folder} is not writable); choose another folder"
        )


def make_output_folder(path: Path, flag: str) -> list[Path]:
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
        raise InputError(
            f"{flag} {path}: cannot create the folder ({exc.strerror}); choose another folder"
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
