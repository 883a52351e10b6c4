"""Occupancy maps: a 2-D grid of occupancy probabilities over the map frame.

The in-memory layout follows the accumulator grid's: ``occupancy[row, col]`` with row 0 at the
map's lowest y (map y up) and column 0 at its lowest x. The ROS ``map_server`` format (a PGM
image with row 0 at the top, and a YAML file with ``resolution``, ``origin``, ``negate``,
``occupied_thresh`` and ``free_thresh``) is what maps are read from and written to, so a map made
with slam_toolbox, Cartographer or gmapping works as it is.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.core.errors import FileFormatError, InputError
from twin.core.store import write_atomic, write_text_atomic

UNKNOWN = -1.0  # occupancy of a cell nothing has been seen of


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid in the map frame (metres, x right, y up).

    ``occupancy`` (ny, nx): the probability that a cell is occupied, in [0, 1], or ``UNKNOWN``;
    ``resolution``: metres per cell; ``origin``: (x, y, yaw) of the lower-left corner of cell
    (0, 0), as map_server's ``origin`` (yaw must be 0: rotated maps are not supported);
    ``occupied_thresh`` / ``free_thresh``: a cell at or above the first is occupied, at or below
    the second free, in between unknown (map_server's trinary reading; its defaults).
    """

    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196

    def __post_init__(self) -> None:
        grid = np.asarray(self.occupancy, dtype=float)
        if grid.ndim != 2 or min(grid.shape) < 1:
            raise InputError(f"an occupancy map must be a 2-D grid, got shape {grid.shape}")
        known = grid[grid != UNKNOWN]
        if known.size and (not np.all(np.isfinite(known)) or known.min() < 0 or known.max() > 1):
            raise InputError("occupancy values must be in [0, 1], or -1 for unknown")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise InputError(f"map resolution must be positive, got {self.resolution!r} m")
        if abs(self.origin[2]) > 1e-9:
            raise InputError("rotated maps (origin yaw != 0) are not supported; re-export it")
        if not 0.0 <= self.free_thresh < self.occupied_thresh <= 1.0:
            raise InputError(
                f"map thresholds must satisfy 0 <= free ({self.free_thresh}) < occupied "
                f"({self.occupied_thresh}) <= 1"
            )
        object.__setattr__(self, "occupancy", grid)

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupancy.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) in metres."""
        ny, nx = self.shape
        x0, y0 = self.origin[0], self.origin[1]
        return x0, y0, x0 + nx * self.resolution, y0 + ny * self.resolution

    @property
    def occupied(self) -> np.ndarray:
        """(ny, nx) bool: cells at or above ``occupied_thresh``."""
        return self.occupancy >= self.occupied_thresh

    @property
    def free(self) -> np.ndarray:
        """(ny, nx) bool: known cells at or below ``free_thresh``."""
        return (self.occupancy != UNKNOWN) & (self.occupancy <= self.free_thresh)

    @property
    def unknown(self) -> np.ndarray:
        return ~(self.occupied | self.free)

    def cell_of(
        self, x: np.ndarray | float, y: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices of the cells holding the points (may lie outside)."""
        col = np.floor((np.asarray(x, dtype=float) - self.origin[0]) / self.resolution)
        row = np.floor((np.asarray(y, dtype=float) - self.origin[1]) / self.resolution)
        return row.astype(np.int64), col.astype(np.int64)

    def center_of(
        self, row: np.ndarray | int, col: np.ndarray | int
    ) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) in metres of the centres of cells (row, col)."""
        x = self.origin[0] + (np.asarray(col, dtype=float) + 0.5) * self.resolution
        y = self.origin[1] + (np.asarray(row, dtype=float) + 0.5) * self.resolution
        return x, y


# -- the ROS map_server format -------------------------------------------------------------------
#
# A map is two files: a YAML description and an image. map_server reads the image's pixels as
# occupancy p = (255 - v) / 255 (or v / 255 with ``negate: 1``) and, in its default ``trinary``
# mode, calls a pixel occupied when p > occupied_thresh, free when p < free_thresh and unknown
# otherwise; ``scale`` mode keeps the in-between values, ``raw`` reads v as a percentage. The
# image's row 0 is the map's top (largest y), the reverse of ``OccupancyMap``'s rows.

MAP_MODES = ("trinary", "scale", "raw")
# What map_saver writes: free, occupied, and unknown pixels (with the default thresholds).
_PGM_FREE, _PGM_OCCUPIED, _PGM_UNKNOWN = 254, 0, 205


def save_map(occupancy_map: OccupancyMap, yaml_path: str | os.PathLike[str]) -> Path:
    """Write ``occupancy_map`` as map_server does: ``NAME.yaml`` beside a binary PGM ``NAME.pgm``.

    The image is trinary (free 254, occupied 0, unknown 205, as map_saver writes them), so
    probabilities between the thresholds are saved as unknown; both files are written
    atomically, the image first, so the YAML never names a missing or partial image. Returns
    the YAML's path.
    """
    target = Path(yaml_path)
    if target.suffix.lower() == ".pgm":
        raise InputError(f"{target}: name the map's YAML file, not its image")
    image = target.with_suffix(".pgm")
    free, occupied = occupancy_map.free_thresh, occupancy_map.occupied_thresh
    if not (free > 1.0 / 255.0 and occupied < 1.0):
        raise InputError(
            f"{target}: thresholds free {free} / occupied {occupied} cannot be written as a "
            "trinary image (map_server needs free > 1/255 and occupied < 1); change them"
        )
    pixels = np.full(occupancy_map.shape, _unknown_pixel(free, occupied), dtype=np.uint8)
    pixels[occupancy_map.free] = _PGM_FREE
    pixels[occupancy_map.occupied] = _PGM_OCCUPIED
    ny, nx = occupancy_map.shape
    res = occupancy_map.resolution
    header = f"P5\n# CREATOR: twin.nav.maps {res:.3f} m/pix\n{nx} {ny}\n255\n".encode("ascii")
    body = np.ascontiguousarray(pixels[::-1]).tobytes()  # image row 0 = the map's top
    write_atomic(image, lambda handle: handle.write(header + body))
    x0, y0, yaw = occupancy_map.origin
    text = (
        f"image: {image.name}\n"
        "mode: trinary\n"
        f"resolution: {res!r}\n"
        f"origin: [{float(x0)!r}, {float(y0)!r}, {float(yaw)!r}]\n"
        "negate: 0\n"
        f"occupied_thresh: {float(occupied)!r}\n"
        f"free_thresh: {float(free)!r}\n"
    )
    return write_text_atomic(target, text)


def _unknown_pixel(free: float, occupied: float) -> int:
    """map_saver's 205 when it reads back as unknown under these thresholds, else the pixel
    nearest the middle between them."""
    p = (255 - _PGM_UNKNOWN) / 255.0
    if free < p < occupied:
        return _PGM_UNKNOWN
    return round(255.0 * (1.0 - 0.5 * (free + occupied)))


def load_map(yaml_path: str | os.PathLike[str]) -> OccupancyMap:
    """Read a map_server map (YAML + PGM image, P5 or P2), e.g. one slam_toolbox saved.

    Trinary maps load as occupancy 1 (occupied), 0 (free) or ``UNKNOWN`` by map_server's rule
    (strictly above / below the thresholds); ``scale`` maps keep each pixel's occupancy p,
    ``raw`` maps the pixel value / 100 (values above 100 unknown); ``negate`` as map_server.
    Any defect of either file is a one-line ``FileFormatError`` naming the file.
    """
    source = Path(yaml_path)
    if not source.is_file():
        raise FileFormatError(f"{source}: no such map file; check the path")
    try:
        text = source.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(
            f"{source}: cannot be read as text ({exc}); is it a map YAML?"
        ) from exc
    meta = _map_yaml(_parse_flat_yaml(text, source), source)
    image = Path(meta["image"])
    if not image.is_absolute():
        image = source.parent / image
    pixels, maxval = read_pgm(image)
    if meta["negate"]:  # map_server inverts the pixel first, in every mode
        pixels = maxval - pixels
    occupied, free = meta["occupied_thresh"], meta["free_thresh"]
    mode = meta["mode"]
    p = 1.0 - pixels / maxval
    if mode == "trinary":
        grid = np.where(p > occupied, 1.0, np.where(p < free, 0.0, UNKNOWN))
    elif mode == "scale":
        grid = p
    else:  # raw: the pixel is the occupancy in percent; map_server's -1 is 255
        grid = np.where(pixels <= 100, pixels / 100.0, UNKNOWN)
    x0, y0, yaw = meta["origin"]
    try:
        return OccupancyMap(grid[::-1].copy(), meta["resolution"], (x0, y0, yaw), occupied, free)
    except InputError as exc:
        raise FileFormatError(f"{source}: {exc}") from exc


def _map_yaml(values: dict[str, object], source: Path) -> dict[str, Any]:
    """The map_server keys of a parsed YAML, checked; map_server's defaults for the optional."""

    def number(key: str, default: float | None = None) -> float:
        if key not in values:
            if default is None:
                raise FileFormatError(f"{source}: has no {key!r}; a map_server YAML needs it")
            return default
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise FileFormatError(f"{source}: {key} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise FileFormatError(f"{source}: {key} must be finite, got {value!r}")
        return float(value)

    image = values.get("image")
    if not isinstance(image, str) or not image:
        found = "nothing" if image is None else repr(image)
        raise FileFormatError(f"{source}: 'image' must name the map's image file, got {found}")
    resolution = number("resolution")
    if resolution <= 0:
        raise FileFormatError(f"{source}: resolution must be positive, got {resolution} m/pixel")
    origin = values.get("origin")
    if (
        not isinstance(origin, list)
        or len(origin) != 3
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in origin)
        or not all(math.isfinite(v) for v in origin)
    ):
        raise FileFormatError(
            f"{source}: origin must be [x, y, yaw] (metres, radians), got {origin!r}"
        )
    if abs(origin[2]) > 1e-9:
        raise FileFormatError(
            f"{source}: origin yaw {origin[2]} rad: rotated maps are not supported; re-export it"
        )
    negate = values.get("negate", 0)
    if negate not in (0, 1) or isinstance(negate, float):
        raise FileFormatError(f"{source}: negate must be 0 or 1, got {negate!r}")
    occupied = number("occupied_thresh", 0.65)
    free = number("free_thresh", 0.196)
    if not 0.0 <= free < occupied <= 1.0:
        raise FileFormatError(
            f"{source}: thresholds must satisfy 0 <= free_thresh ({free}) < occupied_thresh "
            f"({occupied}) <= 1"
        )
    mode = values.get("mode", "trinary")
    if mode not in MAP_MODES:
        raise FileFormatError(f"{source}: mode {mode!r} is not one of {', '.join(MAP_MODES)}")
    return {
        "image": image,
        "resolution": resolution,
        "origin": tuple(float(v) for v in origin),
        "negate": bool(negate),
        "occupied_thresh": occupied,
        "free_thresh": free,
        "mode": mode,
    }


# -- a YAML reader for map_server's flat files ----------------------------------------------------

_YAML_KEY = re.compile(r"^([A-Za-z_][A-Za-z0-9_\-]*)\s*:(?:\s+(.*))?$")
_YAML_INT = re.compile(r"^[-+]?(0|[1-9][0-9]*)$")
_YAML_FLOAT = re.compile(r"^[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?$")
_YAML_SPECIAL = {
    "true": True, "True": True, "TRUE": True,
    "false": False, "False": False, "FALSE": False,
    ".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, ".nan": math.nan,
}  # fmt: skip


def _parse_flat_yaml(text: str, source: Path) -> dict[str, object]:
    """Parse the YAML subset map files use: one ``key: value`` per line at the left margin,
    values scalars (numbers, booleans, plain or quoted strings) or lists (``[a, b, c]`` or a
    block of ``- item`` lines), ``#`` comments, an optional ``---``. Anything else (a nested
    mapping, a repeated key) is refused in one line naming the file and line, never guessed."""
    values: dict[str, object] = {}
    block_key: str | None = None  # a key whose value is a block list being read
    for number, raw in enumerate(text.splitlines(), start=1):
        line = _strip_comment(raw).rstrip()
        where = f"{source}: line {number}"
        if line == "...":  # the end of the document
            break
        if not line.strip() or (line == "---" and not values):
            continue
        if line[0] in " \t" or line.startswith("- "):
            item = line.strip()
            if block_key is None or not (item.startswith("- ") or item == "-"):
                raise FileFormatError(
                    f"{where}: {raw.strip()!r} is not a 'key: value' line; map files are flat"
                )
            block = values[block_key]
            assert isinstance(block, list)
            block.append(_yaml_scalar(item[1:].strip(), where))
            continue
        match = _YAML_KEY.match(line)
        if match is None:
            raise FileFormatError(f"{where}: {raw.strip()!r} is not a 'key: value' line")
        key, value = match.group(1), (match.group(2) or "").strip()
        if key in values:
            raise FileFormatError(f"{where}: {key!r} is given twice")
        if value:
            values[key] = _yaml_value(value, where)
            block_key = None
        else:  # a block list may follow; an empty value stays an empty list
            values[key] = []
            block_key = key
    return values


def _strip_comment(line: str) -> str:
    """``line`` without a ``#`` comment (one at the start or after a space, outside quotes)."""
    quote = None
    for i, char in enumerate(line):
        if quote:
            if char == quote:
                quote = None
        elif char in "'\"":
            quote = char
        elif char == "#" and (i == 0 or line[i - 1] in " \t"):
            return line[:i]
    return line


def _yaml_value(text: str, where: str) -> object:
    if text.startswith("["):
        if not text.endswith("]"):
            raise FileFormatError(f"{where}: the list {text!r} is not closed with ']'")
        inner = text[1:-1].strip()
        return [_yaml_scalar(item.strip(), where) for item in inner.split(",")] if inner else []
    if text.startswith(("{", "&", "*", "!", "|", ">")):
        raise FileFormatError(f"{where}: {text!r}: map files hold plain values and lists only")
    return _yaml_scalar(text, where)


def _yaml_scalar(text: str, where: str) -> object:
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    if text[:1] in ("'", '"', "[", "{"):
        raise FileFormatError(f"{where}: cannot read the value {text!r}")
    if text in _YAML_SPECIAL:
        return _YAML_SPECIAL[text]
    if _YAML_INT.match(text):
        return int(text)
    if _YAML_FLOAT.match(text):
        return float(text)
    return text


# -- PGM images -----------------------------------------------------------------------------------


def read_pgm(path: str | os.PathLike[str]) -> tuple[np.ndarray, int]:
    """Read a binary (P5) or plain (P2) PGM: the pixels (height, width) as stored, row 0 at the
    top, and the image's maxval. Defects are one-line ``FileFormatError``s naming the file."""
    source = Path(path)
    if not source.is_file():
        raise FileFormatError(
            f"{source}: the map's image does not exist; check 'image' in the YAML"
        )
    data = source.read_bytes()
    magic = data[:2]
    if magic not in (b"P5", b"P2"):
        shown = "a PNG" if data[:4] == b"\x89PNG" else f"magic {magic!r}"
        raise FileFormatError(
            f"{source}: is {shown}, not a PGM image (P5 or P2); convert it to PGM"
        )
    fields, end = _pgm_header(data, magic == b"P5", source)
    width, height, maxval = fields
    if width < 1 or height < 1 or not 1 <= maxval <= 65535:
        raise FileFormatError(
            f"{source}: PGM size {width}x{height}, maxval {maxval} are out of range"
        )
    count = width * height
    if magic == b"P5":
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        need = count * dtype.itemsize
        if len(data) - end < need:
            raise FileFormatError(
                f"{source}: PGM is truncated: {len(data) - end} bytes of pixels, "
                f"{width}x{height} need {need}"
            )
        pixels = np.frombuffer(data, dtype=dtype, count=count, offset=end).astype(np.int64)
    else:
        words = _strip_pgm_comments(data[end:]).split()
        if len(words) < count:
            raise FileFormatError(
                f"{source}: PGM is truncated: {len(words)} pixels, {width}x{height} need {count}"
            )
        try:
            pixels = np.array([int(w) for w in words[:count]], dtype=np.int64)
        except ValueError as exc:
            raise FileFormatError(f"{source}: a PGM pixel is not a whole number ({exc})") from exc
    if pixels.size and (pixels.min() < 0 or pixels.max() > maxval):
        raise FileFormatError(f"{source}: PGM pixels exceed its maxval {maxval}")
    return pixels.reshape(height, width), maxval


def _pgm_header(data: bytes, binary: bool, source: Path) -> tuple[list[int], int]:
    """Width, height and maxval after the magic, skipping comments; and the offset of the
    pixels (one whitespace byte after maxval, as the format says)."""
    fields: list[int] = []
    i = 2
    while len(fields) < 3:
        if i >= len(data):
            raise FileFormatError(f"{source}: PGM header ends early (needs width, height, maxval)")
        char = data[i : i + 1]
        if char == b"#":
            newline = data.find(b"\n", i)
            i = len(data) if newline < 0 else newline + 1
        elif char.isspace():
            i += 1
        else:
            start = i
            while i < len(data) and not data[i : i + 1].isspace() and data[i : i + 1] != b"#":
                i += 1
            token = data[start:i]
            if not token.isdigit():
                raise FileFormatError(f"{source}: PGM header field {token[:20]!r} is not a number")
            fields.append(int(token))
    if binary and (i >= len(data) or not data[i : i + 1].isspace()):
        raise FileFormatError(f"{source}: PGM header is not followed by its pixels")
    return fields, i + 1


def _strip_pgm_comments(data: bytes) -> bytes:
    return re.sub(rb"#[^\n]*", b" ", data)
