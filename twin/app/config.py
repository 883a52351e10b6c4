"""The mission's configuration: a TOML file (plus ``--set`` overrides) read into typed settings.

Every mistake is a one-line ``ConfigError`` naming the file, the key and the problem, e.g.
``survey.toml: mission.stops[2]: expected [x, y] in metres, got [1.0]``; a key that came from
``--set`` is named as such (``--set grid.fusion: expected one of ...``). Unknown keys are errors
too, so a misspelt key never silently falls back to a default. Each device type declares its
options as a dataclass (``twin.app.device_types``), so factories only see typed values. Degrees
appear only here (the file is for people); everything past this module is in radians and metres.

A config is named by a path, or by the name of a shipped one (``living_room_serial_twins``);
the shipped default, ``scenes/living_room_survey.toml``, runs the paper's mission in the twin.
"""

from __future__ import annotations

import functools
import json
import math
import tomllib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from twin.app.device_types import OPTIONAL_ROLES, ROLES, device_type, types_of
from twin.app.planner_names import PLANNERS  # noqa: F401 - the config's planner names
from twin.core.errors import InputError
from twin.core.fusion import RULES, FusionRule, make_rule
from twin.core.grid import GridSpec
from twin.core.options import OptionError, option, parse_options
from twin.core.visibility import SUPPORT_KINDS
from twin.resources import scenes_dir

DEFAULT_CONFIG_NAME = "living_room_survey.toml"
# The confidence's temperature, fitted on development runs (benchmarks/fusion_generality.py
# --fit-temperature on seeds no reported figure uses; README "How sure is it?").
TEMPERATURE = 1.23
RERUN_MODES = ("save", "spawn", "serve", "off")
DEVICE_ROLES = ROLES
TWIN_PORT = "twin"  # a serial device's port that names its serial twin (an emulator on a pty)


class ConfigError(InputError):
    """A configuration file is unreadable or a key in it is wrong."""


@dataclass(frozen=True)
class DeviceConfig:
    """One device: its ``type`` picks the implementation; ``options`` is that type's dataclass
    (``twin.app.device_types``), already checked."""

    role: str
    type: str
    options: Any

    def option(self, name: str, default: Any = None) -> Any:
        return getattr(self.options, name, default)


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
    stop_tilts: tuple[float, ...] = ()  # radians, one per stop; empty: every stop at ``tilt``
    # radians: every stop sweeps its headings again this far down, for the objects that stand on
    # the floor; None: no such sweep
    floor_tilt: float | None = None

    def tilt_at(self, stop: int) -> float:
        """The head's tilt (radians, up positive) for every view of stop ``stop``."""
        return self.stop_tilts[stop] if self.stop_tilts else self.tilt


@dataclass(frozen=True)
class GridConfig:
    """``[grid]``. ``rule`` is None for ``fusion = "calibrated"``: that rule's log-likelihood
    ratios come with the detector's model, so it is made once the models are loaded."""

    spec: GridSpec
    supersample: int
    rule: FusionRule | None
    max_range: float | None
    peak_separation: float = 0.5  # metres between distinct hypotheses (see AccumulatorGrid.peaks)
    fusion: str = "accumulate"
    direction_bins: int = 1  # viewpoint-bias correction: directions a cell's evidence is kept in
    visibility: bool = True  # weigh each wedge by what the camera could see (a [visibility] model)
    by_distance: bool = False  # calibrated: each distance band's own likelihood ratios
    room_baseline: bool = True  # subtract what the room gains a cell without the object
    # count a wedge's cells where the best patch's row shows an object standing on a surface
    # there (twin.core.height.HeightCheck; needs a [visibility] model)
    height_check: bool = False


@dataclass(frozen=True)
class VisibilityOptions:
    """``[visibility]``: which cells a wedge may credit or penalise
    (``twin.app.visibility_models``)."""

    source: Literal["auto", "depth", "model", "map", "none"] = option(
        "auto",
        doc='where the depth comes from: "depth" the frame\'s own (the twin\'s camera), "model" '
        'the scene rendered at the localized pose, "map" the laser map; "auto" the first the '
        'robot has; "none" every cell in a wedge is seen (the paper)',
    )
    supports: Literal["model", "anywhere"] = option(
        "model",
        doc='where an object may stand: "model" on the scene\'s surfaces (floor, tops, shelves), '
        '"anywhere" at any height up to 2 m',
    )
    object_height_m: float = option(
        0.2, unit="m", low=0.02, high=2.0, doc="how tall the smallest sought object is"
    )
    object_radius_m: float = option(
        0.15, unit="m", low=0.0, high=1.0,
        doc="how far the largest sought object's near side stands before its centre: the depth "
        "there hits the object itself, which does not hide it",
    )  # fmt: skip


@dataclass(frozen=True)
class ConfidenceOptions:
    """``[confidence]``: how each estimate's confidence is read (``twin.core.confidence``)."""

    radius_m: float = option(
        0.2, unit="m", low=0.01, high=5.0, doc="the estimate is right when within this distance"
    )
    temperature: float = option(
        TEMPERATURE, low=0.01, high=1000.0,
        doc="divides the summed log-likelihood ratios: repeated views of one room are not "
        "independent evidence (fitted on development runs: README)",
    )  # fmt: skip
    p_absent: float = option(
        0.1, low=0.0, high=0.99, doc="prior probability that an object is not in the mapped area"
    )


@dataclass(frozen=True)
class SearchOptions:
    """``[search]``: how ``twin search`` chooses its views and when it stops
    (``twin.app.search``)."""

    planner: Literal["information", "detection", "coverage", "random", "survey"] = option(
        "information",
        doc='"information": the view of most expected information per second; "detection": of '
        'the highest probability of detecting the object per second (Ye & Tsotsos); "coverage":'
        ' of the most cells seen least; "random": any reachable view; "survey": the mission\'s '
        "fixed plan",
    )
    confidence: float = option(
        0.95, low=0.5, high=1.0, doc="stop when every sought object's confidence reaches this"
    )
    absent: float = option(
        0.95, low=0.5, high=1.0, doc="declare an object absent when P(absent) reaches this"
    )
    max_views: int = option(40, low=1, high=10000, doc="stop after this many views")
    max_time_s: float = option(
        900.0, unit="s", low=1.0, high=86400.0, doc="stop once the robot's clock passes this"
    )
    spacing_m: float = option(
        0.4, unit="m", low=0.1, high=5.0, doc="views are taken from a lattice of this spacing"
    )
    headings: int = option(8, low=4, high=64, doc="directions a view may face at each place")
    clearance_m: float = option(
        0.2, unit="m", low=0.0, high=2.0,
        doc="views are taken this much farther from obstacles than the drives keep: room to "
        "turn, and to localize (the narrow gaps between furniture are driven through only)",
    )  # fmt: skip
    view_time_s: float = option(
        1.5, unit="s", low=0.0, high=600.0,
        doc="what a view costs besides moving (capture, settling): keeps cheap views honest",
    )  # fmt: skip
    seed: int = option(0, low=0, doc='seed of the "random" planner')
    repeat_discount: float = option(
        0.7, low=0.0, high=1.0,
        doc="what a view of a cell from where it was seen before is still worth, per earlier "
        "such view: it mostly shows what they showed (the same background, the same "
        "distractor); 1 trusts the belief's independent views",
    )  # fmt: skip
    survey_after: int = option(
        16, low=0, high=10000,
        doc="after this many views not yet sure, the information, detection and coverage "
        "planners fly the mission's fixed plan for the rest of the budget (0: never): it does "
        "not depend on a belief that may be wrong",
    )  # fmt: skip
    follow_up_views: int = option(
        0, low=0, high=10000,
        doc="twin survey and batch-survey: after the fixed plan, up to this many more views of "
        "the places an object may be while its grid's peaks are close (follow_up_ratio): "
        "each the view likeliest to see them per second; 0: the fixed plan only",
    )  # fmt: skip
    follow_up_ratio: float = option(
        1.5, low=1.0, high=100.0,
        doc="the follow-up looks again while an object's first peak is less than this many "
        "times its next, at the peaks that come within it",
    )  # fmt: skip
    follow_up_range_m: float = option(
        2.5, unit="m", low=0.5, high=100.0,
        doc="the follow-up's views are taken within this distance of a place it looks at",
    )  # fmt: skip
    temperature: float = option(
        2.0, low=0.01, high=1000.0,
        doc="the confidence's temperature during a search: the views a search chooses return "
        "to what it suspects, so their evidence is less independent than a survey's "
        "(confidence.temperature); fitted on development searches (README)",
    )  # fmt: skip


@dataclass(frozen=True)
class ObjectConfig:
    """An object to find: its RFCH model file, or ``None`` to train one from the scene."""

    name: str
    model: Path | None
    body: str | None  # the scene body that is this object (ground truth and training), if any
    # the kinds of surface it stands on (keys of twin.core.visibility.SUPPORT_KINDS); empty:
    # any. A toy crate that lives on the floor is no look-alike's peak on a desk.
    stands_on: tuple[str, ...] = ()
    # how tall it stands (m), its own [visibility] object_height_m. Its centre is half this
    # above the surface it is found on.
    object_height_m: float | None = None


@dataclass(frozen=True)
class LocalizationOptions:
    """``[localization]``: how a base with ``pose_source = "laser"`` localizes on a map."""

    map: str = option(
        "scene",
        doc="the map: a map_server YAML file (as slam_toolbox, Cartographer, gmapping or "
        '"twin map" write them), or "scene" to cut it from the scene at the laser\'s height',
    )
    resolution: float = option(0.05, unit="m", low=0.01, high=0.5, doc='cells of a "scene" map')
    particles: int = option(500, low=50, high=20000, doc="particles of the Monte Carlo filter")
    beams: int = option(60, low=8, high=361, doc="beams of each scan the filter weighs")
    start_sigma_m: float = option(
        0.10, unit="m", low=0.0, high=5.0, doc="how well the mission's start position is known"
    )
    start_sigma_deg: float = option(
        5.0, unit="deg", low=0.0, high=180.0, doc="how well the start heading is known"
    )
    global_start: bool = option(
        False, doc="ignore the mission's start pose and localize globally on the whole map"
    )
    max_sigma_m: float = option(
        0.05, unit="m", low=0.001, high=5.0, doc="views whose position is less sure go unfused"
    )
    max_sigma_deg: float = option(
        2.0, unit="deg", low=0.01, high=180.0, doc="views whose heading is less sure go unfused"
    )
    seed: int = option(0, low=0, doc="seed of the filter's randomness")


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
    data: dict[str, Any] = field(default_factory=dict, repr=False)  # the TOML it was read from
    localization: LocalizationOptions | None = None  # with a base whose pose_source is "laser"
    map_file: Path | None = None  # the localization map's YAML (None: cut from the scene)
    visibility: VisibilityOptions = field(default_factory=VisibilityOptions)
    confidence: ConfidenceOptions = field(default_factory=ConfidenceOptions)
    search: SearchOptions = field(default_factory=SearchOptions)

    @property
    def object_heights(self) -> dict[str, float]:
        """Each object's height (m): its own ``object_height_m``, else ``[visibility]``'s."""
        default = self.visibility.object_height_m
        return {obj.name: obj.object_height_m or default for obj in self.objects}

    @property
    def floor_objects(self) -> tuple[str, ...]:
        """The objects that stand on the floor (``stands_on``): the mission's floor sweep
        (``[mission] floor_tilt_deg``) looks for these."""
        return tuple(obj.name for obj in self.objects if "floor" in obj.stands_on)

    @property
    def uses_sim_world(self) -> bool:
        """Whether the robot lives in the MuJoCo world (sim devices, or serial twins)."""
        return any(d.type == "sim" or d.option("port") == TWIN_PORT for d in self.devices.values())


def default_config_path() -> Path:
    return scenes_dir() / DEFAULT_CONFIG_NAME


def shipped_configs() -> list[str]:
    """The names of the mission configs shipped in scenes/ (``--config NAME`` finds them)."""
    return sorted(p.stem for p in scenes_dir().glob("*.toml"))


def resolve_config(name: str | Path | None) -> Path:
    """The config file ``name`` means: a file at that path, else (for a bare name) a shipped
    config of that name, with or without ``.toml``; ``None`` is the shipped default."""
    if name is None:
        return default_config_path()
    path = Path(name).expanduser()
    if path.is_file():
        return path
    if path.is_dir():
        raise ConfigError(f"--config {name}: is a folder; give a config file (.toml)")
    if path.parent == Path():
        for candidate in (scenes_dir() / path.name, scenes_dir() / f"{path.name}.toml"):
            if candidate.is_file():
                return candidate
    raise ConfigError(
        f"--config {name}: no such file, and no shipped config of that name; "
        f"shipped: {', '.join(shipped_configs())}"
    )


class _Table:
    """A TOML table being read: remembers its key path for errors and which keys were used.

    ``overrides`` holds the dotted keys that came from ``--set``: an error about one of them
    names ``--set`` rather than the file, so the user looks in the right place."""

    def __init__(
        self, data: Any, path: str, source: str, overrides: frozenset[str] = frozenset()
    ) -> None:
        self.path, self.source, self.overrides = path, source, overrides
        if not isinstance(data, dict):
            raise self._error(path or "the file", "expected a table")
        self.data = data
        self.used: set[str] = set()

    def _error(self, where: str, problem: str) -> ConfigError:
        if any(where == key or where.startswith((f"{key}.", f"{key}[")) for key in self.overrides):
            return ConfigError(f"--set {where}: {problem}")
        return ConfigError(f"{self.source}: {where}: {problem}")

    def fail(self, key: str, problem: str) -> ConfigError:
        return self._error(self._child(key), problem)

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
            return _Table({}, self._child(key), self.source, self.overrides)
        return _Table(self.get(key), self._child(key), self.source, self.overrides)

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


# -- reading -----------------------------------------------------------------------------------


def read_toml(path: Path) -> dict[str, Any]:
    """A config file's TOML, or a one-line ``ConfigError`` saying why it cannot be read."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file; check the path") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder; give a config file (.toml)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read it ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path.name}: not valid TOML ({exc}); fix the file") from None


def apply_overrides(data: dict[str, Any], settings: Iterable[str]) -> tuple[dict, frozenset[str]]:
    """``data`` with every ``KEY=VALUE`` of ``settings`` applied, and the set of keys set.

    KEY is a dotted path into the tables (``grid.fusion``, ``robot.base.pose_source``); VALUE is
    TOML (``4``, ``[0.0, 0.01]``, ``"normalized"``). Because a shell strips quotes, a VALUE that
    is not TOML but a bare word (``normalized``) is taken as that string. Whether the key exists
    and the value fits is checked with the rest of the config, which names ``--set`` in errors.
    """
    import copy

    data = copy.deepcopy(data)
    keys: set[str] = set()
    for setting in settings:
        key, sep, text = setting.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not sep or not key or any(not p.strip() for p in parts):
            raise ConfigError(
                f"--set {setting!r}: expected KEY=VALUE with a dotted KEY, "
                "e.g. --set mission.views_per_stop=4"
            )
        value = _toml_value(key, text.strip())
        table = data
        for depth, part in enumerate(parts[:-1]):
            child = table.setdefault(part, {})
            if not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise ConfigError(f"--set {key}: {where} is not a table, so it has no keys")
            table = child
        table[parts[-1]] = value
        keys.add(key)
    return data, frozenset(keys)


def _toml_value(key: str, text: str) -> Any:
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        pass
    if text and all(c.isalnum() or c in "_-./:" for c in text):
        return text  # a bare word: a shell ate the quotes around a string
    raise ConfigError(
        f"--set {key}={text}: VALUE is not TOML (a number, true/false, a string or a [list]); "
        "quote it for the shell, e.g. --set 'grid.extent=[0.0, 0.0, 4.5, 6.0]'"
    )


def load_config(
    path: str | Path | None = None,
    base_dir: Path | None = None,
    folder: Path | None = None,
    overrides: Sequence[str] = (),
) -> SurveyConfig:
    """Read and validate a mission config (a path, a shipped config's name, or the default),
    with ``overrides`` (``KEY=VALUE`` strings, as ``--set`` gives them) applied.

    Relative paths inside the file (scene, model files) are taken relative to ``folder`` (the
    file's own folder by default: a run's copy of its config passes the original's), except
    ``run.out`` and ``run.cache``, relative to ``base_dir`` (default: the working directory),
    since they say where this run writes.
    """
    source = resolve_config(path)
    data, keys = apply_overrides(read_toml(source), overrides)
    return parse_config(data, source.name, folder or source.parent, base_dir or Path.cwd(), keys)


def parse_config(
    data: dict[str, Any],
    source: str,
    folder: Path,
    base_dir: Path,
    overrides: frozenset[str] = frozenset(),
) -> SurveyConfig:
    """Validate already-parsed TOML ``data`` (``source`` names it in errors; ``overrides`` are
    the keys that came from ``--set``)."""
    root = _Table(data, "", source, overrides)
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

    devices = _devices(root.table("robot"))
    mission = _mission(root.table("mission"))
    grid = _grid(root.table("grid"), scene)
    twins = root.table("serial_twins", required=False)
    time_scale = twins.number("time_scale", 1.0, lambda v: 0.0 < v <= 20.0, "a factor in (0, 20]")
    twins.finish()
    detector = _detector(root.table("detector", required=False))
    objects = _objects(root.table("objects"), folder)
    localization, map_file = _localization(root, devices, folder)
    visibility = _typed(root, "visibility", VisibilityOptions)
    if visibility.source == "depth" and devices["camera"].type != "sim":
        raise root.fail(
            "visibility.source",
            f'a {devices["camera"].type!r} camera gives no depth; use "model" (the scene '
            'rendered at the robot\'s pose), "map" or "auto"',
        )
    confidence = _typed(root, "confidence", ConfidenceOptions)
    search = _typed(root, "search", SearchOptions)
    if search.follow_up_views > 0 and localization is None:
        raise root.fail(
            "search.follow_up_views",
            "the follow-up plans its drives on the localization map: set "
            'robot.base.pose_source = "laser" (with a [localization] map), or set it to 0',
        )
    root.finish()
    return SurveyConfig(
        source,
        scene,
        devices,
        mission,
        grid,
        objects,
        detector,
        out,
        rerun,
        cache,
        time_scale,
        data,
        localization,
        map_file,
        visibility,
        confidence,
        search,
    )


def _typed(root: _Table, name: str, declared: type) -> Any:
    """An optional table of typed options (defaults when it is absent)."""
    if not root.has(name):
        return declared()
    table = root.table(name)
    try:
        options = parse_options(declared, table.data, f"[{name}]")
    except OptionError as exc:
        raise table.fail(exc.key, exc.problem) from None
    table.used.update(table.data)
    return options


def _resolve(text: str, folder: Path, fallback: Path) -> Path:
    """A path relative to the config's folder, or to the shipped scenes if it is not there."""
    candidate = Path(text).expanduser()
    if candidate.is_absolute():
        return candidate
    local = folder / candidate
    return local if local.exists() else fallback / candidate


def _devices(robot: _Table) -> dict[str, DeviceConfig]:
    devices = {}
    for role in (*DEVICE_ROLES, *OPTIONAL_ROLES):
        if role in OPTIONAL_ROLES and not robot.has(role):
            continue
        table = robot.table(role)
        kind = table.string("type")
        try:
            declared = device_type(role, kind)
        except KeyError:
            raise table.fail(
                "type", f"unknown type {kind!r}; use one of {', '.join(types_of(role))}"
            ) from None
        given = {k: v for k, v in table.data.items() if k != "type"}
        try:
            options = parse_options(declared.options, given, f"type {kind!r}")
        except OptionError as exc:
            raise table.fail(exc.key, exc.problem) from None
        table.used.update(table.data)
        devices[role] = DeviceConfig(role, kind, options)
    robot.finish()
    _check_wiring(robot, devices)
    return devices


def _check_wiring(robot: _Table, devices: dict[str, DeviceConfig]) -> None:
    """What one device's options ask of another, checked before anything opens a port."""
    head, base = devices["pantilt"], devices["base"]
    if head.type != "vcc4":
        return
    pantilt = robot.table("pantilt")
    if head.options.wiring == "aux" and base.type != "arcos":
        raise pantilt.fail(
            "wiring", '"aux" tunnels through the base\'s AUX port, so robot.base.type must be '
            '"arcos"; or use wiring = "direct" with a port'
        )  # fmt: skip
    if head.options.wiring == "direct" and head.options.port is None:
        raise pantilt.fail(
            "port", f'give the serial port (e.g. /dev/ttyUSB0), or "{TWIN_PORT}" for its serial '
            'twin; or use wiring = "aux" on an ARCOS base'
        )  # fmt: skip


def _localization(
    root: _Table, devices: dict[str, DeviceConfig], folder: Path
) -> tuple[LocalizationOptions | None, Path | None]:
    """The ``[localization]`` table, checked against the base's ``pose_source``: a laser pose
    needs a laser and a map. The table is checked even when another pose source leaves it
    unused (``--set robot.base.pose_source=odometry`` on a laser config), so it stays valid."""
    base = devices["base"]
    by_laser = base.option("pose_source") == "laser"
    if not root.has("localization"):
        if by_laser and "laser" not in devices:
            raise root.fail("robot.base.pose_source", '"laser" needs a [robot.laser] device')
        if not by_laser:
            return None, None
        options = LocalizationOptions()
    else:
        table = root.table("localization")
        try:
            options = parse_options(LocalizationOptions, table.data, "[localization]")
        except OptionError as exc:
            raise table.fail(exc.key, exc.problem) from None
        table.used.update(table.data)
        if not by_laser:
            return None, None  # checked, kept for when the pose source is the laser again
    if "laser" not in devices:
        raise root.fail("robot.base.pose_source", '"laser" needs a [robot.laser] device')
    if options.map == "scene":
        in_the_twin = any(
            d.type == "sim" or d.option("port") == TWIN_PORT for d in devices.values()
        )
        if not in_the_twin:
            raise root.fail(
                "localization.map",
                '"scene" cuts the map from the twin\'s scene; on the robot give a map_server '
                "YAML file (build one with 'twin map')",
            )
        return options, None
    map_file = _resolve(options.map, folder, scenes_dir())
    if not map_file.is_file():
        raise root.fail("localization.map", f"no map file {map_file}; check the path")
    return options, map_file


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
    in_range = (lambda v: -30.0 <= v <= 90.0, "a tilt in [-30, 90] degrees")
    tilt = table.number("tilt_deg", 0.0, *in_range)
    stop_tilts: tuple[float, ...] = ()
    if table.has("stop_tilts_deg"):
        # An object on the floor near a stop needs the head down, one on a high shelf level.
        values = table.get("stop_tilts_deg")
        if not isinstance(values, list) or len(values) != len(stops):
            raise table.fail(
                "stop_tilts_deg", f"expected one tilt in degrees per stop ({len(stops)}), got "
                f"{values!r}"
            )  # fmt: skip
        for i, v in enumerate(values):
            if isinstance(v, bool) or not isinstance(v, int | float) or not in_range[0](v):
                raise table.fail(f"stop_tilts_deg[{i}]", f"expected {in_range[1]}, got {v!r}")
        stop_tilts = tuple(math.radians(v) for v in values)
    floor_tilt = None
    if table.has("floor_tilt_deg"):
        floor_tilt = math.radians(
            table.number(
                "floor_tilt_deg", None, lambda v: -30.0 <= v < 0.0, "a tilt in [-30, 0) degrees"
            )
        )
    table.finish()
    return MissionConfig(
        (start[0], start[1], math.radians(start[2])),
        stops,
        headings,
        turn,
        math.radians(tilt),
        stop_tilts,
        floor_tilt,
    )


def _grid(table: _Table, scene: Path) -> GridConfig:
    extent_value = table.get("extent", "scene")
    if extent_value == "scene":
        try:
            extent = scene_extent(scene)
        except InputError as exc:
            raise table.fail(
                "extent", f"{exc}; give the grid's [x_min, y_min, x_max, y_max] in metres"
            ) from None
    else:
        extent = table.numbers(
            "extent", 4, '[x_min, y_min, x_max, y_max] in metres, or "scene"', extent_value
        )
    cell = table.number("cell_size", 0.1, lambda v: v > 0.0, "a positive size in metres")
    try:
        spec = GridSpec(*extent, cell)
    except InputError as exc:
        raise table.fail("extent", str(exc)) from None
    supersample = table.integer("supersample", 10)
    fusion = table.choice("fusion", tuple(RULES), "accumulate")
    params: dict[str, float] = {}
    if fusion == "logodds":
        rate = (lambda v: 0.0 <= v <= 1.0, "a rate in [0, 1]")
        for key in ("p_fp", "p_fn", "threshold"):
            if not table.has(key):
                # No default: a threshold above every score the detector gives (0.5 is above
                # all RFCH scores measured) would silently turn every column into evidence
                # against the object. The detector's calibration (twin roc) gives all three.
                raise table.fail(
                    key, "logodds needs the detector's p_fp, p_fn and threshold; measure them "
                    "with 'twin roc' (on rendered frames: p_fp 0.10, p_fn 0.05 at threshold 0.162)"
                )  # fmt: skip
            params[key] = table.number(key, ..., *rate)
    elif fusion == "normalized":
        params["min_observed"] = table.number(
            "min_observed", 1.0, lambda v: v >= 0.0, "a non-negative coverage"
        )
    max_range = table.number("max_range", None, lambda v: v > 0.0, "a positive range in metres")
    separation = table.number("peak_separation", 0.5, lambda v: v >= 0.0, "a distance >= 0 m")
    switches = {
        "visibility": True, "by_distance": False, "room_baseline": True, "height_check": False,
    }  # fmt: skip
    for key, default in switches.items():
        switches[key] = table.get(key, default)
        if not isinstance(switches[key], bool):
            raise table.fail(key, f"expected true or false, got {switches[key]!r}")
    bins = table.integer("direction_bins", 1)
    if not 1 <= bins <= 64:
        raise table.fail("direction_bins", f"expected 1 (off) to 64 directions, got {bins}")
    table.finish()
    # The calibrated rule's log-likelihood ratios come with the detector's models.
    rule = None if fusion == "calibrated" else make_rule(fusion, **params)
    return GridConfig(spec, supersample, rule, max_range, separation, fusion, bins, **switches)


def scene_extent(scene: Path) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of the scene's floor in metres: the grid's extent when the
    config leaves it to the scene, so a new scene needs no numbers copied into its config."""
    resolved = scene.resolve()
    return _scene_extent(str(resolved), resolved.stat().st_mtime_ns)


@functools.lru_cache(maxsize=16)
def _scene_extent(path: str, mtime_ns: int) -> tuple[float, float, float, float]:
    from twin.sim.world import World  # MuJoCo: only for configs that ask the scene

    return World(path).room_bounds()


def _detector(table: _Table) -> dict[str, Any]:
    """The RFCH parameters (``twin.rfch.RFCHParams``), checked now rather than at training."""
    from twin.rfch.params import RFCHParams

    try:
        RFCHParams.from_json(dict(table.data))
    except (InputError, TypeError, ValueError) as exc:
        key = str(exc).split(" ", 1)[0]  # RFCHParams names the parameter first
        if key in table.data:
            raise table.fail(key, str(exc)) from None
        raise table._error(table.path, str(exc)) from None
    table.used.update(table.data)
    return dict(table.data)


def _objects(table: _Table, folder: Path) -> tuple[ObjectConfig, ...]:
    if not table.data:
        raise table._error("objects", "name at least one object to find")
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
        stands_on = entry.get("stands_on", [])
        if (
            not isinstance(stands_on, list)
            or not all(isinstance(kind, str) for kind in stands_on)
            or not set(stands_on) <= set(SUPPORT_KINDS)
        ):
            raise entry.fail(
                "stands_on", f"expected a list of some of {list(SUPPORT_KINDS)}, got {stands_on!r}"
            )
        height = entry.number(
            "object_height_m",
            None,
            lambda h: 0.0 < h <= 3.0,
            "a height in metres, over 0 and up to 3",
        )
        entry.finish()
        objects.append(ObjectConfig(name, model, body, tuple(stands_on), height))
    table.finish()
    return tuple(objects)


# -- writing -----------------------------------------------------------------------------------


def dump_toml(data: dict[str, Any], comment: str = "") -> str:
    """TOML text for a config's data (tables of strings, numbers, booleans and lists), so a
    run's folder keeps the config it really ran with, ``--set`` overrides included."""
    lines = [f"# {line}" if line else "#" for line in comment.splitlines()]
    _dump_table(data, [], lines)
    return "\n".join(lines).strip() + "\n"


def _dump_table(table: dict[str, Any], path: list[str], lines: list[str]) -> None:
    scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in table.items() if isinstance(v, dict)}
    if path and (scalars or not tables):
        lines += ["", f"[{'.'.join(_key(p) for p in path)}]"]
    lines += [f"{_key(k)} = {_value(v)}" for k, v in scalars.items()]
    for key, child in tables.items():
        _dump_table(child, [*path, key], lines)


def _key(key: str) -> str:
    bare = key and all(c.isalnum() or c in "_-" for c in key)
    return key if bare else _value(key)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        if isinstance(value, float) and not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON's string escapes are TOML's too
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {value!r} ({type(value).__name__}) as TOML")
