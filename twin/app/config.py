"""The survey run's configuration: a TOML file read into validated, typed settings.

Every mistake is a one-line ``ConfigError`` naming the file, the key and the problem, e.g.
``survey.toml: mission.stops[2]: expected [x, y] in metres, got [1.0]``. Unknown keys are errors
too, so a misspelt key never silently falls back to a default. Degrees appear only here (the
file is for people); everything past this module is in radians and metres.

The shipped default, ``scenes/living_room_survey.toml``, runs the paper's mission in the twin.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.core.errors import InputError
from twin.core.fusion import RULES, FusionRule, make_rule
from twin.core.grid import GridSpec
from twin.resources import scenes_dir

DEFAULT_CONFIG_NAME = "living_room_survey.toml"
RERUN_MODES = ("save", "spawn", "serve", "off")
DEVICE_ROLES = ("camera", "pantilt", "base")


class ConfigError(InputError):
    """A configuration file is unreadable or a key in it is wrong."""


@dataclass(frozen=True)
class DeviceConfig:
    """One device: its ``type`` picks the implementation; ``options`` go to its factory."""

    role: str
    type: str
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class MissionConfig:
    """Where the robot stops and how it looks around at each stop.

    ``headings`` are the optical axis's map-frame directions (radians) to view at every stop;
    ``turn`` says how a heading is reached: ``"pan"`` pans the head where its range allows and
    turns the base only for the rest, ``"base"`` turns the base with the head straight.
    """

    start: tuple[float, float, float]  # x, y (m), yaw (rad)
    stops: tuple[tuple[float, float], ...]
    headings: tuple[float, ...]
    turn: str = "pan"
    tilt: float = 0.0


@dataclass(frozen=True)
class GridConfig:
    spec: GridSpec
    supersample: int
    rule: FusionRule
    max_range: float | None
    peak_separation: float = 0.5  # metres between distinct hypotheses (see AccumulatorGrid.peaks)


@dataclass(frozen=True)
class ObjectConfig:
    """An object to find: its RFCH model file, or ``None`` to train one from the scene."""

    name: str
    model: Path | None
    body: str | None  # the scene body that is this object (ground truth and training), if any


@dataclass(frozen=True)
class SurveyConfig:
    source: str
    scene: Path
    devices: dict[str, DeviceConfig]
    mission: MissionConfig
    grid: GridConfig
    objects: tuple[ObjectConfig, ...]
    detector: dict[str, Any]
    out: Path
    rerun: str
    cache: Path
    twin_time_scale: float = 1.0  # serial twins: simulated seconds per wall-clock second


def default_config_path() -> Path:
    return scenes_dir() / DEFAULT_CONFIG_NAME


class _Table:
    """A TOML table being read: remembers its key path for errors and which keys were used."""

    def __init__(self, data: Any, path: str, source: str) -> None:
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: {path or 'the file'}: expected a table")
        self.data, self.path, self.source = data, path, source
        self.used: set[str] = set()

    def fail(self, key: str, problem: str) -> ConfigError:
        where = f"{self.path}.{key}" if self.path else key
        return ConfigError(f"{self.source}: {where}: {problem}")

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise self.fail(key, "is required")
            return default
        return self.data[key]

    def table(self, key: str, required: bool = True) -> _Table:
        self.used.add(key)
        if key not in self.data and not required:
            return _Table({}, self._child(key), self.source)
        return _Table(self.get(key), self._child(key), self.source)

    def number(
        self,
        key: str,
        default: Any = ...,
        check: Callable[[float], bool] | None = None,
        expect: str = "a number",
    ) -> float:
        value = self.get(key, default)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise self.fail(key, f"expected {expect}, got {value!r}")
        if check is not None and not check(float(value)):
            raise self.fail(key, f"expected {expect}, got {value!r}")
        return float(value)

    def integer(self, key: str, default: Any = ..., minimum: int = 1) -> int:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.fail(key, f"expected a whole number >= {minimum}, got {value!r}")
        return value

    def choice(self, key: str, options: tuple[str, ...], default: Any = ...) -> str:
        value = self.get(key, default)
        if value not in options:
            raise self.fail(key, f"expected one of {', '.join(options)}, got {value!r}")
        return value

    def string(self, key: str, default: Any = ...) -> str:
        value = self.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"expected a non-empty string, got {value!r}")
        return value

    def numbers(self, key: str, count: int, what: str, value: Any = ...) -> tuple[float, ...]:
        value = self.get(key) if value is ... else value
        ok = isinstance(value, list) and len(value) == count
        ok = ok and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in value
        )
        if not ok:
            raise self.fail(key, f"expected {what}, got {value!r}")
        return tuple(float(v) for v in value)

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.fail(unknown[0], "unknown key (check its spelling and its table)")

    def _child(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key


def load_config(
    path: str | Path | None = None, base_dir: Path | None = None, folder: Path | None = None
) -> SurveyConfig:
    """Read and validate a survey config (the shipped default when ``path`` is None).

    Relative paths inside the file (scene, model files) are taken relative to ``folder`` (the
    file's own folder by default: a run's copy of its config passes the original's), except
    ``run.out`` and ``run.cache``, relative to ``base_dir`` (default: the working directory),
    since they say where this run writes.
    """
    source = Path(path) if path is not None else default_config_path()
    name = source.name
    try:
        data = tomllib.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{source}: no such config file; check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{source}: cannot read it ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{name}: not valid TOML ({exc}); fix the file") from None
    return parse_config(data, name, folder or source.parent, base_dir or Path.cwd())


def parse_config(data: dict[str, Any], source: str, folder: Path, base_dir: Path) -> SurveyConfig:
    """Validate already-parsed TOML ``data`` (``source`` names it in errors)."""
    root = _Table(data, "", source)
    run = root.table("run", required=False)
    out = base_dir / run.string("out", "runs/survey")
    rerun = run.choice("rerun", RERUN_MODES, "save")
    cache = base_dir / run.string("cache", "runs/cache")
    run.finish()

    scene_table = root.table("scene")
    scene = _resolve(scene_table.string("file"), folder, scenes_dir())
    if not scene.is_file():
        raise scene_table.fail("file", f"no scene file {scene}; check the path")
    scene_table.finish()

    devices_table = root.table("robot")
    devices = {}
    for role in DEVICE_ROLES:
        table = devices_table.table(role)
        kind = table.string("type")
        options = {k: v for k, v in table.data.items() if k != "type"}
        devices[role] = DeviceConfig(role, kind, options)
    devices_table.finish()

    mission = _mission(root.table("mission"))
    grid = _grid(root.table("grid"))
    twins = root.table("serial_twins", required=False)
    time_scale = twins.number("time_scale", 1.0, lambda v: 0.0 < v <= 20.0, "a factor in (0, 20]")
    twins.finish()
    detector_table = root.table("detector", required=False)
    detector = dict(detector_table.data)
    objects = _objects(root.table("objects"), folder)
    root.finish()
    return SurveyConfig(
        source, scene, devices, mission, grid, objects, detector, out, rerun, cache, time_scale
    )


def _resolve(text: str, folder: Path, fallback: Path) -> Path:
    """A path relative to the config's folder, or to the shipped scenes if it is not there."""
    candidate = Path(text).expanduser()
    if candidate.is_absolute():
        return candidate
    local = folder / candidate
    return local if local.exists() else fallback / candidate


def _mission(table: _Table) -> MissionConfig:
    start = table.numbers("start", 3, "[x, y, yaw_deg]")
    stops_value = table.get("stops")
    if not isinstance(stops_value, list) or not stops_value:
        raise table.fail("stops", "expected a list of [x, y] stops in metres")
    stops = tuple(
        table.numbers(f"stops[{i}]", 2, "[x, y] in metres", value=stop)  # type: ignore[misc]
        for i, stop in enumerate(stops_value)
    )
    views = table.integer("views_per_stop", 8)
    step = table.number(
        "view_step_deg", 360.0 / views, lambda v: 0.0 < v <= 360.0, "an angle in (0, 360] degrees"
    )
    first = table.number("first_heading_deg", 0.0)
    headings = tuple(math.radians(first + i * step) for i in range(views))
    turn = table.choice("turn", ("pan", "base"), "pan")
    tilt = table.number("tilt_deg", 0.0, lambda v: -30.0 <= v <= 90.0, "a tilt in [-30, 90]")
    table.finish()
    return MissionConfig(
        (start[0], start[1], math.radians(start[2])), stops, headings, turn, math.radians(tilt)
    )


def _grid(table: _Table) -> GridConfig:
    extent = table.numbers("extent", 4, "[x_min, y_min, x_max, y_max] in metres")
    cell = table.number("cell_size", 0.1, lambda v: v > 0.0, "a positive size in metres")
    try:
        spec = GridSpec(*extent, cell)
    except InputError as exc:
        raise table.fail("extent", str(exc)) from None
    supersample = table.integer("supersample", 10)
    fusion = table.choice("fusion", tuple(RULES), "accumulate")
    params: dict[str, float] = {}
    if fusion == "logodds":
        unit = (lambda v: 0.0 <= v <= 1.0, "a rate in [0, 1]")
        params = {
            key: table.number(key, None if key != "threshold" else 0.5, *unit)
            for key in ("p_fp", "p_fn", "threshold")
        }
        if params["p_fp"] is None or params["p_fn"] is None:
            raise table.fail("p_fp", "logodds needs the detector's p_fp and p_fn (twin roc)")
    elif fusion == "normalized":
        params["min_observed"] = table.number(
            "min_observed", 1.0, lambda v: v >= 0.0, "a non-negative coverage"
        )
    max_range = table.number("max_range", None, lambda v: v > 0.0, "a positive range in metres")
    separation = table.number("peak_separation", 0.5, lambda v: v >= 0.0, "a distance >= 0 m")
    table.finish()
    return GridConfig(spec, supersample, make_rule(fusion, **params), max_range, separation)


def _objects(table: _Table, folder: Path) -> tuple[ObjectConfig, ...]:
    if not table.data:
        raise ConfigError(f"{table.source}: objects: name at least one object to find")
    objects = []
    for name in list(table.data):
        entry = table.table(name)
        model_text = entry.get("model", None)
        if model_text is not None and (not isinstance(model_text, str) or not model_text):
            raise entry.fail("model", f"expected a model file path, got {model_text!r}")
        body = entry.get("body", None)
        if body is not None and (not isinstance(body, str) or not body):
            raise entry.fail("body", f"expected a scene body name, got {body!r}")
        if model_text is None and body is None:
            raise entry.fail("model", "give a model file, or the scene body to train one from")
        model = None if model_text is None else _resolve(model_text, folder, folder)
        entry.finish()
        objects.append(ObjectConfig(name, model, body))
    table.finish()
    return tuple(objects)
