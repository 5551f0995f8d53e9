"""A training run's configuration: the four settings of ``es``, ``policies`` and ``envs``, joined.

``config.json`` is its serialisation (one object per section), and an experiment file is the same
sections in TOML (``experiments/*.toml``): both are read by ``TrainConfig.from_dict``, so a resumed
run and an experiment are configured by the one loader. config.json files of earlier versions (one
flat object) are read too.
"""

from __future__ import annotations

import tomllib
import types
import typing
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from envs import EnvSettings
from es.settings import ESSettings, RunSettings
from policies import PolicySettings

SECTIONS = {"es": ESSettings, "policy": PolicySettings, "env": EnvSettings, "run": RunSettings}


@dataclass(frozen=True)
class TrainConfig:
    es: ESSettings
    policy: PolicySettings
    env: EnvSettings
    run: RunSettings

    def to_dict(self) -> dict:
        return {name: asdict(getattr(self, name)) for name in SECTIONS}

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        """The sections of ``data``; keys a section does not know are ignored (they are information:
        versions, the command, the layout). A flat object (config.json before sections) is read too."""
        if "es" not in data and "kind" in data:
            data = {name: data for name in SECTIONS}
        return cls(**{name: section(data.get(name, {}), settings) for name, settings in SECTIONS.items()})

    @classmethod
    def from_toml(cls, path: str | Path) -> "TrainConfig":
        return cls.from_dict(read_toml(path))

    def with_values(self, **values) -> "TrainConfig":
        """A copy with the named fields changed, wherever they live (``lr=0.1, threads=2``)."""
        changed = {}
        for name, settings in SECTIONS.items():
            mine = {key: value for key, value in values.items() if key in field_names(settings)}
            changed[name] = replace(getattr(self, name), **mine) if mine else getattr(self, name)
        unknown = set(values) - {key for settings in SECTIONS.values() for key in field_names(settings)}
        if unknown:
            raise ValueError(f"unknown settings: {', '.join(sorted(unknown))}")
        return TrainConfig(**changed)

    def value(self, name: str):
        """A field by name, whichever section holds it."""
        for section_name, settings in SECTIONS.items():
            if name in field_names(settings):
                return getattr(getattr(self, section_name), name)
        raise KeyError(name)


def field_names(settings: type) -> set[str]:
    return {item.name for item in fields(settings)}


def section(values: dict, settings: type):
    """A settings dataclass from a dict: known fields only, each of its field's type (``check_type``),
    lists back to tuples where the field is one."""
    hints = typing.get_type_hints(settings)
    known = {}
    for name in field_names(settings):
        if name in values:
            value = values[name]
            check_type(name, value, hints[name])
            if isinstance(value, list) and typing.get_origin(hints[name]) is tuple:
                value = tuple(value)
            known[name] = value
    return settings(**known)


TYPE_NAMES = {bool: "true or false", int: "a whole number", float: "a number", str: "a string", type(None): "none"}


def _matches(value, hint) -> bool:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return any(_matches(value, option) for option in typing.get_args(hint))
    if typing.get_origin(hint) is tuple:
        return isinstance(value, (list, tuple))
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


def check_type(name: str, value, hint) -> None:
    """Refuse a value of another type than its setting's (an experiment file or config.json can hold
    anything: ``reservoir = "false"`` would otherwise be true)."""
    if not _matches(value, hint):
        options = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
        expected = " or ".join(TYPE_NAMES.get(option, "a list") for option in options)
        raise ValueError(f"{name} must be {expected}, got {value!r}")


def read_toml(path: str | Path) -> dict:
    """An experiment file's sections; a syntax error is a ValueError naming the line."""
    with open(path, "rb") as handle:
        return tomllib.load(handle)
