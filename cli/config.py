"""A run's configuration: the settings of ``es`` (the search, the run), ``policies``, ``envs`` and
``report.loggers``, joined, and read from
what a user hands in (config.json, an experiment file) with every key checked against its declaration
(``settings``).

``config.json`` is its serialisation (one object per section), and an experiment file is the same
sections in TOML (``experiments/*.toml``). The settings of a plug-in the run does not choose are not
recorded (``settings.chosen``: no ``hebb_rule`` for a static run, no PGPE setting for an OpenAI-ES run, no
W&B setting without ``--logger wandb``); those of another policy kind are refused when given. config.json
files of earlier versions are read too: one flat object, or sections that recorded every setting whatever
the plug-ins (those of the plug-ins not chosen hold their defaults, or a tracker's, and are left out), without
the sections added since (``LATER_SECTIONS``), with the keys of settings since retired (``RETIRED``). Resume
and evaluation start from the recorded settings and apply the flags given (``overlay``): a flag that
contradicts the recording is refused, naming both values.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from envs import EnvSettings
from es.settings import ESSettings, RunSettings
from policies import KINDS, PolicySettings
from report.loggers import LogSettings
from settings import (
    Option,
    chosen,
    contradictions,
    file_value,
    left_out_by,
    options,
    owner_words,
    stray,
    type_problem,
)

SECTIONS = {"es": ESSettings, "policy": PolicySettings, "env": EnvSettings, "run": RunSettings, "log": LogSettings}
LATER_SECTIONS = ("log",)  # absent from the config.json of earlier versions (their loggers: RETIRED's run.tensorboard)
TRAIN_SCRIPTS = {name: kind.scripts[0] for name, kind in KINDS.items()}  # the training script of each policy kind


def declared() -> list[Option]:
    """Every declared setting, section by section."""
    return [item for settings in SECTIONS.values() for item in options(settings)]


def section_of(name: str) -> str:
    return next(section for section, settings in SECTIONS.items() if name in {item.name for item in options(settings)})


class Contradiction(ValueError):
    """Flags given that differ from what a run recorded; ``differing``: '--lr 0.9 (the run has 0.2)', ..."""

    def __init__(self, differing: list[str]):
        super().__init__(", ".join(differing))
        self.differing = differing


@dataclass(frozen=True)
class TrainConfig:
    es: ESSettings
    policy: PolicySettings
    env: EnvSettings
    run: RunSettings
    log: LogSettings = LogSettings()

    def to_dict(self) -> dict:
        """The sections, without the settings of the plug-ins this run does not choose."""
        sections = {name: asdict(getattr(self, name)) for name in SECTIONS}
        values = {key: value for section in sections.values() for key, value in section.items()}
        every = declared()
        return {name: {item.name: section[item.name] for item in options(SECTIONS[name])
                       if chosen(item, values, every)} for name, section in sections.items()}

    @classmethod
    def from_dict(cls, data: dict, source: str = "config.json") -> TrainConfig:
        """A run's config.json: every section, every key known; keys outside the sections are information
        (versions, the command, the layout). A flat object (config.json before sections) is read as it was."""
        if not isinstance(data, dict):
            raise ValueError(f"{source} is not a JSON object; a run's config.json holds the sections "
                             f"{', '.join(SECTIONS)} in one object")
        if "es" not in data and "kind" in data:
            known = {item.name for item in declared()}
            return cls.from_values({key: value for key, value in data.items() if key in known}, source)
        missing = [name for name in SECTIONS if not isinstance(data.get(name), dict) and name not in LATER_SECTIONS]
        if missing:
            raise ValueError(f"{source} has no {', '.join(repr(name) for name in missing)} section; a run's "
                             f"config.json holds the sections {', '.join(SECTIONS)}")
        return cls.from_values(section_values(data, source, recorded=True), source)

    @classmethod
    def from_values(cls, values: dict, source: str) -> TrainConfig:
        """The settings from flat values (``{"lr": 0.2, ...}``); each value's type is checked, then the settings
        check their values."""
        for item in declared():
            if item.name in values and (problem := type_problem(item, values[item.name])) is not None:
                raise ValueError(f"{source}: {problem}")
        return cls(**{name: settings(**{item.name: values[item.name] for item in options(settings)
                                        if item.name in values}) for name, settings in SECTIONS.items()})

    @classmethod
    def from_toml(cls, path: str | Path) -> TrainConfig:
        sections = read_toml(path)
        kind = sections.get("policy", {}).get("kind", PolicySettings.kind)
        return cls.from_values(section_values(sections, f"--config {path}", kind=kind), f"--config {path}")

    def with_values(self, **values) -> TrainConfig:
        """A copy with the named fields changed, wherever they live (``lr=0.1, threads=2``)."""
        unknown = set(values) - {item.name for item in declared()}
        if unknown:
            raise ValueError(f"unknown settings: {', '.join(sorted(unknown))}")
        changed = {}
        for name, settings in SECTIONS.items():
            mine = {key: value for key, value in values.items() if key in {item.name for item in options(settings)}}
            changed[name] = replace(getattr(self, name), **mine) if mine else getattr(self, name)
        return TrainConfig(**changed)

    def fixed(self) -> dict:
        """The settings a resume may not change, flat (``{"popsize": 4, ...}``): what a checkpoint records
        of the settings it was written under (``es.runfolder.settings_record``). The loggers' section is left
        out: it says where a run reports, never what it computes, and records a tracker's run id once the
        tracker has given one."""
        resumable = {item.name for item in declared() if item.spec.resumable}
        return {key: value for name, section in self.to_dict().items() if name != "log"
                for key, value in section.items() if key not in resumable}

    def value(self, name: str):
        """A field by name, whichever section holds it."""
        return getattr(getattr(self, section_of(name)), name)

    def overlay(self, given: dict, changeable) -> TrainConfig:
        """These settings with the ``given`` values of those in ``changeable``; every other given value must
        be what these settings hold already (a ``Contradiction`` lists those that are not). Resume (only the
        resumable settings change) and evaluation (the policy is the run's) both start from a run this way."""
        fixed = {name: value for name, value in given.items() if name not in changeable}
        differing = contradictions({name: self.value(name) for name in fixed}, fixed, declared())
        if differing:
            raise Contradiction(differing)
        return self.with_values(**{name: value for name, value in given.items() if name in changeable})


# keys of earlier versions that no setting declares any more: (section, key) -> what a value of it becomes today
RETIRED: dict[tuple[str, str], Callable[[object], dict]] = {
    # --fast_conv, the compiled CNN, went before 0.1.0 (no faster than the default CNN); such a run goes on, and is
    # evaluated, with the default CNN, whose features differ from its by about 1e-5 (docs/speed-carracing.md)
    ("policy", "fast_conv"): lambda value: {},
    # --tensorboard, a setting of the run before 0.1.0, is --logger tensorboard (the flag stays, as its alias)
    ("run", "tensorboard"): lambda value: {"logger": ("tensorboard",)} if value is True else {},
}


def section_values(sections: dict, source: str, kind: str | None = None, recorded: bool = False) -> dict:
    """The flat settings of sectioned data (a config.json when ``recorded``, else an experiment file), every key
    checked: unknown keys and keys of another policy kind are refused with their names. A config.json records
    the settings of the plug-ins it chooses (``chosen``); one of an earlier version, which recorded every
    setting, may hold those of the others at their defaults (or a tracker's run id), which are left out, and the
    keys of ``RETIRED``."""
    kind = kind or sections.get("policy", {}).get("kind", PolicySettings.kind)
    flat, unknown, items = {}, [], {}
    for name, settings in SECTIONS.items():
        entries = sections.get(name, {})
        if not isinstance(entries, dict):
            raise ValueError(f"{source}: [{name}] must be a table of settings")
        known = {item.name: item for item in options(settings)}
        for key, value in entries.items():
            item = known.get(key)
            if (name, key) in RETIRED:
                flat.update(RETIRED[name, key](value))
            elif item is None or (item.spec.derived and not recorded):
                unknown.append(f"{name}.{key}")
            else:
                flat[key], items[key] = (value if recorded else file_value(item, value)), (name, item)
    if unknown:
        raise ValueError(f"{source}: unknown settings {', '.join(unknown)}")
    every = declared()
    # the choices made: a config.json's, all of them (its own or their defaults); an experiment file's, the
    # script's kind (its other choices may come from flags: ``settings.unmet_requirement`` judges them)
    choices = ({item.name: flat.get(item.name, item.default) for item in every} if recorded else {"kind": kind})
    foreign = []
    for key, (name, item) in items.items():
        if chosen(item, choices, every):
            continue
        if not recorded or stray(item, flat[key], choices, every):
            foreign.append(f"{name}.{key} ({item.label}, for {owner_words(item, every)}) does not apply to "
                           f"{this_run(item, choices, every)}")
        del flat[key]
    if foreign:
        raise ValueError(f"{source}: {', '.join(foreign)}")
    return flat


def this_run(item: Option, choices: dict, every: list[Option]) -> str:
    """The run, by the choice that leaves ``item`` out: 'a static run', 'this run (--strategy openai)'."""
    choice = left_out_by(item, choices, every)
    value = choices[choice.name]
    shown = " ".join(value) if isinstance(value, (tuple, list)) else value
    return f"this run ({choice.label} {shown or 'none'})" if choice.flag else f"a {shown} run"


def read_toml(path: str | Path) -> dict:
    """An experiment file's sections; a syntax error is a ValueError naming the line."""
    with open(path, "rb") as handle:
        return tomllib.load(handle)
