"""Typed options: a table of a config file declared as a dataclass, checked key by key.

A device type (or any other table) declares its keys as the fields of a frozen dataclass, each
made with ``option()``: the field's name is the key, its annotation the type, and the metadata
carry the unit, the allowed range or choices and a one-line description. ``parse_options``
checks a TOML table against the declaration and returns the dataclass, or raises
``OptionError`` naming the key and what was expected; ``describe_options`` lists the keys for
people (``twin devices``). Nothing downstream ever converts raw input: a width is an ``int``
before any factory sees it.

Supported annotations: ``bool``, ``int``, ``float``, ``str``, ``Literal[...]`` of strings,
``int | str``, ``X | None`` (the key may be left out; TOML has no null), and ``tuple[float, ...]``
whose length is the default's.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from twin.core.errors import InputError

_UNSET: Any = dataclasses.MISSING


class OptionError(InputError):
    """``key`` of a table is wrong: ``problem`` says how (the caller adds where the table is)."""

    def __init__(self, key: str, problem: str) -> None:
        self.key, self.problem = key, problem
        super().__init__(f"{key}: {problem}")


def option(
    default: Any = _UNSET,
    *,
    unit: str = "",
    low: float | None = None,
    high: float | None = None,
    doc: str = "",
) -> Any:
    """A declared key: its default (none: required), unit, inclusive range [low, high], doc."""
    metadata = {"unit": unit, "low": low, "high": high, "doc": doc}
    if isinstance(default, list):
        raise TypeError("give a list default as a tuple: option defaults must be immutable")
    return dataclasses.field(default=default, metadata=metadata)


@dataclass(frozen=True)
class OptionInfo:
    """One declared key, as ``describe_options`` reports it."""

    name: str
    kind: str  # e.g. "int", "float", "one of direct, aux"
    unit: str
    default: Any  # dataclasses.MISSING when the key is required
    low: float | None
    high: float | None
    doc: str

    @property
    def required(self) -> bool:
        return self.default is dataclasses.MISSING

    def expected(self) -> str:
        """What a valid value is, in words: 'a whole number of px in [16, 4096]'."""
        unit = f" of {self.unit}" if self.unit and self.kind in ("int", "float") else ""
        words = {"int": "a whole number", "float": "a number", "str": "a non-empty string",
                 "bool": "true or false", "int | str": "a whole number or a string"}  # fmt: skip
        text = words.get(self.kind, self.kind) + unit
        if self.low is not None and self.high is not None:
            text += f" in [{self.low:g}, {self.high:g}]"
        elif self.low is not None:
            text += f" >= {self.low:g}"
        elif self.high is not None:
            text += f" <= {self.high:g}"
        return text


def describe_options(cls: type) -> list[OptionInfo]:
    """The keys ``cls`` declares, in declaration order."""
    hints = typing.get_type_hints(cls)
    infos = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        infos.append(
            OptionInfo(
                f.name,
                _kind(hints[f.name], f.default),
                meta.get("unit", ""),
                f.default,
                meta.get("low"),
                meta.get("high"),
                meta.get("doc", ""),
            )
        )
    return infos


def parse_options(cls: type, table: Mapping[str, Any], owner: str = "") -> Any:
    """``table`` checked against ``cls``'s declaration; an ``OptionError`` names the first wrong
    key. An unknown key is an error that lists the known ones (a misspelt key must never fall
    back to a default); ``owner`` (e.g. "type 'opencv'") names whose keys they are."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - set(fields))
    if unknown:
        known = ", ".join(fields) or "none"
        whose = f" for {owner}" if owner else ""
        raise OptionError(unknown[0], f"unknown option{whose}; known: {known}")
    values = {}
    infos = {info.name: info for info in describe_options(cls)}
    for name, f in fields.items():
        info = infos[name]
        if name not in table:
            if f.default is dataclasses.MISSING:
                raise OptionError(name, f"is required: give {info.expected()}")
            continue
        values[name] = _check(hints[name], table[name], info)
    return cls(**values)


def _kind(annotation: Any, default: Any) -> str:
    annotation = _strip_none(annotation)
    if typing.get_origin(annotation) is Literal:
        return "one of " + ", ".join(str(a) for a in typing.get_args(annotation))
    if typing.get_origin(annotation) is tuple:
        size = len(default) if isinstance(default, tuple) else "n"
        return f"a list of {size} numbers"
    if _is_union(annotation):
        return " | ".join(a.__name__ for a in typing.get_args(annotation))
    return annotation.__name__


def _strip_none(annotation: Any) -> Any:
    if _is_union(annotation):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
        return typing.Union[tuple(args)]  # noqa: UP007 - rebuilt from a runtime tuple
    return annotation


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _check(annotation: Any, value: Any, info: OptionInfo) -> Any:
    annotation = _strip_none(annotation)
    bad = OptionError(info.name, f"expected {info.expected()}, got {value!r}")
    origin = typing.get_origin(annotation)
    if origin is Literal:
        if value not in typing.get_args(annotation):
            raise bad
        return value
    if origin is tuple:
        size = len(info.default) if isinstance(info.default, tuple) else None
        if not isinstance(value, list) or (size is not None and len(value) != size):
            raise bad
        numbers = tuple(_number(v, bad) for v in value)
        for v in numbers:
            _in_range(v, info, bad)
        return numbers
    if _is_union(annotation):  # int | str
        if isinstance(value, bool):
            raise bad
        if isinstance(value, int) and int in typing.get_args(annotation):
            return value
        if isinstance(value, str) and value and str in typing.get_args(annotation):
            return value
        raise bad
    if annotation is bool:
        if not isinstance(value, bool):
            raise bad
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return _in_range(value, info, bad)
    if annotation is float:
        return _in_range(_number(value, bad), info, bad)
    if annotation is str:
        if not isinstance(value, str) or not value:
            raise bad
        return value
    raise TypeError(f"option {info.name}: unsupported annotation {annotation!r}")


def _number(value: Any, bad: OptionError) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise bad
    return float(value)


def _in_range(value: Any, info: OptionInfo, bad: OptionError) -> Any:
    if info.low is not None and value < info.low:
        raise bad
    if info.high is not None and value > info.high:
        raise bad
    return value
