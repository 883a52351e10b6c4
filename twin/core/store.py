"""Atomic files, and the project's array-file format: ``.npz`` arrays plus a JSON header.

Grids and detector models are both saved this way. The header (format name, version and any
metadata) is stored as a UTF-8 JSON byte array inside the same ``.npz``, so one file carries both
and ``allow_pickle=False`` is enough to read it safely.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from twin.core.errors import FileFormatError, InputError

_HEADER_KEY = "__header__"


def write_atomic(path: str | os.PathLike[str], write: Callable[[IO[bytes]], None]) -> Path:
    """Write a file through ``write(fileobj)`` so that readers see the old file or the new one.

    The bytes go to a temporary file in the same directory, are flushed to disk, and only then
    renamed over ``path``; an interrupted write leaves the previous file intact.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        os.fchmod(fd, 0o666 & ~_current_umask())
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return target


def _current_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 text atomically (see ``write_atomic``)."""
    return write_atomic(path, lambda handle: handle.write(text.encode("utf-8")))


def save_arrays(
    path: str | os.PathLike[str],
    kind: str,
    version: int,
    header: Mapping[str, Any],
    arrays: Mapping[str, np.ndarray],
    compress: bool = True,
) -> Path:
    """Save ``arrays`` and a JSON ``header`` tagged with a format ``kind`` and ``version``.

    ``compress=False`` writes them as they are: several times faster, for files rewritten
    often (a mission's checkpoint after every view), at several times the size."""
    if _HEADER_KEY in arrays:
        raise ValueError(f"array name {_HEADER_KEY!r} is reserved for the header")
    full_header = {"format": kind, "version": version, **header}
    header_bytes = np.frombuffer(json.dumps(full_header).encode("utf-8"), dtype=np.uint8)
    payload = {_HEADER_KEY: header_bytes, **{k: np.asarray(v) for k, v in arrays.items()}}
    save = np.savez_compressed if compress else np.savez
    return write_atomic(path, lambda handle: save(handle, **payload))


def load_arrays(
    path: str | os.PathLike[str], kind: str, version: int
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Load a file written by ``save_arrays``; any defect is a one-line ``FileFormatError``."""
    source = Path(path)
    if not source.is_file():
        raise FileFormatError(f"{source}: no such file; check the path")
    try:
        with np.load(source, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise FileFormatError(
            f"{source}: not a readable {kind} file ({exc.__class__.__name__}: {exc}); re-create it"
        ) from exc
    raw_header = arrays.pop(_HEADER_KEY, None)
    if raw_header is None:
        raise FileFormatError(f"{source}: has no header, so it is not a {kind} file; re-create it")
    try:
        header = json.loads(raw_header.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{source}: its header is corrupt ({exc}); re-create it") from exc
    if not isinstance(header, dict) or header.get("format") != kind:
        found = header.get("format") if isinstance(header, dict) else None
        raise FileFormatError(f"{source}: is a {found!r} file, not a {kind!r} file")
    if header.get("version") != version:
        raise FileFormatError(
            f"{source}: {kind} format version {header.get('version')!r} is not supported "
            f"(this version of twin reads version {version}); re-create the file"
        )
    return header, arrays


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float as None: JSON has no inf or nan."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value


class JsonLinesJournal:
    """An append-only record of finished work, so an interrupted run resumes where it stopped.

    The first line names what is recorded (``kind``) and the parameters that decide its results
    (``identity``); each further line is one finished piece, flushed to disk as it arrives. A
    journal of another kind, or of other parameters, is refused in one line; a last line torn
    by a crash is skipped (that piece simply runs again) and ended, so appends start anew.
    ``entries`` holds the readable pieces, in order.
    """

    def __init__(self, path: Path, kind: str, identity: dict[str, Any], fresh: bool = False):
        self.path = path
        self.entries: list[dict[str, Any]] = []
        if path.exists() and not fresh:
            self._read(kind, identity)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            with path.open("w", encoding="utf-8") as handle:
                handle.write(json.dumps({kind: identity}) + "\n")

    def _read(self, kind: str, identity: dict[str, Any]) -> None:
        text = self.path.read_text(encoding="utf-8")
        if text and not text.endswith("\n"):
            with self.path.open("a", encoding="utf-8") as handle:
                handle.write("\n")
        lines = text.splitlines()
        try:
            recorded = json.loads(lines[0])[kind]
        except (IndexError, KeyError, TypeError, json.JSONDecodeError):
            raise InputError(
                f"{self.path} is not a {kind} journal; choose another --out or pass --fresh"
            ) from None
        if recorded != identity:
            changed = sorted(k for k in identity if recorded.get(k) != identity[k])
            raise InputError(
                f"{self.path.parent} holds a {kind} with other parameters ({', '.join(changed)}); "
                "choose another --out, or pass --fresh to discard it"
            )
        for line in lines[1:]:
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(entry, dict):
                self.entries.append(entry)

    def append(self, entry: dict[str, Any]) -> None:
        with self.path.open("a", encoding="utf-8") as handle:
            handle.write(json.dumps(entry) + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        self.entries.append(entry)
